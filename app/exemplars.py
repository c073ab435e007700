"""Learn from decisions: the reviewed objects of a project as a model library (contract 2).

The crops and their medians are the library's (:mod:`sbsc_core.recognition.learning.crops`).

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
from pathlib import Path

import cv2
import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from sbsc_core.recognition.learning.crops import (
    footprint,
    learnt_depth,
    learnt_view,
    relief,
    upright,
)

from .models import DetectionRow, Project, WallRow
from .review_rules import review_score

__all__ = ["build_exemplar_library", "footprint", "learnt_depth", "learnt_view", "upright"]

MAX_VIEWS = 12  # crops per class at most (the surest first), merged into one view and one depth model
EXEMPLAR_BASE = 100  # exemplar views are colour_101.png, colour_102.png, ...


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
    dets.sort(key=lambda d: -(2.0 if d.source == "reviewer" else (review_score(d.confidence, d.alpha) or 0.0)))
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
        win = footprint(colour.shape, wall.height_m, wall.pixel_m, u=d.u, v=d.v,
                        width_m=float(meta["width_m"]), height_m=float(meta["height_m"]))
        if win is None:
            continue
        r0, c0, r1, c1 = win
        crop_relief = relief(depth, win, ring_px=max(2, (r1 - r0) // 4)) if depth is not None else None
        if depth is not None and crop_relief is None:
            continue  # mostly unseen
        views.setdefault(d.class_id, []).append(colour[r0:r1, c0:c1])
        if crop_relief is not None:
            reliefs.setdefault(d.class_id, []).append(crop_relief)
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


