"""The whole method, scan in, positioned objects out (paper, Figure 2).

``detect`` runs the stages in order on an in-memory cloud and returns every intermediate
result; ``detect_scans`` does the same on scan files out of core (a bounded sample for
segmentation, one partition file per wall, tasks on a local pool or a Dask cluster);
``detect_to_dir`` runs ``detect_scans`` and writes the outputs of ``sbsc detect`` atomically:

``detections.json``
    contract 4, plus a top-level ``pixel_m``.
``rois.json``
    ``{"schema": "sbsc.rois/1", "pixel_m": ..., "walls": {wall: {"depth": [...], "colour": [...]}}}``
    with every RoI as ``{"u_min", "u_max", "v_min", "v_max"}`` metres in the wall frame.
``orthoimages/<wall>_colour.png``, ``<wall>_depth.png``, ``<wall>_depth.npy``, ``<wall>_overlay.png``
    the colour and depth orthoimages (row 0 = top of the wall, ``pixel_m`` pixels), the raw
    depth in metres (NaN = no data) and the RoIs (depth cyan, colour magenta, as the paper's
    figure 21) with the recognized objects as red spots.
``suggestions.json``
    candidates the consensus did not keep, offered to a reviewer as possible misses
    (:mod:`sbsc_core.suggestions`).
"""

from __future__ import annotations

import contextlib
import importlib
import itertools
import json
import multiprocessing
import os
import shutil
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import (
    FIRST_COMPLETED,
    Executor,
    Future,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
    wait,
)
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from .amplitude import colour_where_relief_allows
from .colour_prep import prepare_colour
from .colour_recognition import (
    ColourPrototypes,
    colour_image,
    colour_rois,
    learn_prototypes,
    match_colour,
)
from .confidence import model_reliefs, screened_consensus, unexplained_regions
from .consensus import ConsensusHit
from .cpu_features import numpy_environment
from .depth_recognition import depth_images, depth_rois, match_depth
from .errors import InputError, SbscError
from .io.atomic import atomic_output_dir
from .io.crs import georeference_fields, scan_crs
from .lookalikes import library_relief_models, resolve_on_wall
from .mounting import within_wall_height
from .orthoimage import build_orthoimage
from .partition import (
    SampleBuffer,
    WallIndex,
    drop_wall_partition,
    partition_part,
    plan_parts,
    sample_part,
    sample_step,
    scan_origin,
    scratch_folder,
    station_names,
    wall_orthoimage,
    worker_ready,
)
from .placement import place_hits
from .registration import StationSamples, refine_registration, station_sample_points
from .segmentation import (
    StoreyPoints,
    find_scan_storeys,
    segment_floor_ceiling_walls,
    segment_storeys,
)
from .settings import DetectionSettings, load_settings
from .stages import Progress, Stage, no_progress
from .storey_samples import storey_cloud, storey_part, storey_steps
from .suggestions import suggestions_document
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
    WallFrame,
)
from .wall_area import find_wall_area

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
    surfaces: list[dict] = field(default_factory=list)  # contract-4 surfaces beyond walls (ceiling tiles)
    registration: list[dict] = field(default_factory=list)  # per scan file: how its registration was refined

    @property
    def openings(self):
        beyond = {sf["id"] for sf in self.surfaces}
        return [o for wid, w in self.walls.items() if wid not in beyond for o in w.area.openings]


WALL_STAGES = ("orthoimage", "colour_prep", "wall_area", "depth", "colour")


def process_wall(cloud: PointCloud, wall: Wall, templates: dict[str, ModelTemplate],
                 prototypes: ColourPrototypes, s: DetectionSettings) -> tuple[WallResult, dict[str, float]]:
    """Sections 3.2-4.3 on one wall: orthoimage, colour preparation, wall area and openings,
    RoIs and candidates in depth and in colour. Returns the result and seconds per stage."""
    t = time.perf_counter()
    ortho = build_orthoimage(cloud, wall, s.orthoimage)
    return process_orthoimage(ortho, templates, prototypes, s, {"orthoimage": time.perf_counter() - t})


def process_orthoimage(ortho: Orthoimage, templates: dict[str, ModelTemplate], prototypes: ColourPrototypes,
                       s: DetectionSettings, t_stage: dict[str, float] | None = None
                       ) -> tuple[WallResult, dict[str, float]]:
    """Sections 3.2 (colour) to 4.3 on one wall's orthoimage; seconds per stage added to ``t_stage``."""
    t_stage = dict(t_stage or {})
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
    d_cands, c_cands = resolve_on_wall(d_cands, c_cands, c_img, prototypes, s.lookalikes,
                                       relief=d_img.levelled, gain_range=s.depth.gain_range)
    if s.colour.relief_must_allow:  # a print without its object's relief is not the object
        c_cands, _ = colour_where_relief_allows(c_cands, d_img.levelled, *library_relief_models(prototypes),
                                                s.depth.gain_range)
    t_stage["colour"] = time.perf_counter() - t
    return WallResult(ortho, area, d_rois, c_rois, d_cands, c_cands), t_stage


def _partition_wall_job(scratch: str, w: int, wall_id: str, frame: WallFrame, templates: dict[str, ModelTemplate],
                        prototypes: ColourPrototypes, s: DetectionSettings, images: str | None = None
                        ) -> tuple[str, WallResult, dict[str, float]]:
    """One wall's work from its partition file (what a worker, local or on a cluster, runs).

    With ``images`` (a folder beside the partitions) the wall's images are written there
    and the result is returned without them (:func:`park_wall`).
    """
    t = time.perf_counter()
    ortho = wall_orthoimage(scratch, w, wall_id, frame, s.orthoimage)
    res, t_stage = process_orthoimage(ortho, templates, prototypes, s, {"orthoimage": time.perf_counter() - t})
    if images is not None:
        res = park_wall(res, Path(images))
    return wall_id, res, t_stage


def _templates_job(library: ModelLibrary, s: DetectionSettings, classes: list[str]
                   ) -> tuple[dict[str, ModelTemplate], ColourPrototypes]:
    """The templates of the searched classes at the orthoimage's pixel size, and their colour prototypes."""
    templates = make_templates(library, s.orthoimage.pixel_m, classes)
    return templates, learn_prototypes(templates, s.colour)


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
    """A no-op run in a worker: it has imported the whole method (this module)."""
    return True


def _environ(name: str) -> str | None:
    """An environment variable as a worker sees it."""
    return os.environ.get(name)


def worker_environment() -> dict[str, str]:
    """Environment variables for new worker processes (see :mod:`sbsc_core.cpu_features`)."""
    return numpy_environment()


@contextlib.contextmanager
def _environment(extra: dict[str, str]) -> Iterator[None]:
    """``extra`` in os.environ while processes are started (they copy it), then as before."""
    saved = {k: os.environ.get(k) for k in extra}
    os.environ.update(extra)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def wall_pool(settings: DetectionSettings, n_walls: int | None = None) -> ProcessPoolExecutor | None:
    """The worker processes for the per-wall stages (None when they run in this process).

    The workers are started at once (spawned), each importing only what reading the scan
    needs (:func:`~sbsc_core.partition.worker_ready`, a fraction of a second), so a caller
    that creates the pool before reading the scan has them ready for the reading tasks;
    :func:`detect_scans` has them import the rest while segmentation runs. The caller shuts
    the pool down.
    """
    workers = _worker_count(settings)
    if workers <= 1 or (n_walls is not None and n_walls <= 1):
        return None
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    with _environment(worker_environment()):  # each submit below starts one worker (a copy of the environment)
        for _ in range(workers):
            pool.submit(worker_ready)
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


if TYPE_CHECKING:  # the documents (and pydantic) are imported where used: the wall workers never need them
    from .io.documents import ExpectedCounts

    Expected = dict[str, int] | ExpectedCounts  # contract 3: counts, or counts with per-storey counts


def _as_expected(expected: Expected | None) -> ExpectedCounts | None:
    from .io.documents import ExpectedCounts

    if expected is None or isinstance(expected, ExpectedCounts):
        return expected
    return ExpectedCounts(dict(expected))


def _search_classes(library: ModelLibrary, expected: dict[str, int] | None, kind: str = "wall") -> list[str]:
    """The classes searched for on surfaces of ``kind``: expected (or all) and mounted there."""
    if expected is not None:
        unknown = sorted(set(expected) - set(library.models))
        if unknown:
            raise InputError("expected", f"class '{unknown[0]}' is not in the model library")
        return library.classes_on(kind, sorted(c for c, n in expected.items() if n > 0))
    return library.classes_on(kind)


def searched_surfaces(s: DetectionSettings, library: ModelLibrary, expected: ExpectedCounts | None) -> DetectionSettings:
    """``s`` with ceilings and columns searched only where they may hold a searched class.

    Every kind of surface is searched by default (contract 6): ``settings.ceilings.enabled``
    and ``settings.columns.enabled`` say that the user allows it (``--no-ceilings`` and
    ``--no-columns`` do not); a kind is then searched when a class searched for (expected, or
    every class of the library) may be mounted there (its ``model.json`` ``mount``, every
    surface when it has none).
    """
    counts = None if expected is None else expected.counts
    ceilings = s.ceilings.enabled and bool(_search_classes(library, counts, "ceiling"))
    columns = s.columns.enabled and bool(_search_classes(library, counts, "column"))
    if (ceilings, columns) == (s.ceilings.enabled, s.columns.enabled):
        return s
    return replace(s, ceilings=replace(s.ceilings, enabled=ceilings), columns=replace(s.columns, enabled=columns))


def _collect_walls(results: Iterator[tuple[str, WallResult, dict[str, float]]], n_walls: int, progress: Progress,
                   timings: dict[str, float]) -> dict[str, WallResult]:
    t = time.perf_counter()
    walls: dict[str, WallResult] = {}
    stage_t = dict.fromkeys(WALL_STAGES, 0.0)
    for i, (wid, res, t_wall) in enumerate(results):
        progress(Stage.WALLS, (i + 1) / max(1, n_walls))
        walls[wid] = res
        for k, v in t_wall.items():
            stage_t[k] += v
    timings.update(stage_t)
    timings["walls_elapsed"] = time.perf_counter() - t
    return walls


def storey_counts(seg: Segmentation, expected: ExpectedCounts | None,
                  log: Callable[[str], None] | None = None) -> dict[str, dict[str, int]] | None:
    """The expected counts of each storey found, when the expected counts give them for exactly
    the storeys that segmentation found (same ids); else None, said in ``log`` when the
    counts have storeys that do not match (then the building's counts apply to all storeys)."""
    if expected is None or not expected.storeys or len(seg.storeys) < 2:
        return None
    found = [st.id for st in seg.storeys]
    if sorted(found) != sorted(expected.storeys):
        if log is not None:
            log(f"warning: the expected counts name storeys {', '.join(sorted(expected.storeys))} but the scan "
                f"has {', '.join(found)}: the building's counts apply to all storeys together")
        return None
    return {sid: dict(expected.storeys[sid]) for sid in found}


def consensus_by_storey(depth: list[Candidate], colour: list[Candidate], wall_storey: dict[str, str],
                        counts: dict[str, dict[str, int]], classes: list[str],
                        run: Callable[[list[Candidate], list[Candidate], dict[str, int]], list[ConsensusHit]],
                        ) -> list[ConsensusHit]:
    """The consensus ``run(depth, colour, counts)`` on each storey with that storey's expected counts.

    ``wall_storey`` maps a wall id to its storey; a surface that is not a wall (a ceiling tile,
    a column face) belongs to the storey its id starts with (``S2-...``). A storey's expected
    counts limit only the instances on its own surfaces, so a storey whose candidates are
    weaker is not starved by another's. Returns the hits in class order, storey by storey.
    """
    def storey_of(wall_id: str) -> str | None:
        return wall_storey.get(wall_id) or next((sid for sid in counts if wall_id.startswith(f"{sid}-")), None)

    hits: list[ConsensusHit] = []
    for sid, cnt in counts.items():
        hits += run([c for c in depth if storey_of(c.wall_id) == sid], [c for c in colour if storey_of(c.wall_id) == sid],
                    {c: int(cnt.get(c, 0)) for c in classes})
    rank = {c: i for i, c in enumerate(classes)}
    return sorted(hits, key=lambda h: rank.get(h.class_id, len(rank)))


def _consensus(seg: Segmentation, walls: dict[str, WallResult], templates: dict[str, ModelTemplate],
               classes: list[str], expected: ExpectedCounts | None, s: DetectionSettings, progress: Progress,
               timings: dict[str, float], log: Callable[[str], None] | None = None) -> DetectionResult:
    progress(Stage.CONSENSUS, 0.0)
    t = time.perf_counter()
    orthos = {k: w.ortho for k, w in walls.items()}
    margin = s.consensus.mount_margin_m
    depth_c = within_wall_height([c for w in walls.values() for c in w.depth_candidates], orthos, margin_m=margin)
    colour_c = within_wall_height([c for w in walls.values() for c in w.colour_candidates], orthos, margin_m=margin)
    reliefs = model_reliefs(templates)
    frames = {k: (o.frame, o.pixel_m) for k, o in orthos.items()}  # one object seen on two pieces of a wall

    def run(d: list[Candidate], c: list[Candidate], counts: dict[str, int] | None) -> list[ConsensusHit]:
        return screened_consensus(d, c, counts, classes, s.consensus, s.confidence, reliefs=reliefs, frames=frames)

    per_storey = storey_counts(seg, expected, log)
    if per_storey is not None:
        chosen = consensus_by_storey(depth_c, colour_c, {w.id: w.storey for w in seg.walls}, per_storey, classes, run)
    else:
        chosen = run(depth_c, colour_c, None if expected is None else expected.counts)
    if s.confidence.enabled and s.confidence.report_unknown:  # regions like no class, for review
        chosen += unexplained_regions({k: w.depth_rois for k, w in walls.items()}, chosen, templates)
    detections = place_hits(chosen, orthos, templates)
    timings[Stage.CONSENSUS] = time.perf_counter() - t
    progress(Stage.CONSENSUS, 1.0)
    return DetectionResult(seg, walls, detections, timings, classes)


def detect(
    cloud: PointCloud,
    library: ModelLibrary,
    expected: Expected | None = None,
    settings: DetectionSettings | None = None,
    progress: Progress | None = None,
    pool: ProcessPoolExecutor | None = None,
) -> DetectionResult:
    """Run sections 3 and 4 of the paper on a registered coloured cloud in memory.

    ``expected`` maps class ids to instance counts (contract 3); classes not named are not
    searched. Without it every class of the library is searched with no count limit. As
    :class:`~sbsc_core.io.documents.ExpectedCounts` with per-storey counts for the storeys
    found, each storey's counts limit the instances on its walls (:func:`consensus_by_storey`).
    ``pool`` (see :func:`wall_pool`) runs the per-wall stages; by default one is made.
    With ``settings.ceilings`` / ``settings.columns`` enabled the ceilings and the columns'
    faces are searched too, as by :func:`detect_scans` (the result's ``surfaces``).
    :func:`detect_scans` does the same on scan files without holding the cloud.
    """
    s = settings or DetectionSettings()
    progress = progress or no_progress
    timings: dict[str, float] = {}
    expected = _as_expected(expected)
    s = searched_surfaces(s, library, expected)
    classes = _search_classes(library, None if expected is None else expected.counts)

    t0 = time.perf_counter()
    progress(Stage.SEGMENTATION, 0.0)
    seg = segment_floor_ceiling_walls(cloud, s.segmentation)
    columns = _columns_of(cloud, seg, s, sample=_regular_sample(cloud, s)) if s.columns.enabled else []
    timings[Stage.SEGMENTATION] = time.perf_counter() - t0

    t = time.perf_counter()
    templates = make_templates(library, s.orthoimage.pixel_m, classes)
    prototypes = learn_prototypes(templates, s.colour)
    timings["templates"] = time.perf_counter() - t
    walls = _collect_walls(_walls_results(cloud, seg, templates, prototypes, s, pool), len(seg.walls),
                           progress, timings)
    if s.ceilings.enabled or s.columns.enabled:  # objects on ceilings and columns (issue 11)
        beyond = _beyond_walls_in_memory(cloud, seg, library, expected, s, pool, progress, timings, columns)
        walls.update(beyond.walls)
        templates, classes = {**beyond.templates, **templates}, sorted(set(classes) | set(beyond.classes))
    result = _consensus(seg, walls, templates, classes, expected, s, progress, timings)
    if s.ceilings.enabled or s.columns.enabled:
        beyond.place(result)
    timings["total"] = time.perf_counter() - t0
    return result


def _regular_sample(cloud: PointCloud, s: DetectionSettings) -> PointCloud:
    """A regular sample of an in-memory cloud as big as the one :func:`detect_scans` measures
    the ceiling levels and the columns on (views, no copy)."""
    step = max(1, -(-len(cloud) // (2 * s.segmentation.fit_max_points)))
    return cloud if step == 1 else PointCloud(cloud.xyz[::step], cloud.rgb[::step], cloud.origin, cloud.sources)


def _columns_of(cloud: PointCloud, seg: Segmentation, s: DetectionSettings,
                log: Callable[[str], None] | None = None, *, sample: PointCloud | None = None) -> list:
    """The free-standing columns found in ``sample`` (default ``cloud``, the cloud the walls'
    point indices refer to); the walls that are a column's face are dropped from ``seg``
    (:func:`~sbsc_core.columns.walls_on_columns`)."""
    from .columns import find_columns, lone_short_walls, walls_on_columns

    lone = lone_short_walls(cloud, seg.walls, s.columns)
    columns = find_columns(cloud if sample is None else sample, seg, s.columns, lone_walls=lone)
    faces = set(walls_on_columns(cloud, seg, columns, s.columns, lone)) if columns and lone else set()
    if faces:
        seg.walls = [w for w in seg.walls if w.id not in faces]
        if log is not None:
            log(f"{', '.join(sorted(faces))}: a column's face, not a wall")
    return columns


def _beyond_walls_in_memory(cloud: PointCloud, seg: Segmentation, library: ModelLibrary,
                            expected: ExpectedCounts | None, s: DetectionSettings,
                            pool: ProcessPoolExecutor | None, progress: Progress,
                            timings: dict[str, float], columns: list) -> _BeyondWalls:
    """:func:`_beyond_walls` on an in-memory cloud: the levels are measured on a regular
    sample of it (as :func:`detect_scans` does; ``columns`` were found before the walls'
    stages), its points are binned into the surfaces' partitions in a temporary folder in
    this process, and the surfaces' stages run in ``pool`` (or one made here), their images
    kept in the results."""
    import tempfile

    from .ceilings import ceiling_levels, memory_parts

    levels = ceiling_levels(_regular_sample(cloud, s), seg, s.ceilings) if s.ceilings.enabled else None
    own = pool is None
    executor: Executor = (wall_pool(s) if own else pool) or InlineExecutor()
    try:
        with tempfile.TemporaryDirectory(prefix=".sbsc-surfaces-", dir=os.environ.get("SBSC_SCRATCH_DIR")) as tmp:
            return _beyond_walls(memory_parts(cloud), np.asarray(cloud.origin, np.float64), seg, levels, columns,
                                 library, expected, s, executor=executor, scratch=Path(tmp), parked=None,
                                 in_flight=2 * max(1, _worker_count(s)), progress=progress, timings=timings,
                                 log=lambda msg: None, part_executor=InlineExecutor())
    finally:
        if own and isinstance(executor, ProcessPoolExecutor):
            executor.shutdown(wait=True, cancel_futures=True)


# --------------------------------------------------------------------------- out of core


class InlineExecutor(Executor):
    """Runs each task at once in this process (one worker, or a single wall)."""

    def submit(self, fn, /, *args, **kwargs) -> Future:  # type: ignore[override]
        fut: Future = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller through the future
            fut.set_exception(exc)
        return fut


@contextlib.contextmanager
def wall_executor(settings: DetectionSettings, scheduler: str | None = None) -> Iterator[Executor]:
    """Where the per-part and per-wall tasks run.

    With ``scheduler`` (``tcp://HOST:PORT``) they run on that Dask distributed cluster, whose
    workers must reach the scan files and the scratch folder at the same paths; otherwise in
    a local pool of ``settings.workers`` spawned processes (in this process for one worker).
    """
    if scheduler:
        try:
            from distributed import Client
        except ImportError:  # pragma: no cover - a declared dependency
            raise InputError("--scheduler", "dask distributed is not installed") from None
        try:
            client = Client(scheduler, set_as_default=False, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError("--scheduler", f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
        try:
            yield client.get_executor(pure=False)
        finally:
            client.close()
        return
    pool = wall_pool(settings)
    if pool is None:
        yield InlineExecutor()
        return
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _as_done(ex: Executor, jobs: Iterable[tuple], fn: Callable, in_flight: int) -> Iterator[tuple[int, object]]:
    """``(k, fn(*job))`` for the k-th job, as the tasks finish, with at most ``in_flight`` submitted at once.

    A new job is submitted as soon as any task finishes (not only the oldest), so that a
    long task never leaves the other workers idle; the caller puts the results back in
    order where it matters. Tasks finished together are given in job order.
    """
    pending: dict[Future, int] = {}
    todo = enumerate(jobs)
    try:
        for k, job in itertools.islice(todo, in_flight):
            pending[ex.submit(fn, *job)] = k
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(done, key=pending.__getitem__):
                k = pending.pop(fut)
                res = fut.result()
                nxt = next(todo, None)
                if nxt is not None:
                    pending[ex.submit(fn, *nxt[1])] = nxt[0]
                yield k, res
    finally:
        for f in pending:
            f.cancel()


def _in_order(ex: Executor, jobs: Iterable[tuple], fn: Callable, in_flight: int) -> Iterator:
    """Results of ``fn(*job)`` in job order, computed as by :func:`_as_done` (a result that is
    ready early waits for the ones before it)."""
    ready: dict[int, object] = {}
    nxt = 0
    for k, res in _as_done(ex, jobs, fn, in_flight):
        ready[k] = res
        while nxt in ready:
            yield ready.pop(nxt)
            nxt += 1


def surface_stage(executor: Executor, *, stage: str, part_fn: Callable, part_jobs: list[tuple], job_fn: Callable,
                  surfaces: Sequence, library: ModelLibrary, classes: list[str], s: DetectionSettings,
                  scratch: Path, parked: Path | None, in_flight: int, progress: Progress,
                  part_executor: Executor | None = None,
                  ) -> tuple[np.ndarray, dict[str, WallResult], dict[str, ModelTemplate]]:
    """A stage on surfaces beyond the walls (ceiling tiles, column faces), run as the walls' is.

    ``part_fn(*job)`` bins one scan part's points into the surfaces' partitions and returns
    the points written per surface; then ``job_fn(scratch, k, surface, templates, prototypes,
    s)`` runs the walls' stages on surface number ``k`` and returns ``(id, result, timings)``.
    Surfaces that got no point are left out (no work, no result). Returns the points binned
    per surface, the results by surface id (their images parked in ``parked``,
    :func:`park_wall`, unless it is None) and the templates of ``classes``. ``part_executor`` (default:
    ``executor``) runs the binning (an in-memory cloud's parts are binned in this process).
    """
    kept = np.zeros(len(surfaces), np.int64)
    for _, written in _as_done(part_executor or executor, part_jobs, part_fn, in_flight):
        kept += np.asarray(written, np.int64)
    templates, prototypes = _templates_job(library, s, classes)
    jobs = [(str(scratch), k, sf, templates, prototypes, s) for k, sf in enumerate(surfaces) if kept[k] > 0]
    results: dict[str, WallResult] = {}
    for i, (sid, res, _) in enumerate(_in_order(executor, jobs, job_fn, in_flight)):
        results[sid] = res if parked is None else park_wall(res, parked)
        progress(stage, (i + 1) / len(jobs))
    return kept, results, templates


@dataclass
class _BeyondWalls:
    """What the ceiling and column stages add to the walls' results for the consensus."""

    walls: dict[str, WallResult] = field(default_factory=dict)
    templates: dict[str, ModelTemplate] = field(default_factory=dict)
    classes: list[str] = field(default_factory=list)
    surfaces: list[dict] = field(default_factory=list)
    faces: dict = field(default_factory=dict)  # column faces by id

    def place(self, result: DetectionResult) -> None:
        """Name each detection's surface kind and put those on a round column back on it."""
        if not self.surfaces:
            return
        kinds = {sf["id"]: sf["kind"] for sf in self.surfaces}
        for d in result.detections:
            d.surface = kinds.get(d.wall_id)
            if d.wall_id in self.faces:  # a round column's face is unrolled: put the object back on it
                d.u = self.faces[d.wall_id].arc_u(d.u)
                d.position = self.faces[d.wall_id].to_world(d.u, d.v)
        result.surfaces = self.surfaces


def _beyond_walls(parts: Sequence, origin: np.ndarray, seg: Segmentation, levels: list | None, columns: list,
                  library: ModelLibrary, expected: ExpectedCounts | None, s: DetectionSettings, *,
                  executor: Executor, scratch: Path, parked: Path | None, in_flight: int, progress: Progress,
                  timings: dict[str, float], log: Callable[[str], None],
                  part_executor: Executor | None = None) -> _BeyondWalls:
    """The ceiling tiles' and column faces' results (issue 11), when the settings ask for them."""
    out = _BeyondWalls()
    counts = None if expected is None else expected.counts
    if s.ceilings.enabled:  # objects on ceilings: the tiles join the walls in the consensus
        from .ceilings import detect_ceilings

        ceil = detect_ceilings(parts, origin, seg, library, counts, s, executor=executor, scratch=scratch,
                               parked=parked, in_flight=in_flight, progress=progress, timings=timings, log=log,
                               levels=levels, part_executor=part_executor)
        out.walls.update(ceil.walls)
        out.templates.update(ceil.templates)
        out.classes = sorted(set(out.classes) | set(ceil.classes))
        out.surfaces += ceil.surfaces()
    if columns:  # objects on columns: their faces join the walls in the consensus too
        from .columns import detect_columns

        cols = detect_columns(parts, origin, columns, library, counts, s, executor=executor, scratch=scratch,
                              parked=parked, in_flight=in_flight, progress=progress, timings=timings, log=log,
                              part_executor=part_executor)
        out.walls.update(cols.walls)
        out.templates = {**cols.templates, **out.templates}
        out.classes = sorted(set(out.classes) | set(cols.classes))
        out.surfaces += cols.surfaces()
        out.faces = {f.id: f for f in cols.faces}
    return out


def _storey_points(executor: Executor, parts: Sequence, sample_meta: list[tuple[int, bool]], origin: np.ndarray,
                   sources: Sequence[str], points: int, s: DetectionSettings, *, scratch: Path, in_flight: int,
                   log: Callable[[str], None]) -> StoreyPoints:
    """The ``storey_points`` of :func:`segment_storeys` for a scan of ``points`` points read out
    of core: one more pass over the parts (:func:`~sbsc_core.storey_samples.storey_part`)
    writes each storey's points at its own sample density (from its share of the sample),
    then each storey's cloud is read back in turn."""
    limit = 2 * s.segmentation.fit_max_points

    def read(bounds: list[tuple[float, float]], shares: list[float]) -> Iterator[PointCloud]:
        t = time.perf_counter()
        steps = storey_steps(shares, points, limit)
        jobs = [(part, origin, bounds, steps, str(scratch), n, spilled)
                for part, (n, spilled) in zip(parts, sample_meta, strict=True)]
        written = np.zeros(len(bounds), np.int64)
        for _, got in _as_done(executor, jobs, storey_part, in_flight):
            written += np.asarray(got, np.int64)
        log(f"{len(bounds)} storeys read again at their own density in {time.perf_counter() - t:.1f} s: "
            + ", ".join(f"S{k + 1} {int(n):,} points (every {st})"
                        for k, (n, st) in enumerate(zip(written, steps, strict=True))))
        for k in range(len(bounds)):
            yield storey_cloud(scratch, parts, k, origin, sources, limit)

    return read


def detect_scans(
    scans: Sequence[Path],
    library: ModelLibrary,
    expected: Expected | None = None,
    settings: DetectionSettings | None = None,
    progress: Progress | None = None,
    *,
    executor: Executor,
    scratch: Path,
    log: Callable[[str], None] | None = None,
    origin: np.ndarray | None = None,
) -> tuple[DetectionResult, int]:
    """:func:`detect` on scan files, out of core (see :mod:`sbsc_core.partition`).

    Every part of the files is read by a task of ``executor``: once for a bounded regular
    sample that segmentation runs on, once more (or from its spill) to write each wall's
    binned points to its partition in ``scratch``; each wall's stages then run as a task on
    its partition. Each wall's task writes the wall's images to ``scratch/images``
    (:func:`park_wall`), so the result holds no orthoimage: write it with
    ``write_outputs(..., parked=scratch / "images")``. ``origin`` is the recentring origin
    (default: :func:`~sbsc_core.partition.scan_origin` of the first file). Returns the result
    and the number of points read.
    """
    s = settings or DetectionSettings()
    progress = progress or no_progress
    log = log or (lambda msg: None)
    timings: dict[str, float] = {}
    expected = _as_expected(expected)
    s = searched_surfaces(s, library, expected)
    classes = _search_classes(library, None if expected is None else expected.counts)
    workers = max(1, _worker_count(s))
    t0 = time.perf_counter()

    progress(Stage.READING, 0.0)
    parts, estimate = plan_parts([Path(p) for p in scans])
    origin = scan_origin(scans[0]) if origin is None else np.asarray(origin, np.float64)
    step = sample_step(estimate, s)
    sample_jobs = [(part, origin, step, str(scratch)) for part in parts]
    samples: list = [None] * len(parts)
    if workers > 1:  # this process waits while the workers read: it imports what segmentation needs meanwhile
        threading.Thread(target=importlib.import_module, args=("scipy.signal",), daemon=True).start()
    gathered = SampleBuffer(parts, step)  # each sample copied into the cloud while the others are read
    names = station_names(parts)
    refine = len(names) > 1 and s.registration.enabled
    per_station = Counter(p.station for p in parts)
    stations = StationSamples(len(names), station_sample_points(len(names), s.registration),
                              [per_station[k] for k in range(len(names))]) if refine else None
    for i, (k, smp) in enumerate(_as_done(executor, sample_jobs, sample_part, 2 * workers)):
        if stations is not None:
            stations.add(parts[k].station, smp.xyz)
        samples[k] = gathered.add(k, smp)
        progress(Stage.READING, (i + 1) / len(parts))
    points = sum(smp.points for smp in samples)
    sources = [str(p) for p in scans]
    records: list[dict] = []
    if stations is not None:  # one file per station: their disagreement is removed first
        t = time.perf_counter()
        registration = refine_registration([stations.station(k) for k in range(len(names))],
                                           settings=s.registration, log=log)
        del stations
        parts = [p.posed(registration.poses[p.station]) for p in parts]
        for k, p in enumerate(parts):
            gathered.move(k, samples, p.pose)
        timings["registration"] = time.perf_counter() - t
        records = registration.records(names)
        moved = [r for r in records if r["rotation_deg"] > 0 or any(r["translation_m"])]
        log(f"registration refined in {timings['registration']:.1f} s: {len(registration.edges)} overlapping pairs "
            f"of {len(names)} stations in {len(registration.groups)} group(s); "
            + (f"largest move {max(np.linalg.norm(r['translation_m']) for r in moved) * 1000:.1f} mm"
               if moved else "nothing moved"))
    cloud = gathered.cloud(samples, origin, sources, 2 * s.segmentation.fit_max_points)
    sample_meta = [(smp.points, smp.spilled) for smp in samples]
    samples.clear()
    timings[Stage.READING] = time.perf_counter() - t0
    log(f"read {points:,} points from {len(scans)} file(s) in {timings['reading']:.1f} s "
        f"(sample of {len(cloud):,} for segmentation)")

    t = time.perf_counter()
    progress(Stage.SEGMENTATION, 0.0)
    # the workers are idle while segmentation runs here: they import the per-wall stages and
    # make the templates now
    warm = [executor.submit(_ready) for _ in range(workers)] if workers > 1 else []
    made = executor.submit(_templates_job, library, s, classes) if workers > 1 else None
    found = find_scan_storeys(cloud, s.segmentation)
    sampled = len(cloud)
    if len(found.levels) > 1 and sampled < points:
        # several storeys in a thinned sample: each is read again at the density it has when
        # scanned alone (the sample is let go first unless the ceilings or columns need it)
        if not (s.columns.enabled or s.ceilings.enabled):
            del cloud
        seg = segment_storeys(found, _storey_points(executor, parts, sample_meta, found.origin, sources, points, s,
                                                    scratch=Path(scratch), in_flight=2 * workers, log=log),
                              s.segmentation, point_index=False)
    else:
        seg = segment_floor_ceiling_walls(cloud, s.segmentation, storeys=found)
    if seg.stray_points:  # counted in the sample: scaled to the whole scan
        seg.stray_points = int(round(seg.stray_points * points / max(sampled, 1)))
    found_columns = []
    if s.columns.enabled:  # free-standing columns (issue 11), found in the sample
        found_columns = _columns_of(cloud, seg, s, log)
    levels = None
    if s.ceilings.enabled:  # lower ceilings within a storey (stepped ceilings), measured in the sample
        from .ceilings import ceiling_levels

        levels = ceiling_levels(cloud, seg, s.ceilings)
    cloud = None
    for wall in seg.walls:  # indices into the sample: the walls' points come from their partitions
        wall.point_index = np.zeros(0, np.int64)
    for f in warm:
        f.cancel()  # not started yet: not needed (a worker that imports it runs a wall task later)
    timings[Stage.SEGMENTATION] = time.perf_counter() - t
    if len(seg.storeys) > 1:  # named before the long stages start
        log(f"{len(seg.storeys)} storeys: " + ", ".join(
            f"{st.id} (z {st.floor_z:.2f} to {st.ceiling_z:.2f} m, {sum(w.storey == st.id for w in seg.walls)} walls)"
            for st in seg.storeys))

    t = time.perf_counter()
    progress(Stage.PARTITION, 0.0)
    index = WallIndex.build(seg.walls, origin, s.segmentation)
    part_jobs = [(part, origin, index, str(scratch), n, spilled, s.orthoimage)
                 for part, (n, spilled) in zip(parts, sample_meta, strict=True)]
    kept = np.zeros(len(seg.walls), np.int64)
    for i, (_, written) in enumerate(_as_done(executor, part_jobs, partition_part, 2 * workers)):
        kept += np.asarray(written, np.int64)
        progress(Stage.PARTITION, (i + 1) / len(parts))
    timings[Stage.PARTITION] = time.perf_counter() - t
    log(f"{len(seg.walls)} walls: {int(kept.sum()):,} points binned into their partitions "
        f"in {timings['partition']:.1f} s")

    t = time.perf_counter()
    templates, prototypes = made.result() if made is not None else _templates_job(library, s, classes)
    timings["templates"] = time.perf_counter() - t
    # the biggest walls first, so that no worker is left with a big one at the end; the
    # results are put back in the walls' order (the consensus sees them as in memory)
    order = sorted(range(len(seg.walls)), key=lambda w: -int(kept[w]))
    parked = Path(scratch) / "images"
    parked.mkdir(exist_ok=True)
    # each task writes its wall's images itself: this process only receives the small results
    wall_jobs = [(str(scratch), w, seg.walls[w].id, seg.walls[w].frame, templates, prototypes, s, str(parked))
                 for w in order]
    with ThreadPoolExecutor(max_workers=1) as cleaner:  # frees the disk while the walls run, not at the end

        def results() -> Iterator[tuple[str, WallResult, dict[str, float]]]:
            for k, res in _as_done(executor, wall_jobs, _partition_wall_job, 2 * workers):
                cleaner.submit(drop_wall_partition, scratch, order[k])  # its points are not read again
                yield res

        done = _collect_walls(results(), len(seg.walls), progress, timings)
    walls = {wall.id: done[wall.id] for wall in seg.walls}
    beyond = _beyond_walls(parts, origin, seg, levels, found_columns, library, expected, s, executor=executor,
                           scratch=Path(scratch), parked=parked, in_flight=2 * workers, progress=progress,
                           timings=timings, log=log)
    walls.update(beyond.walls)
    if s.ceilings.enabled or found_columns:
        templates, classes = {**beyond.templates, **templates}, sorted(set(classes) | set(beyond.classes))
    result = _consensus(seg, walls, templates, classes, expected, s, progress, timings, log)
    beyond.place(result)
    result.registration = records
    timings["total"] = time.perf_counter() - t0
    return result, points


def detect_to_dir(
    scans: Sequence[Path],
    models: Path,
    *,
    expected: Path | Expected | None = None,
    out: Path,
    settings_file: Path | None = None,
    settings: DetectionSettings | None = None,
    log: Callable[[str], None] | None = None,
    progress: Progress | None = None,
    scheduler: str | None = None,
    scratch: Path | None = None,
) -> dict:
    """``sbsc detect``: read, detect, write every output atomically; return a summary dict.

    The scans are streamed (:func:`detect_scans`); ``scheduler`` runs the work on a Dask
    cluster (:func:`wall_executor`); ``scratch`` (default ``$SBSC_SCRATCH_DIR``, else the
    output's parent folder) holds the partitions while the command runs.
    """
    log = log or (lambda msg: None)
    progress = progress or no_progress
    s = settings or load_settings(settings_file)
    progress(Stage.READING, 0.0)
    paths = [Path(p) for p in scans]
    if not paths:
        raise InputError("scans", "no scan files given")
    stack = contextlib.ExitStack()
    ex = stack.enter_context(wall_executor(s, scheduler))  # the workers start while the inputs are read
    try:
        from .io.documents import read_expected_counts
        from .io.models import load_model_library

        library = load_model_library(Path(models))
        counts = read_expected_counts(expected) if isinstance(expected, (str, Path)) else expected
        origin = scan_origin(paths[0])  # read once: the recentring origin and the georeference
        georef = georeference_fields(scan_crs(paths), origin)
    except BaseException:
        stack.close()
        raise
    with stack, scratch_folder(Path(out), scratch) as work:
        result, points = detect_scans(paths, library, counts, s, progress, executor=ex, scratch=work, log=log,
                                      origin=origin)
        seg = result.segmentation
        if seg.stray_points:
            log(f"ignored about {seg.stray_points:,} stray points outside the dense part of the scan")
        per_storey = storey_counts(seg, _as_expected(counts)) or {}
        for st in seg.storeys:
            walls = [w for w in seg.walls if w.storey == st.id]
            found = sum(1 for d in result.detections if d.wall_id in {w.id for w in walls})
            of = f" of {sum(per_storey[st.id].values())} expected" if st.id in per_storey else ""
            log(f"storey {st.id}: floor z = {st.floor_z:.2f} m, ceiling z = {st.ceiling_z:.2f} m, "
                f"{len(walls)} walls, {found} objects{of}")
            if st.ceiling_z - st.floor_z > _TALL_STOREY_M:
                log(f"warning: storey {st.id} is {st.ceiling_z - st.floor_z:.1f} m high; if it is several "
                    "storeys, no slab between them was seen (check the scan)")
        log(f"{len(seg.walls)} walls, {len(result.openings)} openings, "
            f"{len(result.detections)} objects in {result.timings['total']:.1f} s")
        progress(Stage.WRITING, 0.0)
        with atomic_output_dir(out) as tmp:
            write_outputs(result, tmp, s.orthoimage.pixel_m, extra=georef, parked=work / "images", executor=ex)
    progress(Stage.DONE, 1.0)
    return {
        "points": points,
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


def overlay_image(w: WallResult, detections: Sequence[Detection], colour_bgr: np.ndarray | None = None) -> np.ndarray:
    """The colour orthoimage with depth RoIs (cyan), colour RoIs (magenta) and red spots (BGR).

    ``colour_bgr`` is the colour orthoimage when ``w`` no longer holds it (see :func:`park_wall`).
    """
    img = cv2.cvtColor(w.ortho.colour, cv2.COLOR_RGB2BGR).copy() if colour_bgr is None else colour_bgr.copy()
    for b in w.depth_rois:
        cv2.rectangle(img, (b.c0, b.r0), (b.c1 - 1, b.r1 - 1), (255, 255, 0), 1)
    for b in w.colour_rois:
        cv2.rectangle(img, (b.c0, b.r0), (b.c1 - 1, b.r1 - 1), (255, 0, 255), 1)
    for d in detections:
        r, c = w.ortho.uv_to_pixel(d.u, d.v)
        cv2.circle(img, (int(round(float(c))), int(round(float(r)))), 6, (0, 0, 255), -1)
    return img


def _write_wall_images(ortho: Orthoimage, images: Path) -> None:
    """The colour and depth images of one wall (``<wall>_colour.png``, ``_depth.png``, ``_depth.npy``)."""
    wid = ortho.wall_id
    if not cv2.imwrite(str(images / f"{wid}_colour.png"), cv2.cvtColor(ortho.colour, cv2.COLOR_RGB2BGR)):
        raise SbscError(f"{images}: cannot write images")
    cv2.imwrite(str(images / f"{wid}_depth.png"), depth_visualisation(ortho.depth))
    np.save(images / f"{wid}_depth.npy", ortho.depth.astype(np.float32))


_PARKED = np.zeros((0, 0), bool)


def park_wall(res: WallResult, images: Path) -> WallResult:
    """Write a wall's images now and keep only what the consensus and the documents need.

    The orthoimages and masks (about 10 bytes a pixel) are the part of a wall's result that
    grows with the building; :func:`write_outputs` with ``parked=images`` moves the images
    into the output and draws the overlays from the colour images on disk.
    """
    _write_wall_images(res.ortho, images)
    o = res.ortho
    ortho = Orthoimage(wall_id=o.wall_id, frame=o.frame, pixel_m=o.pixel_m, colour=np.zeros((0, 0, 3), np.uint8),
                       depth=np.zeros((0, 0), np.float32), mask=_PARKED)
    area = WallArea(visible=_PARKED, openings=res.area.openings, opening_mask=_PARKED,
                    wall_colour=res.area.wall_colour)
    return WallResult(ortho, area, res.depth_rois, res.colour_rois, res.depth_candidates, res.colour_candidates)


def _parked_overlay_job(parked: str, w: WallResult, detections: list[Detection]) -> str:
    """Draw a parked wall's overlay from its colour image in ``parked`` and write it there."""
    wid = w.ortho.wall_id
    colour = cv2.imread(str(Path(parked) / f"{wid}_colour.png"), cv2.IMREAD_COLOR)
    if not cv2.imwrite(str(Path(parked) / f"{wid}_overlay.png"), overlay_image(w, detections, colour)):
        raise SbscError(f"{parked}: cannot write images")
    return wid


def write_outputs(result: DetectionResult, out: Path, pixel_m: float, extra: dict | None = None,
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
    from .io.documents import detections_document

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
