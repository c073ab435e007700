"""The whole method, scan in, positioned objects out (paper, Figure 2).

``detect`` runs the stages in order on an in-memory cloud and returns every intermediate
result; ``detect_to_dir`` reads the inputs, runs ``detect`` and writes the outputs of
``sbsc detect`` atomically:

``detections.json``
    contract 4, plus a top-level ``pixel_m``.
``rois.json``
    ``{"schema": "sbsc.rois/1", "pixel_m": ..., "walls": {wall: {"depth": [...], "colour": [...]}}}``
    with every RoI as ``{"u_min", "u_max", "v_min", "v_max"}`` metres in the wall frame.
``orthoimages/<wall>_colour.png``, ``<wall>_depth.png``, ``<wall>_depth.npy``, ``<wall>_overlay.png``
    the colour and depth orthoimages (row 0 = top of the wall, ``pixel_m`` pixels), the raw
    depth in metres (NaN = no data) and the RoIs (depth cyan, colour magenta, as the paper's
    figure 21) with the recognized objects as red spots.
"""

from __future__ import annotations

import itertools
import json
import multiprocessing
import os
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .colour_prep import prepare_colour
from .colour_recognition import (
    ColourPrototypes,
    colour_image,
    colour_rois,
    learn_prototypes,
    match_colour,
)
from .consensus import consensus_all
from .depth_recognition import depth_images, depth_rois, match_depth
from .errors import InputError, SbscError
from .io.atomic import atomic_output_dir
from .io.documents import detections_document, read_expected
from .io.models import load_model_library
from .io.scans import read_scans
from .orthoimage import build_orthoimage
from .placement import place_hits
from .segmentation import segment_floor_ceiling_walls
from .settings import DetectionSettings, load_settings
from .templates import ModelTemplate, make_templates
from .types import (
    Box,
    Candidate,
    Detection,
    ModelLibrary,
    Orthoimage,
    PointCloud,
    Segmentation,
    Wall,
    WallArea,
)
from .wall_area import find_wall_area

Progress = Callable[[str, float], None]
_TALL_STOREY_M = 5.0  # a storey higher than this is named in a warning (several storeys taken as one?)


@dataclass
class WallResult:
    """Everything the method computed for one wall."""

    ortho: Orthoimage
    area: WallArea
    depth_rois: list[Box]
    colour_rois: list[Box]
    depth_candidates: list[Candidate]
    colour_candidates: list[Candidate]


@dataclass
class DetectionResult:
    segmentation: Segmentation
    walls: dict[str, WallResult]
    detections: list[Detection]
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage
    classes: list[str] = field(default_factory=list)

    @property
    def openings(self):
        return [o for w in self.walls.values() for o in w.area.openings]


def _noop_progress(stage: str, fraction: float) -> None:
    return None


WALL_STAGES = ("orthoimage", "colour_prep", "wall_area", "depth", "colour")


def process_wall(cloud: PointCloud, wall: Wall, templates: dict[str, ModelTemplate],
                 prototypes: ColourPrototypes, s: DetectionSettings) -> tuple[WallResult, dict[str, float]]:
    """Sections 3.2-4.3 on one wall: orthoimage, colour preparation, wall area and openings,
    RoIs and candidates in depth and in colour. Returns the result and seconds per stage."""
    t_stage: dict[str, float] = {}
    t = time.perf_counter()
    ortho = build_orthoimage(cloud, wall, s.orthoimage)
    t_stage["orthoimage"] = time.perf_counter() - t
    t = time.perf_counter()
    ortho = prepare_colour(ortho, s.colour_prep)
    t_stage["colour_prep"] = time.perf_counter() - t
    t = time.perf_counter()
    area = find_wall_area(ortho, s.wall_area)
    t_stage["wall_area"] = time.perf_counter() - t
    t = time.perf_counter()
    d_img = depth_images(ortho, area, s.depth)  # J_D and its wall level, computed once per wall
    d_rois = depth_rois(ortho, area, s.depth, templates, d_img)
    d_cands = match_depth(ortho, area, d_rois, templates, s.depth, d_img)
    t_stage["depth"] = time.perf_counter() - t
    t = time.perf_counter()
    c_img = colour_image(ortho, area, s.colour)  # J_C and J_BW, computed once per wall
    c_rois = colour_rois(ortho, area, s.colour, c_img)
    c_cands = match_colour(ortho, area, c_rois, prototypes, s.colour, c_img)
    t_stage["colour"] = time.perf_counter() - t
    return WallResult(ortho, area, d_rois, c_rois, d_cands, c_cands), t_stage


def _wall_cloud(cloud: PointCloud, wall: Wall) -> tuple[PointCloud, Wall]:
    """The points of one wall as a cloud of their own (what a worker process receives)."""
    sub = PointCloud(cloud.xyz[wall.point_index], cloud.rgb[wall.point_index], cloud.origin, cloud.sources)
    return sub, Wall(wall.id, wall.frame, np.arange(len(wall.point_index), dtype=np.int64), wall.storey)


def _process_wall_job(sub: PointCloud, wall: Wall, templates: dict[str, ModelTemplate],
                      prototypes: ColourPrototypes, s: DetectionSettings
                      ) -> tuple[str, WallResult, dict[str, float]]:
    res, t_stage = process_wall(sub, wall, templates, prototypes, s)
    return wall.id, res, t_stage


def _worker_count(settings: DetectionSettings) -> int:
    return settings.workers or min(2, os.cpu_count() or 1)


def _ready() -> bool:
    """A no-op run in each new worker: it is spawned and has imported the method."""
    return True


def wall_pool(settings: DetectionSettings, n_walls: int | None = None) -> ProcessPoolExecutor | None:
    """The worker processes for the per-wall stages (None when they run in this process).

    The workers are started at once (spawned, each importing the library, about a second),
    so a caller that creates the pool before reading the scan has them ready when the walls
    are. The caller shuts the pool down.
    """
    workers = _worker_count(settings)
    if workers <= 1 or (n_walls is not None and n_walls <= 1):
        return None
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    for _ in range(workers):
        pool.submit(_ready)
    return pool


def _walls_results(cloud: PointCloud, seg: Segmentation, templates: dict[str, ModelTemplate],
                   prototypes: ColourPrototypes, s: DetectionSettings,
                   pool: ProcessPoolExecutor | None = None) -> Iterator[tuple[str, WallResult, dict[str, float]]]:
    """Process every wall, in worker processes (``pool``, or one of ``s.workers`` made here)
    when there are several walls.

    Each worker receives only its wall's points; at most two walls per worker are in flight,
    so the scan is never copied whole. Results come back in the order of ``seg.walls``.
    """
    own = pool is None and len(seg.walls) > 1
    if own:
        pool = wall_pool(s, len(seg.walls))
    if pool is None or len(seg.walls) <= 1:
        for wall in seg.walls:
            res, t_stage = process_wall(cloud, wall, templates, prototypes, s)
            yield wall.id, res, t_stage
        return
    try:
        pending: deque = deque()
        todo = iter(seg.walls)
        for wall in itertools.islice(todo, 2 * _worker_count(s)):
            pending.append(pool.submit(_process_wall_job, *_wall_cloud(cloud, wall), templates, prototypes, s))
        while pending:
            yield pending.popleft().result()
            nxt = next(todo, None)
            if nxt is not None:
                pending.append(pool.submit(_process_wall_job, *_wall_cloud(cloud, nxt), templates,
                                           prototypes, s))
    finally:
        if own:
            pool.shutdown(wait=True, cancel_futures=True)


def detect(
    cloud: PointCloud,
    library: ModelLibrary,
    expected: dict[str, int] | None = None,
    settings: DetectionSettings | None = None,
    progress: Progress | None = None,
    pool: ProcessPoolExecutor | None = None,
) -> DetectionResult:
    """Run sections 3 and 4 of the paper on a registered coloured cloud of one floor.

    ``expected`` maps class ids to instance counts (contract 3); classes not named are not
    searched. Without it every class of the library is searched with no count limit.
    ``pool`` (see :func:`wall_pool`) runs the per-wall stages; by default one is made.
    """
    s = settings or DetectionSettings()
    progress = progress or _noop_progress
    timings: dict[str, float] = {}
    if expected is not None:
        unknown = sorted(set(expected) - set(library.models))
        if unknown:
            raise InputError("expected", f"class '{unknown[0]}' is not in the model library")
        classes = sorted(c for c, n in expected.items() if n > 0)
    else:
        classes = library.class_ids

    t0 = time.perf_counter()
    progress("segmentation", 0.0)
    seg = segment_floor_ceiling_walls(cloud, s.segmentation)
    timings["segmentation"] = time.perf_counter() - t0

    t = time.perf_counter()
    templates = make_templates(library, s.orthoimage.pixel_m, classes)
    prototypes = learn_prototypes(templates, s.colour)
    timings["templates"] = time.perf_counter() - t
    t = time.perf_counter()

    walls: dict[str, WallResult] = {}
    stage_t = dict.fromkeys(WALL_STAGES, 0.0)
    for i, (wid, res, t_wall) in enumerate(_walls_results(cloud, seg, templates, prototypes, s, pool)):
        progress("walls", (i + 1) / max(1, len(seg.walls)))
        walls[wid] = res
        for k, v in t_wall.items():
            stage_t[k] += v
    timings.update(stage_t)
    timings["walls_elapsed"] = time.perf_counter() - t

    progress("consensus", 0.0)
    t = time.perf_counter()
    depth_c = [c for w in walls.values() for c in w.depth_candidates]
    colour_c = [c for w in walls.values() for c in w.colour_candidates]
    hits = consensus_all(depth_c, colour_c, expected, s.consensus, classes)
    orthos = {k: w.ortho for k, w in walls.items()}
    detections = place_hits([h for cls in classes for h in hits.get(cls, [])], orthos, templates)
    timings["consensus"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    progress("consensus", 1.0)
    return DetectionResult(seg, walls, detections, timings, classes)


def detect_to_dir(
    scans: Sequence[Path],
    models: Path,
    *,
    expected: Path | dict[str, int] | None = None,
    out: Path,
    settings_file: Path | None = None,
    settings: DetectionSettings | None = None,
    log: Callable[[str], None] | None = None,
    progress: Progress | None = None,
) -> dict:
    """``sbsc detect``: read, detect, write every output atomically; return a summary dict."""
    log = log or (lambda msg: None)
    progress = progress or _noop_progress
    s = settings or load_settings(settings_file)
    progress("reading", 0.0)
    library = load_model_library(Path(models))
    counts = read_expected(expected) if isinstance(expected, (str, Path)) else expected
    pool = wall_pool(s)  # the workers start while the scan is read
    try:
        t = time.perf_counter()
        cloud = read_scans([Path(p) for p in scans])
        read_s = time.perf_counter() - t
        log(f"read {len(cloud):,} points from {len(scans)} file(s) in {read_s:.1f} s")
        result = detect(cloud, library, counts, s, progress, pool)
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    result.timings["reading"] = read_s
    seg = result.segmentation
    if seg.stray_points:
        log(f"ignored {seg.stray_points:,} stray points outside the dense part of the scan")
    for st in seg.storeys:
        walls = [w for w in seg.walls if w.storey == st.id]
        found = sum(1 for d in result.detections if d.wall_id in {w.id for w in walls})
        log(f"storey {st.id}: floor z = {st.floor_z:.2f} m, ceiling z = {st.ceiling_z:.2f} m, "
            f"{len(walls)} walls, {found} objects")
        if st.ceiling_z - st.floor_z > _TALL_STOREY_M:
            log(f"warning: storey {st.id} is {st.ceiling_z - st.floor_z:.1f} m high; if it is several storeys, "
                "no slab between them was seen (check the scan)")
    log(f"{len(seg.walls)} walls, {len(result.openings)} openings, "
        f"{len(result.detections)} objects in {result.timings['total']:.1f} s")
    progress("writing", 0.0)
    with atomic_output_dir(out) as tmp:
        write_outputs(result, tmp, s.orthoimage.pixel_m)
    progress("done", 1.0)
    return {
        "points": len(cloud),
        "walls": len(result.segmentation.walls),
        "openings": len(result.openings),
        "detections": len(result.detections),
        "storeys": len(seg.storeys),
        "stray_points": seg.stray_points,
        "timings": result.timings,
    }


def _box_uv(ortho: Orthoimage, b: Box) -> dict:
    px, h = ortho.pixel_m, ortho.frame.height_m
    return {"u_min": round(b.c0 * px, 4), "u_max": round(b.c1 * px, 4),
            "v_min": round(h - b.r1 * px, 4), "v_max": round(h - b.r0 * px, 4)}


def depth_visualisation(depth: np.ndarray, scale_m: float = 0.10) -> np.ndarray:
    """8-bit grey image of a depth map: wall plane mid-grey, relief darker, no data white."""
    img = np.full(depth.shape, 255, np.uint8)
    ok = np.isfinite(depth)
    img[ok] = np.clip(128 - depth[ok] / scale_m * 127, 0, 254).astype(np.uint8)
    return img


def overlay_image(w: WallResult, detections: Sequence[Detection]) -> np.ndarray:
    """The colour orthoimage with depth RoIs (cyan), colour RoIs (magenta) and red spots (BGR)."""
    img = cv2.cvtColor(w.ortho.colour, cv2.COLOR_RGB2BGR).copy()
    for b in w.depth_rois:
        cv2.rectangle(img, (b.c0, b.r0), (b.c1 - 1, b.r1 - 1), (255, 255, 0), 1)
    for b in w.colour_rois:
        cv2.rectangle(img, (b.c0, b.r0), (b.c1 - 1, b.r1 - 1), (255, 0, 255), 1)
    for d in detections:
        r, c = w.ortho.uv_to_pixel(d.u, d.v)
        cv2.circle(img, (int(round(float(c))), int(round(float(r)))), 6, (0, 0, 255), -1)
    return img


def write_outputs(result: DetectionResult, out: Path, pixel_m: float) -> None:
    """Write detections.json, rois.json and the per-wall images into ``out``."""
    images = out / "orthoimages"
    images.mkdir(parents=True, exist_ok=True)
    rois: dict[str, dict] = {}
    for wid, w in result.walls.items():
        dets = [d for d in result.detections if d.wall_id == wid]
        if not cv2.imwrite(str(images / f"{wid}_colour.png"), cv2.cvtColor(w.ortho.colour, cv2.COLOR_RGB2BGR)):
            raise SbscError(f"{images}: cannot write images")
        cv2.imwrite(str(images / f"{wid}_depth.png"), depth_visualisation(w.ortho.depth))
        np.save(images / f"{wid}_depth.npy", w.ortho.depth.astype(np.float32))
        cv2.imwrite(str(images / f"{wid}_overlay.png"), overlay_image(w, dets))
        rois[wid] = {"depth": [_box_uv(w.ortho, b) for b in w.depth_rois],
                     "colour": [_box_uv(w.ortho, b) for b in w.colour_rois]}
    seg = result.segmentation
    extra: dict = {"pixel_m": pixel_m, "classes_searched": result.classes, "stray_points": seg.stray_points}
    if len(seg.storeys) > 1:  # contract 4: a one-storey scan omits the storeys
        extra["storeys"] = [st.to_dict() for st in seg.storeys]
    doc = detections_document([(wall.id, wall.frame) for wall in seg.walls], result.openings,
                              result.detections, extra=extra)
    if len(seg.storeys) > 1:
        for wall, entry in zip(seg.walls, doc["walls"], strict=True):
            entry["storey"] = wall.storey
    (out / "detections.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    (out / "rois.json").write_text(
        json.dumps({"schema": "sbsc.rois/1", "pixel_m": pixel_m, "walls": rois}, indent=1) + "\n",
        encoding="utf-8")
