"""BIM side of the tool: IFC as-is export, as-designed import and Scan-vs-BIM comparison.

The paper (Adan et al. 2018, section 6) ends with the recognized objects' 3D positions
"augmenting" the as-is BIM model, and names as future work what this package does next:
reporting designed objects that were not found (possibly not built) and found objects that
the as-designed model does not hold.

- :mod:`.export`  detections (contract 4) -> IFC4 / IFC4X3 as-is model
- :mod:`.design`  as-designed IFC -> expected objects; ground truth -> as-designed IFC
- :mod:`.compare` as-designed vs detections: found / displaced / missing / unexpected
- :mod:`.report`  self-contained HTML report with per-wall pictures
- :mod:`.bcf`     BCF 2.1 topics, one per finding

How a library class is written into IFC comes from its ``model.json`` (contract 2):
``ifc_class``, ``predefined_type`` and an optional ``object_type``. :class:`ClassTyping`
holds that plus the box used as the object's body (footprint x depth).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import ModelLibrary, ObjectModel

SCHEMAS: tuple[str, ...] = ("IFC4", "IFC4X3", "IFC2X3")
PSET_RECOGNITION = "SBSC_Recognition"  # alpha, rho, source, review of an exported detection
PSET_DESIGN = "SBSC_Design"  # class of an object in an as-designed file written by sbsc
DEFAULT_DEPTH_M = 0.02  # body depth of a class whose depth is not known
MIN_DEPTH_M = 0.002  # thinnest box body written (a sign is ~3 mm)


@dataclass(frozen=True)
class ClassTyping:
    """How one library class is written to / recognized in IFC.

    Attributes
    ----------
    class_id, name
        The class's id (its folder in the model library) and its name.
    ifc_class, predefined_type, object_type
        The IFC entity, its PredefinedType and ObjectType (``model.json``).
    width_m, height_m, depth_m
        The box written as the object's body: footprint and depth, metres.
    """

    class_id: str
    name: str
    ifc_class: str
    predefined_type: str | None
    object_type: str | None
    width_m: float
    height_m: float
    depth_m: float


def normalise_schema(schema: str, where: str = "schema") -> str:
    """``"ifc4"`` -> ``"IFC4"``; ``IFC4X3`` (any ADD) -> ``"IFC4X3"``; ``IFC2X3`` (any TC) -> ``"IFC2X3"``.

    Parameters
    ----------
    schema
        An IFC schema name, in any case.
    where
        The option or field named by the error.

    Returns
    -------
    str
        One of :data:`SCHEMAS`.

    Raises
    ------
    InputError
        For any other schema.
    """
    s = str(schema).strip().upper()
    if s.startswith("IFC4X3"):
        return "IFC4X3"
    if s == "IFC4":
        return "IFC4"
    if s.startswith("IFC2X3"):
        return "IFC2X3"
    raise InputError(where, f"unknown IFC schema '{schema}' (expected one of {', '.join(SCHEMAS)})")


def _typing(class_id: str, meta: Mapping, relief: np.ndarray | None = None) -> ClassTyping:
    """A class's typing from its ``model.json`` fields; the body depth is ``depth_m``, else the
    highest point of the relief ``depth.npy``, else :data:`DEFAULT_DEPTH_M`."""
    depth = meta.get("depth_m")
    if not isinstance(depth, int | float) or isinstance(depth, bool) or not np.isfinite(depth) or depth <= 0:
        depth = None
        if relief is not None and np.isfinite(relief).any():
            top = float(np.nanmax(relief))
            depth = top if top > 0 else None
    object_type = meta.get("object_type")
    return ClassTyping(
        class_id=class_id, name=str(meta["name"]), ifc_class=str(meta["ifc_class"]),
        predefined_type=meta.get("predefined_type"),
        object_type=str(object_type) if object_type else None,
        width_m=float(meta["width_m"]), height_m=float(meta["height_m"]),
        depth_m=max(MIN_DEPTH_M, float(depth if depth is not None else DEFAULT_DEPTH_M)),
    )


def _typing_from_model(model: ObjectModel) -> ClassTyping:
    meta = {**model.extra, "name": model.name, "ifc_class": model.ifc_class,
            "predefined_type": model.predefined_type, "width_m": model.width_m, "height_m": model.height_m}
    return _typing(model.class_id, meta, model.depth)


def bundled_typings() -> dict[str, ClassTyping]:
    """The classes of the bundled model library, in its order (read from its ``model.json`` files)."""
    from ..io.models import read_library_metadata
    from ..paths import bundled_models_dir

    return {cid: _typing(cid, meta) for cid, meta in read_library_metadata(bundled_models_dir()).items()}


def class_typings(library: ModelLibrary | None = None, models: Path | None = None) -> dict[str, ClassTyping]:
    """Typing of every class: from ``library``, else the directory ``models``, else the
    bundled library.

    Parameters
    ----------
    library
        A model library already read.
    models
        A model library's folder (contract 2), read when ``library`` is None.

    Returns
    -------
    dict[str, ClassTyping]
        Class id -> how it is written in IFC, in the library's order.
    """
    if library is None and models is not None:
        from ..io.models import load_model_library

        library = load_model_library(models)
    if library is None:
        return bundled_typings()
    return {cid: _typing_from_model(m) for cid, m in library.models.items()}
