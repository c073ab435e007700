"""Which model library a project's job used, and its classes (model.json fields)."""

from __future__ import annotations

import functools
from pathlib import Path

from sqlalchemy.orm import Session

from .errors import Invalid
from .models import (
    ModelLibraryRow,
    WallRow,
)


@functools.lru_cache(maxsize=1)
def bundled_classes() -> dict:
    """The bundled model library's classes (contract 2): class id -> name, IFC class, predefined
    type and footprint, by class id as for an uploaded library; read from its ``model.json`` files."""
    from sbsc_core.io.models import read_library_metadata
    from sbsc_core.paths import bundled_models_dir

    keys = ("name", "ifc_class", "predefined_type", "width_m", "height_m")
    meta = read_library_metadata(bundled_models_dir())
    return {cid: {**{k: meta[cid].get(k) for k in keys}, "mount": list(meta[cid]["mount"])} for cid in sorted(meta)}


def check_mount(classes: dict, class_id: str, wall: WallRow) -> None:
    """422 when the library says ``class_id`` is never mounted on this kind of surface (model.json
    ``mount``: a radiator on a ceiling, a smoke detector on a column). A library stored before
    ``mount`` was kept allows every surface."""
    kind = wall.kind or "wall"
    mounts = classes[class_id].get("mount")
    if mounts and kind not in mounts:
        raise Invalid(f"class: '{class_id}' is mounted on {' or '.join(mounts)} (its model.json 'mount'), "
                      f"not on {kind} {wall.key}")


def library_classes(s: Session, models_id: int | None) -> dict:
    """Class id -> model.json fields of an uploaded library, or of the bundled one."""
    if models_id is not None:
        row = s.get(ModelLibraryRow, models_id)
        if row is not None:
            return dict(row.classes)
    return bundled_classes()


def models_dir(s: Session, models_id: int | None, data_dir: Path) -> Path:
    """The model library directory (contract 2) a job used: the uploaded library's folder under
    ``data_dir``, or the bundled one (no library, or its row is gone). The one place the app
    resolves it (the job worker, the 3D scene, the exports and the review API ask here)."""
    from sbsc_core.paths import bundled_models_dir

    row = s.get(ModelLibraryRow, models_id) if models_id is not None else None
    return data_dir / row.path if row is not None else bundled_models_dir()
