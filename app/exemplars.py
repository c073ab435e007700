"""Learn from decisions: the reviewed objects of a project as a model library (contract 2).

Every accepted object (recognized, relabelled or added by a reviewer) is cut out of its
wall's colour and depth orthoimages over exactly its footprint. Each class of the project's
library is copied with its own views and ``model.json``, and gets one learnt front view
(``colour_101.png``: the per-pixel median of the crops, which the library reader loads like
any other view) and one further depth model (``depth_101.npy``: the per-pixel median of the
upright objects' relief above the wall level around each). Medians average the scanner noise
of single crops out, and one view and one model per class keep recognition's cost low
(each further view or model is one more correlation per class and wall);
the reader loads ``depth_<k>.npy`` as further depth models and recognition keeps the best
match of all a class's models, see docs/model-library.md). The result is a library a
re-run of the project, or a run on another floor of the same building, can use like any
uploaded library.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import cv2
import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from .models import DetectionRow, Project, WallRow

MIN_SEEN = 0.6  # a crop with less of its footprint scanned is left out
MAX_VIEWS = 12  # crops per class at most (the surest first), merged into one view and one depth model
MAX_TURN_DEG = 5.0  # an object turned by more (from upright or upside down) gives no crop
MIN_DEPTH_SAMPLES = 1  # crops a learnt depth model needs at least
EXEMPLAR_BASE = 100  # exemplar views are colour_101.png, colour_102.png, ...


def footprint(shape: tuple[int, ...], wall_height_m: float, pixel_m: float, u: float, v: float,
              width_m: float, height_m: float) -> tuple[int, int, int, int] | None:
    """(r0, c0, r1, c1) of an object's footprint in an orthoimage; None when it leaves the image."""
    c0 = int(round((u - width_m / 2) / pixel_m))
    c1 = int(round((u + width_m / 2) / pixel_m))
    r0 = int(round((wall_height_m - v - height_m / 2) / pixel_m))
    r1 = int(round((wall_height_m - v + height_m / 2) / pixel_m))
    if r0 < 0 or c0 < 0 or r1 > shape[0] or c1 > shape[1] or r1 - r0 < 2 or c1 - c0 < 2:
        return None
    return r0, c0, r1, c1


def _relief(depth: np.ndarray, win: tuple[int, int, int, int], ring_px: int) -> np.ndarray | None:
    r0, c0, r1, c1 = win
    crop = depth[r0:r1, c0:c1].astype(np.float32)
    if np.isfinite(crop).mean() < MIN_SEEN:
        return None
    R0, C0 = max(0, r0 - ring_px), max(0, c0 - ring_px)
    R1, C1 = min(depth.shape[0], r1 + ring_px), min(depth.shape[1], c1 + ring_px)
    ring = depth[R0:R1, C0:C1].copy()
    ring[r0 - R0:r1 - R0, c0 - C0:c1 - C0] = np.nan
    level = float(np.nanmedian(ring)) if np.isfinite(ring).any() else 0.0
    return crop - level


def build_exemplar_library(s: Session, project: Project, data_dir: Path, source_library: Path,
                           dest: Path) -> dict[str, int]:
    """Write the exemplar library of ``project``'s current results into ``dest``.

    Returns class id -> number of exemplar views added. Classes without accepted objects
    are copied unchanged, so the library stays complete.
    """
    if project.current_job_id is None:
        return {}
    dets = list(s.scalars(select(DetectionRow).where(DetectionRow.job_id == project.current_job_id,
                                                     DetectionRow.status == "accepted")))
    walls = {w.key: w for w in s.scalars(select(WallRow).where(WallRow.job_id == project.current_job_id))}
    dest.mkdir(parents=True, exist_ok=True)
    for class_dir in sorted(Path(source_library).iterdir()):
        if class_dir.is_dir() and (class_dir / "model.json").is_file():
            shutil.copytree(class_dir, dest / class_dir.name, dirs_exist_ok=True)
    images: dict[tuple[str, str], np.ndarray | None] = {}

    def image(wall: WallRow, kind: str) -> np.ndarray | None:
        key = (wall.key, kind)
        if key not in images:
            meta = (wall.images or {}).get(kind)
            img = None
            if meta:
                path = data_dir / meta["path"]
                img = np.load(path) if kind == "depth" else cv2.imread(str(path), cv2.IMREAD_COLOR)
            images[key] = img
        return images[key]

    added: dict[str, int] = {}
    reliefs: dict[str, list[np.ndarray]] = {}
    views: dict[str, list[np.ndarray]] = {}
    # the surest first: reviewer-added objects, then by confidence / alpha
    dets.sort(key=lambda d: -(2.0 if d.source == "reviewer" else
                              (d.confidence if d.confidence is not None else (d.alpha or 0.0))))
    for d in dets:
        cdir = dest / d.class_id
        wall = walls.get(d.wall_key)
        if wall is None or not (cdir / "model.json").is_file() or added.get(d.class_id, 0) >= MAX_VIEWS:
            continue
        if not upright(float((d.extra or {}).get("rotation_deg") or 0.0)):
            continue  # a crop is cut over the upright footprint
        meta = json.loads((cdir / "model.json").read_text(encoding="utf-8"))
        colour, depth = image(wall, "colour"), image(wall, "depth")
        if colour is None:
            continue
        win = footprint(colour.shape, wall.height_m, wall.pixel_m, d.u, d.v,
                        float(meta["width_m"]), float(meta["height_m"]))
        if win is None:
            continue
        r0, c0, r1, c1 = win
        relief = _relief(depth, win, ring_px=max(2, (r1 - r0) // 4)) if depth is not None else None
        if depth is not None and relief is None:
            continue  # mostly unseen
        views.setdefault(d.class_id, []).append(colour[r0:r1, c0:c1])
        if relief is not None:
            reliefs.setdefault(d.class_id, []).append(relief.astype(np.float32))
        added[d.class_id] = added.get(d.class_id, 0) + 1
    # numbered after the library's own views: colour_101.png, depth_101.npy
    for cid, crops in views.items():
        view = learnt_view(crops)
        if view is not None:
            cv2.imwrite(str(dest / cid / f"colour_{EXEMPLAR_BASE + 1}.png"), view)
    for cid, crops in reliefs.items():
        model = learnt_depth(crops)
        if model is not None:
            np.save(dest / cid / f"depth_{EXEMPLAR_BASE + 1}.npy", model)
    return added


def _common(crops: list[np.ndarray]) -> list[np.ndarray]:
    """The crops of the most common size (a wall of another pixel size gives another)."""
    shapes = [c.shape for c in crops]
    shape = max(set(shapes), key=shapes.count)
    return [c for c in crops if c.shape == shape]


def learnt_view(crops: list[np.ndarray]) -> np.ndarray | None:
    """The per-pixel median of the colour crops of one class (BGR uint8); None without crops."""
    if not crops:
        return None
    return np.median(np.stack(_common(crops)), axis=0).round().astype(np.uint8)


def upright(rotation_deg: float) -> bool:
    """Whether an object turned by ``rotation_deg`` still covers its upright footprint: within
    ``MAX_TURN_DEG`` of upright or of upside down (the crop is the object as it hangs)."""
    off = abs((rotation_deg + 90.0) % 180.0 - 90.0)
    return off <= MAX_TURN_DEG


def learnt_depth(crops: list[np.ndarray]) -> np.ndarray | None:
    """The per-pixel median of the relief crops of one class (NaN where none saw it); None
    with fewer than ``MIN_DEPTH_SAMPLES`` crops. Crops of another size than the most common
    one (a wall of another pixel size) are left out."""
    if len(crops) < MIN_DEPTH_SAMPLES:
        return None
    stack = np.stack(_common(crops))
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pixels stay NaN
        model = np.nanmedian(stack, axis=0).astype(np.float32)
    return model if np.isfinite(model).any() else None
