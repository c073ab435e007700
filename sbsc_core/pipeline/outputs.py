"""A run's result and the output folder of ``sbsc detect`` (contract 4): detections.json,
rois.json, suggestions, the orthoimages and their overlays."""

from __future__ import annotations

import json
import shutil
from concurrent.futures import (
    Executor,
)
from dataclasses import dataclass, field
from pathlib import Path

import cv2

from ..errors import SbscError
from ..recognition.suggestions import suggestions_document
from ..types import (
    Detection,
    Segmentation,
)
from .executors import _as_done
from .walls import WallResult, _box_uv, _write_wall_images, overlay_image


@dataclass
class DetectionResult:
    """What :func:`~sbsc_core.pipeline.detect.detect` found, before it is written out.

    Attributes
    ----------
    segmentation
        The storeys, floors, ceilings and walls found in the cloud.
    walls
        Each surface's orthoimages, RoIs and candidates, by wall (or ceiling tile, column face) id.
    detections
        The recognized objects (the consensus of depth and colour, placed and scored).
    timings
        Seconds per stage.
    classes
        The classes searched for.
    surfaces
        The surfaces beyond walls (ceiling tiles, column faces) as in contract 4.
    registration
        Per scan file, how its registration was refined.
    """

    segmentation: Segmentation
    walls: dict[str, WallResult]
    detections: list[Detection]
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage
    classes: list[str] = field(default_factory=list)
    surfaces: list[dict] = field(default_factory=list)  # contract-4 surfaces beyond walls (ceiling tiles)
    registration: list[dict] = field(default_factory=list)  # per scan file: how its registration was refined

    @property
    def openings(self):
        beyond = {sf["id"] for sf in self.surfaces}
        return [o for wid, w in self.walls.items() if wid not in beyond for o in w.area.openings]


def _parked_overlay_job(parked: str, w: WallResult, detections: list[Detection]) -> str:
    """Draw a parked wall's overlay from its colour image in ``parked`` and write it there."""
    wid = w.ortho.wall_id
    colour = cv2.imread(str(Path(parked) / f"{wid}_colour.png"), cv2.IMREAD_COLOR)
    if not cv2.imwrite(str(Path(parked) / f"{wid}_overlay.png"), overlay_image(w, detections, colour)):
        raise SbscError(f"{parked}: cannot write images")
    return wid


def write_outputs(result: DetectionResult, out: Path, pixel_m: float, *, extra: dict | None = None,
                  parked: Path | None = None, executor: Executor | None = None) -> None:
    """Write detections.json, rois.json and the per-wall images into ``out``.

    ``extra`` adds top-level keys to detections.json (the scan's ``crs`` and ``origin``);
    ``parked``: the folder where :func:`park_wall` wrote the walls' images; with it,
    ``executor`` (that of the detection) draws the overlays side by side, in ``parked``.
    """
    images = out / "orthoimages"
    images.mkdir(parents=True, exist_ok=True)
    rois: dict[str, dict] = {}
    drawn = set()
    if parked is not None and executor is not None:
        jobs = [(str(parked), w, [d for d in result.detections if d.wall_id == wid])
                for wid, w in result.walls.items()]
        drawn = {wid for _, wid in _as_done(executor, jobs, _parked_overlay_job, 4 * max(1, len(jobs)))}
    for wid, w in result.walls.items():
        dets = [d for d in result.detections if d.wall_id == wid]
        if parked is None:
            _write_wall_images(w.ortho, images)
            cv2.imwrite(str(images / f"{wid}_overlay.png"), overlay_image(w, dets))
        else:
            for suffix in ("colour.png", "depth.png", "depth.npy"):
                shutil.move(parked / f"{wid}_{suffix}", images / f"{wid}_{suffix}")
            if wid in drawn:
                shutil.move(parked / f"{wid}_overlay.png", images / f"{wid}_overlay.png")
            else:
                overlay = overlay_image(w, dets, cv2.imread(str(images / f"{wid}_colour.png"), cv2.IMREAD_COLOR))
                cv2.imwrite(str(images / f"{wid}_overlay.png"), overlay)
        rois[wid] = {"depth": [_box_uv(w.ortho, b) for b in w.depth_rois],
                     "colour": [_box_uv(w.ortho, b) for b in w.colour_rois]}
    seg = result.segmentation
    fields: dict = {"pixel_m": pixel_m, "classes_searched": result.classes, "stray_points": seg.stray_points,
                   **(extra or {})}
    if len(seg.storeys) > 1:  # contract 4: a one-storey scan omits the storeys
        fields["storeys"] = [st.to_dict() for st in seg.storeys]
    if result.surfaces:
        fields["surfaces"] = result.surfaces
    if result.registration:  # several scan files: each one's refined registration
        fields["registration"] = result.registration
    from ..io.documents import detections_document

    doc = detections_document([(wall.id, wall.frame) for wall in seg.walls], result.openings,
                              result.detections, extra=fields)
    if len(seg.storeys) > 1:
        for wall, entry in zip(seg.walls, doc["walls"], strict=True):
            entry["storey"] = wall.storey
    (out / "detections.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    (out / "rois.json").write_text(
        json.dumps({"schema": "sbsc.rois/1", "pixel_m": pixel_m, "walls": rois}, indent=1) + "\n",
        encoding="utf-8")
    cands = [c for w in result.walls.values() for c in (*w.depth_candidates, *w.colour_candidates)]
    sugg = suggestions_document({k: w.ortho for k, w in result.walls.items()}, cands, result.detections)
    (out / "suggestions.json").write_text(json.dumps(sugg, indent=1) + "\n", encoding="utf-8")
