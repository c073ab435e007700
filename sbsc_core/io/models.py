"""Load and check an object model library (contract 2), and unpack one from a zip.

A library is a directory with one sub-directory per class::

    models/socket_x1/model.json      name, ifc_class, predefined_type?, width_m, height_m, mount?
    models/socket_x1/colour.png      front views: colour.png, colour_1.png, ...
    models/socket_x1/depth.npy       optional 2-D relief over the footprint (metres)
    models/socket_x1/depth_1.npy     optional further depth models of the class: depth_1.npy,
                                     depth_2.npy, ... (e.g. exemplars measured on a reviewed scan;
                                     see docs/model-library.md); each checked like depth.npy

An optional number ``order`` in ``model.json`` sets the class's place in the library's
order (:func:`library_order`: tables and lists name the classes in it); classes without it
follow, alphabetically. :func:`read_library_metadata` reads only the ``model.json`` files:
the class metadata (names, IFC classes, sizes, order) without the views.

Every problem raises :class:`~sbsc_core.errors.InputError` naming the class directory
or the file and what is wrong with it, e.g. ``models/socket_x1/model.json: missing key
'width_m'``.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import stat
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path, PurePosixPath

import numpy as np

from ..errors import InputError
from ..types import SURFACE_KINDS, ModelLibrary, ObjectModel
from .detections_model import bad_text
from .safe_json import load_json_file

CLASS_ID_RE = re.compile(r"^[a-z0-9_]+$")
COLOUR_FILE_RE = re.compile(r"^colour(?:_(\d+))?\.png$")
# further depth models: depth_<k>.npy (and depth_exemplar_<k>.npy, the name exemplar libraries of
# the review app used before they were read)
EXTRA_DEPTH_RE = re.compile(r"^depth_(?:exemplar_)?(\d+)\.npy$")
MAX_EXTRA_DEPTHS = 32  # more is refused: each one is a further correlation per wall
REQUIRED_KEYS = ("name", "ifc_class", "width_m", "height_m")
MODEL_MIN_M = 0.005  # an object's footprint side: at least about one orthoimage pixel
MODEL_MAX_M = 10.0  # at most a wall's size (a 1e5 m model would allocate a huge template)
MODEL_JSON_MAX_BYTES = 1024 * 1024
DEPTH_ASPECT_TOLERANCE = 0.10  # relative mismatch allowed between depth.npy and width/height

# Limits of library_from_zip (a zip comes from a web upload).
ZIP_MAX_ENTRIES = 2000
ZIP_MAX_ENTRY_BYTES = 64 << 20
ZIP_MAX_TOTAL_BYTES = 512 << 20
_ZIP_IGNORED = ("__MACOSX",)


def load_model_library(root: Path | str) -> ModelLibrary:
    """Read and check every class directory of ``root``.

    Sub-directories starting with ``.`` and ``__MACOSX`` are ignored; loose files
    beside the class directories (a README, say) too.

    Parameters
    ----------
    root
        A model library (contract 2): one folder per class with its ``model.json``, colour
        views and depth model.

    Returns
    -------
    ModelLibrary
        The classes by id, checked.

    Raises
    ------
    InputError
        Naming the file or field that cannot be used.
    """
    root = Path(root)
    if not root.exists():
        raise InputError(root, "no such directory")
    if not root.is_dir():
        raise InputError(root, "not a directory")
    models: dict[str, ObjectModel] = {}
    for d in sorted(root.iterdir()):
        if not d.is_dir() or d.name.startswith(".") or d.name in _ZIP_IGNORED:
            continue
        if not CLASS_ID_RE.match(d.name):
            raise InputError(d, "class directory name must be lower case letters, digits and '_'")
        models[d.name] = load_object_model(d)
    if not models:
        raise InputError(root, "no class directories (expected one sub-directory per object class)")
    return ModelLibrary(models=models, root=str(root))


def library_order(metadata: Mapping[str, Mapping]) -> list[str]:
    """The class ids of a library in its order: by ``order`` (``model.json``, a number), then
    the classes without it, each group alphabetically by class id (stable)."""
    def key(cid: str) -> tuple[int, float, str]:
        order = metadata[cid].get("order")
        ok = isinstance(order, int | float) and not isinstance(order, bool) and math.isfinite(order)
        return (0, float(order), cid) if ok else (1, 0.0, cid)

    return sorted(metadata, key=key)


def ordered_class_ids(library: ModelLibrary) -> list[str]:
    """The classes of a loaded library in its order (:func:`library_order`)."""
    return library_order({cid: m.extra for cid, m in library.models.items()})


def read_library_metadata(root: Path | str) -> dict[str, dict]:
    """Class id -> the checked fields of its ``model.json``, in the library's order.

    Reads only the ``model.json`` files (no front view, no depth), with the same checks and
    errors as :func:`load_model_library`.
    """
    root = Path(root)
    if not root.is_dir():
        raise InputError(root, "no such directory" if not root.exists() else "not a directory")
    meta: dict[str, dict] = {}
    for d in sorted(root.iterdir()):
        if not d.is_dir() or d.name.startswith(".") or d.name in _ZIP_IGNORED:
            continue
        if not CLASS_ID_RE.match(d.name):
            raise InputError(d, "class directory name must be lower case letters, digits and '_'")
        meta[d.name] = _read_model_json(d / "model.json")
    if not meta:
        raise InputError(root, "no class directories (expected one sub-directory per object class)")
    return {cid: meta[cid] for cid in library_order(meta)}


def load_object_model(class_dir: Path) -> ObjectModel:
    """Read one class directory (``model.json``, ``colour*.png``, optional ``depth.npy`` and
    further depth models ``depth_<k>.npy``).

    The further depth models are kept apart from ``depth.npy`` (the class's reference model,
    used for look-alikes, snapping and placement); recognition tries them as well and keeps
    the best match. A class with further depth models but no ``depth.npy`` uses the first of
    them as its reference model.
    """
    class_dir = Path(class_dir)
    meta = _read_model_json(class_dir / "model.json")
    width, height = meta["width_m"], meta["height_m"]
    views = [_read_colour_view(p) for p in _colour_files(class_dir)]
    depth_path = class_dir / "depth.npy"
    depth = _read_depth(depth_path, width, height) if depth_path.exists() else None
    extra_depths = [_read_depth(p, width, height) for p in _extra_depth_files(class_dir)]
    if depth is None and extra_depths:
        depth = extra_depths.pop(0)
    extra = {k: v for k, v in meta.items() if k not in (*REQUIRED_KEYS, "predefined_type", "mount")}
    return ObjectModel(
        class_id=class_dir.name, name=meta["name"], ifc_class=meta["ifc_class"],
        predefined_type=meta.get("predefined_type"), width_m=width, height_m=height,
        colour_views=views, depth=depth, extra=extra, extra_depths=extra_depths, mount=meta["mount"],
    )


def _read_model_json(path: Path) -> dict:
    if not path.is_file():
        raise InputError(path, "missing")
    meta = load_json_file(path, max_bytes=MODEL_JSON_MAX_BYTES)
    if not isinstance(meta, dict):
        raise InputError(path, "expected a JSON object")
    for key in REQUIRED_KEYS:
        if key not in meta:
            raise InputError(path, f"missing key '{key}'")
    for key in ("name", "ifc_class"):
        if not isinstance(meta[key], str) or not meta[key].strip():
            raise InputError(path, f"'{key}' must be a non-empty string")
        why = bad_text(meta[key])
        if why:
            raise InputError(path, f"'{key}' {why}")
    if not meta["ifc_class"].startswith("Ifc"):
        raise InputError(path, f"'ifc_class' must be an IFC entity name such as IfcOutlet, got '{meta['ifc_class']}'")
    order = meta.get("order")
    if order is not None and (isinstance(order, bool) or not isinstance(order, int | float)
                              or not math.isfinite(order)):
        raise InputError(path, f"'order' must be a number, got {json.dumps(order)}")
    pt = meta.get("predefined_type")
    if pt is not None and (not isinstance(pt, str) or not pt.strip()):
        raise InputError(path, "'predefined_type' must be a non-empty string or null")
    for key in ("width_m", "height_m"):
        v = meta[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0:
            raise InputError(path, f"'{key}' must be a number > 0, got {json.dumps(v)}")
        if not MODEL_MIN_M <= v <= MODEL_MAX_M:
            raise InputError(path, f"'{key}' must be between {MODEL_MIN_M:g} and {MODEL_MAX_M:g} m "
                                   f"(a wall-mounted object), got {json.dumps(v)}")
        meta[key] = float(v)
    meta["mount"] = _read_mount(path, meta.get("mount", list(SURFACE_KINDS)))
    return meta


def _read_mount(path: Path, value: object) -> tuple[str, ...]:
    """``mount``: a non-empty list of distinct surface kinds (wall, ceiling, column), kept in that order."""
    if not isinstance(value, list) or not value:
        raise InputError(path, f"'mount' must be a non-empty list of {', '.join(SURFACE_KINDS)}, "
                               f"got {json.dumps(value)[:80]}")
    for kind in value:
        if kind not in SURFACE_KINDS:
            raise InputError(path, f"'mount' has unknown surface {json.dumps(kind)[:40]} "
                                   f"(known: {', '.join(SURFACE_KINDS)})")
    if len(set(value)) != len(value):
        raise InputError(path, "'mount' names a surface twice")
    return tuple(k for k in SURFACE_KINDS if k in value)


def _colour_files(class_dir: Path) -> list[Path]:
    found = []
    for p in class_dir.iterdir():
        m = COLOUR_FILE_RE.match(p.name)
        if m and p.is_file():
            found.append((-1 if m.group(1) is None else int(m.group(1)), p))
    if not found:
        raise InputError(class_dir, "no front view (expected colour.png, colour_1.png, ...)")
    return [p for _, p in sorted(found)]


def _extra_depth_files(class_dir: Path) -> list[Path]:
    """``depth_<k>.npy`` (or ``depth_exemplar_<k>.npy``) files in order of ``k``."""
    found = []
    for p in class_dir.iterdir():
        m = EXTRA_DEPTH_RE.match(p.name)
        if m and p.is_file():
            found.append((int(m.group(1)), p.name, p))
    if len(found) > MAX_EXTRA_DEPTHS:
        raise InputError(class_dir, f"too many further depth models ({len(found)} > {MAX_EXTRA_DEPTHS})")
    return [p for _, _, p in sorted(found)]


def _read_colour_view(path: Path) -> np.ndarray:
    """A PNG front view as (h, w, 4) uint8 RGBA (opaque when the file has no alpha)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise InputError(path, "not a readable PNG image")
    if img.dtype == np.uint16:
        img = ((img.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise InputError(path, f"unsupported pixel type {img.dtype}")
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        channels = 1 if img.ndim == 2 else img.shape[2]
        raise InputError(path, f"expected an RGB or RGBA image, got {channels} channel(s)")
    code = cv2.COLOR_BGR2RGBA if img.shape[2] == 3 else cv2.COLOR_BGRA2RGBA
    return np.ascontiguousarray(cv2.cvtColor(img, code))


def _read_depth(path: Path, width_m: float, height_m: float) -> np.ndarray:
    """``depth.npy``: 2-D float, finite or NaN, aspect ratio matching the footprint."""
    try:
        depth = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise InputError(path, f"not a readable .npy array ({str(exc).splitlines()[0] if str(exc) else 'bad file'})") from None
    if not isinstance(depth, np.ndarray) or depth.ndim != 2 or min(depth.shape) == 0:
        raise InputError(path, f"expected a non-empty 2-D array, got shape {getattr(depth, 'shape', None)}")
    if depth.dtype.kind != "f":
        raise InputError(path, f"expected a float array, got {depth.dtype}")
    depth = depth.astype(np.float32)
    if np.isinf(depth).any():
        raise InputError(path, "infinite values (use NaN for unknown)")
    rows, cols = depth.shape
    expected_cols = rows * width_m / height_m
    if abs(cols - expected_cols) > max(1.0, DEPTH_ASPECT_TOLERANCE * expected_cols):
        raise InputError(path, f"shape {rows}x{cols} does not match the footprint "
                               f"{width_m:g} x {height_m:g} m (width/height)")
    return depth


# --------------------------------------------------------------------------- zip upload


def library_from_zip(zip_path: Path | str, dest_dir: Path | str) -> Path:
    """Unpack a zipped model library safely into ``dest_dir`` and check it.

    The zip holds the class directories at its top level or inside one top-level
    folder. Refused (InputError naming the entry): absolute paths, ``..``, symbolic
    links, more than ``ZIP_MAX_ENTRIES`` entries, entries over ``ZIP_MAX_ENTRY_BYTES``
    or a total over ``ZIP_MAX_TOTAL_BYTES`` (counted while decompressing), and any
    library error of :func:`load_model_library`. ``dest_dir`` must not exist or be
    empty; on failure it is left as it was. Returns the library root directory.
    """
    zip_path, dest_dir = Path(zip_path), Path(dest_dir)
    label = zip_path.name
    if not zip_path.is_file():
        raise InputError(label, "no such file")
    if dest_dir.exists() and any(dest_dir.iterdir()):
        raise InputError(dest_dir, "destination is not empty")
    if not zipfile.is_zipfile(zip_path):
        raise InputError(label, "not a zip file")
    dest_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{dest_dir.name}.partial-", dir=dest_dir.parent))
    try:
        _extract_zip(zip_path, tmp, label)
        root_rel = _library_root(tmp)
        try:
            load_model_library(tmp / root_rel)
        except InputError as exc:
            try:
                where = Path(exc.where).relative_to(tmp).as_posix()
            except ValueError:
                where = exc.where
            raise InputError(f"{label}: {where}", exc.reason) from None
        if dest_dir.exists():
            dest_dir.rmdir()
        tmp.rename(dest_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return dest_dir / root_rel


def _extract_zip(zip_path: Path, out: Path, label: str) -> None:
    try:
        zf = zipfile.ZipFile(zip_path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise InputError(label, f"not a readable zip file ({exc})") from None
    with zf:
        infos = zf.infolist()
        if len(infos) > ZIP_MAX_ENTRIES:
            raise InputError(label, f"too many entries ({len(infos)} > {ZIP_MAX_ENTRIES})")
        total = 0
        for info in infos:
            name = info.filename
            rel = _safe_entry_name(name, label)
            if rel is None:
                continue
            mode = info.external_attr >> 16
            if stat.S_ISLNK(mode):
                raise InputError(f"{label}: {name}", "symbolic links are not allowed")
            target = out.joinpath(*rel.parts)
            if info.is_dir():
                target.mkdir(parents=True, exist_ok=True)
                continue
            if info.file_size > ZIP_MAX_ENTRY_BYTES:
                raise InputError(f"{label}: {name}", f"entry too large ({info.file_size} bytes)")
            target.parent.mkdir(parents=True, exist_ok=True)
            size = 0
            try:
                with zf.open(info) as src, open(target, "wb") as dst:
                    while block := src.read(1 << 20):
                        size += len(block)
                        total += len(block)
                        if size > ZIP_MAX_ENTRY_BYTES:
                            raise InputError(f"{label}: {name}", "entry too large")
                        if total > ZIP_MAX_TOTAL_BYTES:
                            raise InputError(label, f"unpacks to more than {ZIP_MAX_TOTAL_BYTES} bytes")
                        dst.write(block)
            except (zipfile.BadZipFile, OSError, EOFError, NotImplementedError, RuntimeError) as exc:
                raise InputError(f"{label}: {name}", f"cannot unpack ({exc})") from None


def _safe_entry_name(name: str, label: str) -> PurePosixPath | None:
    """The entry's relative path, None for entries to skip; refuses unsafe names."""
    if "\\" in name or "\x00" in name:
        raise InputError(f"{label}: {name}", "backslashes or NUL in entry names are not allowed")
    p = PurePosixPath(name)
    if p.is_absolute() or (p.parts and ":" in p.parts[0]):
        raise InputError(f"{label}: {name}", "absolute paths are not allowed")
    if ".." in p.parts:
        raise InputError(f"{label}: {name}", "'..' in entry names is not allowed")
    parts = [x for x in p.parts if x not in ("", ".")]
    if not parts or parts[0] in _ZIP_IGNORED or parts[-1] == ".DS_Store":
        return None
    return PurePosixPath(*parts)


def _library_root(tmp: Path) -> Path:
    """'.' if the class directories are at the top; the folder's name if inside one folder."""
    dirs = [p for p in tmp.iterdir()
            if p.is_dir() and not p.name.startswith(".") and p.name not in _ZIP_IGNORED]
    if len(dirs) == 1 and not (dirs[0] / "model.json").exists():
        return Path(dirs[0].name)
    return Path(".")
