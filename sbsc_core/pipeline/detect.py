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
    (:mod:`sbsc_core.recognition.suggestions`).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import (
    Executor,
    Future,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
)
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..imaging.partition import (
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
)
from ..io.atomic import atomic_output_dir
from ..io.crs import georeference_fields, scan_crs
from ..recognition.colour_recognition import (
    learn_prototypes,
)
from ..recognition.confidence import model_reliefs, screened_consensus, unexplained_regions
from ..recognition.consensus import ConsensusHit
from ..recognition.mounting import within_wall_height
from ..recognition.placement import place_hits
from ..recognition.templates import ModelTemplate, make_templates
from ..scene.registration import StationSamples, refine_registration, station_sample_points
from ..scene.segmentation import (
    StoreyPoints,
    find_scan_storeys,
    segment_floor_ceiling_walls,
    segment_storeys,
)
from ..scene.storey_samples import storey_cloud, storey_part, storey_steps
from ..settings import DetectionSettings, load_settings
from ..stages import Progress, Stage, no_progress
from ..types import (
    Candidate,
    ModelLibrary,
    PointCloud,
    Segmentation,
)
from .executors import (
    InlineExecutor,
    _as_done,
    _walls_results,
    call_job,
    close_pool,
    wall_executor,
    wall_pool,
)
from .outputs import DetectionResult, write_outputs
from .walls import (
    WALL_STAGES,
    WallResult,
    _as_expected,
    _partition_wall_job,
    _templates_job,
    search_classes,
    searched_surfaces,
)
from .worker_env import _ready, _worker_count

_TALL_STOREY_M = 5.0  # a storey higher than this is named in a warning (several storeys taken as one?)


if TYPE_CHECKING:  # the documents (and pydantic) are imported where used: the wall workers never need them
    from ..io.documents import ExpectedCounts
    from ..scene.ceilings import CeilingBinning, CeilingResults
    from .walls import Expected


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
                        *, counts: dict[str, dict[str, int]], classes: list[str],
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
               classes: list[str], expected: ExpectedCounts | None, *, s: DetectionSettings, progress: Progress,
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
        return screened_consensus(d, c, counts, classes, consensus_settings=s.consensus,
                                  settings=s.confidence, reliefs=reliefs, frames=frames)

    per_storey = storey_counts(seg, expected, log)
    if per_storey is not None:
        chosen = consensus_by_storey(depth_c, colour_c, {w.id: w.storey for w in seg.walls},
                                     counts=per_storey, classes=classes, run=run)
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
    *, settings: DetectionSettings | None = None,
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

    Parameters
    ----------
    cloud
        The registered coloured cloud (contract 1, read with :func:`~sbsc_core.io.scans.read_scans`).
    library
        The model library (contract 2).
    expected
        Instances per class (contract 3), or with per-storey counts; None: every class, no limit.
    settings
        Every threshold of the method; None: the defaults.
    progress
        Called with each :class:`~sbsc_core.stages.Stage` and the fraction of it done.
    pool
        The process pool the walls run on; None: one is made for the call.

    Returns
    -------
    DetectionResult
        The segmentation, each wall's images and candidates, the detections and seconds per stage.
    """
    s = settings or DetectionSettings()
    progress = progress or no_progress
    timings: dict[str, float] = {}
    expected = _as_expected(expected)
    s = searched_surfaces(s, library, expected)
    classes = search_classes(library, None if expected is None else expected.counts)

    t0 = time.perf_counter()
    progress(Stage.SEGMENTATION, 0.0)
    seg = segment_floor_ceiling_walls(cloud, s.segmentation)
    columns = _columns_of(cloud, seg, s, sample=_regular_sample(cloud, s)) if s.columns.enabled else []
    timings[Stage.SEGMENTATION] = time.perf_counter() - t0

    t = time.perf_counter()
    templates = make_templates(library, s.orthoimage.pixel_m, classes)
    prototypes = learn_prototypes(templates, s.colour)
    timings["templates"] = time.perf_counter() - t
    walls = _collect_walls(_walls_results(cloud, seg, templates, prototypes, s, pool=pool), len(seg.walls),
                           progress, timings)
    if s.ceilings.enabled or s.columns.enabled:  # objects on ceilings and columns (issue 11)
        beyond = _beyond_walls_in_memory(cloud, seg, library, expected, s, pool=pool, progress=progress, timings=timings, columns=columns)
        walls.update(beyond.walls)
        templates, classes = {**beyond.templates, **templates}, sorted(set(classes) | set(beyond.classes))
    result = _consensus(seg, walls, templates, classes, expected, s=s, progress=progress, timings=timings)
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
    (:func:`~sbsc_core.scene.columns.walls_on_columns`)."""
    from ..scene.columns import find_columns, lone_short_walls, walls_on_columns

    lone = lone_short_walls(cloud, seg.walls, s.columns)
    columns = find_columns(cloud if sample is None else sample, seg, s.columns, lone_walls=lone)
    faces = set(walls_on_columns(cloud, seg, columns, s.columns, lone)) if columns and lone else set()
    if faces:
        seg.walls = [w for w in seg.walls if w.id not in faces]
        if log is not None:
            log(f"{', '.join(sorted(faces))}: a column's face, not a wall")
    return columns


def _pendants_of(cloud: PointCloud, seg: Segmentation, library: ModelLibrary, expected: ExpectedCounts | None,
                 s: DetectionSettings, *, columns: list, levels: list | None,
                 log: Callable[[str], None] | None = None) -> list:
    """The panels hanging from the ceilings found in ``cloud`` (the segmentation sample), when
    ceilings are searched (:func:`~sbsc_core.scene.pendants.find_pendants`): as big as the
    classes that may be on a ceiling."""
    if not (s.ceilings.enabled and s.pendants.enabled):
        return []
    from ..scene.pendants import find_pendants

    classes = search_classes(library, None if expected is None else expected.counts, kind="ceiling")
    sizes = [(library[c].width_m, library[c].height_m) for c in classes]
    faces = find_pendants(cloud, seg, s.pendants, sizes=sizes, columns=columns, levels=levels)
    if faces and log is not None:
        log(f"{len(faces)} panel(s) hanging from the ceiling: " + ", ".join(
            f"{f.id} ({f.frame.width_m - 2 * s.pendants.margin_m:.2f} m wide)" for f in faces))
    return faces


def _beyond_walls_in_memory(cloud: PointCloud, seg: Segmentation, library: ModelLibrary,
                            expected: ExpectedCounts | None, s: DetectionSettings,
                            *, pool: ProcessPoolExecutor | None, progress: Progress,
                            timings: dict[str, float], columns: list) -> _BeyondWalls:
    """:func:`_beyond_walls` on an in-memory cloud: the levels are measured on a regular
    sample of it (as :func:`detect_scans` does; ``columns`` were found before the walls'
    stages), its points are binned into the surfaces' partitions in a temporary folder in
    this process, and the surfaces' stages run in ``pool`` (or one made here), their images
    kept in the results."""
    import tempfile

    from ..scene.ceilings import ceiling_levels, memory_parts

    sample = _regular_sample(cloud, s)
    levels = ceiling_levels(sample, seg, s.ceilings) if s.ceilings.enabled else None
    pendants = _pendants_of(sample, seg, library, expected, s, columns=columns, levels=levels)
    own = pool is None
    executor: Executor = (wall_pool(s) if own else pool) or InlineExecutor()
    try:
        with tempfile.TemporaryDirectory(prefix=".sbsc-surfaces-", dir=os.environ.get("SBSC_SCRATCH_DIR")) as tmp:
            return _beyond_walls(memory_parts(cloud), np.asarray(cloud.origin, np.float64), seg,
                                 levels=levels, columns=columns, pendants=pendants,
                                 library=library, expected=expected, s=s, executor=executor,
                                 scratch=Path(tmp), parked=None,
                                 in_flight=2 * max(1, _worker_count(s)), progress=progress, timings=timings,
                                 log=lambda msg: None, part_executor=InlineExecutor())
    finally:
        if own and isinstance(executor, ProcessPoolExecutor):
            close_pool(executor)


# --------------------------------------------------------------------------- out of core


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
        # an object on a pendant hangs from the ceiling: its surface is the ceiling (contract 4)
        kinds = {sf["id"]: "ceiling" if sf["kind"] == "pendant" else sf["kind"] for sf in self.surfaces}
        for d in result.detections:
            d.surface = kinds.get(d.wall_id)
            if d.wall_id in self.faces:  # a round column's face is unrolled: put the object back on it
                d.u = self.faces[d.wall_id].arc_u(d.u)
                d.position = self.faces[d.wall_id].to_world(d.u, d.v)
        result.surfaces = self.surfaces


def _beyond_walls(parts: Sequence, origin: np.ndarray, seg: Segmentation, *, levels: list | None,
                  columns: list, pendants: list = (),
                  library: ModelLibrary, expected: ExpectedCounts | None, s: DetectionSettings,
                  executor: Executor, scratch: Path, parked: Path | None, in_flight: int, progress: Progress,
                  timings: dict[str, float], log: Callable[[str], None],
                  part_executor: Executor | None = None, ceilings_done: CeilingResults | None = None,
                  ) -> _BeyondWalls:
    """The ceiling tiles' and column faces' results (issue 11), when the settings ask for them.

    ``ceilings_done``: the ceiling tiles' results, when they ran with the walls (:class:`_TilesAlong`)."""
    out = _BeyondWalls()
    counts = None if expected is None else expected.counts
    if s.ceilings.enabled:  # objects on ceilings: the tiles join the walls in the consensus
        from .surfaces import detect_ceilings

        ceil = ceilings_done or detect_ceilings(
            parts, origin, seg, library=library, expected=counts, s=s, executor=executor, scratch=scratch,
            parked=parked, in_flight=in_flight, progress=progress, timings=timings, log=log,
            levels=levels, part_executor=part_executor)
        out.walls.update(ceil.walls)
        out.templates.update(ceil.templates)
        out.classes = sorted(set(out.classes) | set(ceil.classes))
        out.surfaces += ceil.surfaces()
    if columns:  # objects on columns: their faces join the walls in the consensus too
        from .surfaces import detect_columns

        cols = detect_columns(parts, origin, columns, library=library, expected=counts, s=s,
                              executor=executor, scratch=scratch,
                              parked=parked, in_flight=in_flight, progress=progress, timings=timings, log=log,
                              part_executor=part_executor)
        out.walls.update(cols.walls)
        out.templates = {**cols.templates, **out.templates}
        out.classes = sorted(set(out.classes) | set(cols.classes))
        out.surfaces += cols.surfaces()
        out.faces = {f.id: f for f in cols.faces}
    if pendants:  # objects hanging from the ceilings: their panels join the walls in the consensus too
        from .surfaces import detect_pendants

        pend = detect_pendants(parts, origin, list(pendants), library=library, expected=counts, s=s,
                               executor=executor, scratch=scratch, parked=parked, in_flight=in_flight,
                               progress=progress, timings=timings, log=log, part_executor=part_executor)
        out.walls.update(pend.walls)
        out.templates = {**pend.templates, **out.templates}
        out.classes = sorted(set(out.classes) | set(pend.classes))
        out.surfaces += pend.surfaces()
    return out


class _TilesAlong:
    """The ceiling tiles that the walls' partition pass binned (``binning``, None: none), as
    tasks of the walls' stream: their jobs, then their results as they come.

    The tiles' templates are ``made`` in a worker while segmentation runs (None: made here).
    """

    def __init__(self, binning: CeilingBinning | None, *, scratch: Path, classes: list[str], made: Future | None,
                 library: ModelLibrary, s: DetectionSettings) -> None:
        self.binning, self.scratch, self.classes = binning, scratch, classes
        self.made, self.library, self.s = made, library, s
        self.done: dict[int, tuple[str, WallResult]] = {}
        self.seconds = 0.0
        self.kept = np.zeros(0, np.int64)  # points binned per tile (set by :meth:`jobs`)
        self.templates: dict[str, ModelTemplate] = {}  # the tiles' templates (set by :meth:`jobs`)

    def jobs(self, parked: Path) -> list[tuple[int, tuple[str, int], Callable, dict]]:
        """``(points, ("tile", k), job function, its arguments)`` for every tile that got points."""
        if self.binning is None:
            return []
        from ..scene.ceilings import binned_records
        from .surfaces import ceiling_tile_job

        self.kept = binned_records(self.scratch, len(self.binning.tiles))
        made = self.made.result() if self.made is not None else _templates_job(self.library, self.s, self.classes)
        self.templates, prototypes = made
        return [(int(n), ("tile", k), ceiling_tile_job,
                 dict(scratch=str(self.scratch), k=k, tile=tile, templates=self.templates, prototypes=prototypes,
                      s=self.s, images=str(parked)))
                for k, (tile, n) in enumerate(zip(self.binning.tiles, self.kept, strict=True)) if n > 0]

    def add(self, k: int, res: tuple[str, WallResult, dict[str, float]], *, progress: Progress | None) -> None:
        """Tile ``k``'s result; its progress told when ``progress`` is given (the walls are done)."""
        self.done[k] = res[:2]
        self.seconds += sum(res[2].values())
        if progress is not None:
            self.progress(progress)

    def progress(self, progress: Progress) -> None:
        if self.binning is not None:
            progress(Stage.CEILINGS, len(self.done) / max(1, int(np.count_nonzero(self.kept))))

    def results(self, levels: list | None, timings: dict[str, float],
                log: Callable[[str], None]) -> CeilingResults | None:
        """The tiles' results for the consensus (None when no tile was binned); ``timings["ceilings"]``
        the seconds of the tiles' tasks (in the workers, beside the walls')."""
        if self.binning is None:
            return None
        from .surfaces import ceiling_results

        timings[Stage.CEILINGS] = self.seconds
        return ceiling_results(self.binning.tiles, self.kept, dict(self.done[k] for k in sorted(self.done)),
                               self.templates, self.classes, levels=levels, log=log,
                               said=f"with the walls ({self.seconds:.1f} s of tasks)")


def _storey_points(executor: Executor, parts: Sequence, sample_meta: list[tuple[int, bool]], origin: np.ndarray,
                   *, sources: Sequence[str], points: int, s: DetectionSettings, scratch: Path,
                   in_flight: int,
                   log: Callable[[str], None]) -> StoreyPoints:
    """The ``storey_points`` of :func:`segment_storeys` for a scan of ``points`` points read out
    of core: one more pass over the parts (:func:`~sbsc_core.scene.storey_samples.storey_part`)
    writes each storey's points at its own sample density (from its share of the sample),
    then each storey's cloud is read back in turn."""
    limit = 2 * s.segmentation.fit_max_points

    def read(bounds: list[tuple[float, float]], shares: list[float]) -> Iterator[PointCloud]:
        t = time.perf_counter()
        steps = storey_steps(shares, points, limit)
        jobs = [dict(part=part, origin=origin, bounds=bounds, steps=steps, scratch=str(scratch), points=n,
                     spilled=spilled) for part, (n, spilled) in zip(parts, sample_meta, strict=True)]
        written = np.zeros(len(bounds), np.int64)
        for _, got in _as_done(executor, jobs, storey_part, in_flight):
            written += np.asarray(got, np.int64)
        log(f"{len(bounds)} storeys read again at their own density in {time.perf_counter() - t:.1f} s: "
            + ", ".join(f"S{k + 1} {int(n):,} points (every {st})"
                        for k, (n, st) in enumerate(zip(written, steps, strict=True))))
        for k in range(len(bounds)):
            yield storey_cloud(scratch, parts, k, origin, sources=sources, limit=limit)

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
    """:func:`detect` on scan files, out of core (see :mod:`sbsc_core.imaging.partition`).

    Every part of the files is read by a task of ``executor``: once for a bounded regular
    sample that segmentation runs on, once more (or from its spill) to write each wall's
    binned points to its partition in ``scratch``; each wall's stages then run as a task on
    its partition. Each wall's task writes the wall's images to ``scratch/images``
    (:func:`park_wall`), so the result holds no orthoimage: write it with
    ``write_outputs(..., parked=scratch / "images")``. ``origin`` is the recentring origin
    (default: :func:`~sbsc_core.imaging.partition.scan_origin` of the first file). Returns the result
    and the number of points read.

    Parameters
    ----------
    scans
        The registered scan files of one building (contract 1).
    library, expected, settings, progress
        As for :func:`detect`.
    executor
        Where the parts and walls run: a local pool, a Dask client's executor or inline.
    scratch
        A folder for the partitions and the parked images (left to the caller to remove).
    log
        Called with a line per step worth telling.
    origin
        The recentring origin; None: that of the first file.

    Returns
    -------
    tuple[DetectionResult, int]
        The result (its walls' images parked in ``scratch / "images"``) and the points read.
    """
    s = settings or DetectionSettings()
    progress = progress or no_progress
    log = log or (lambda msg: None)
    timings: dict[str, float] = {}
    expected = _as_expected(expected)
    s = searched_surfaces(s, library, expected)
    classes = search_classes(library, None if expected is None else expected.counts)
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
    ceiling_classes = search_classes(library, None if expected is None else expected.counts, kind="ceiling")
    made_c = (executor.submit(_templates_job, library, s, ceiling_classes)
              if workers > 1 and s.ceilings.enabled and ceiling_classes else None)
    found = find_scan_storeys(cloud, s.segmentation)
    sampled = len(cloud)
    if len(found.levels) > 1 and sampled < points:
        # several storeys in a thinned sample: each is read again at the density it has when
        # scanned alone (the sample is let go first unless the ceilings or columns need it)
        if not (s.columns.enabled or s.ceilings.enabled):
            del cloud
        seg = segment_storeys(found, _storey_points(executor, parts, sample_meta, found.origin, sources=sources, points=points, s=s,
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
        from ..scene.ceilings import ceiling_levels

        levels = ceiling_levels(cloud, seg, s.ceilings)
    pendants = _pendants_of(cloud, seg, library, expected, s, columns=found_columns, levels=levels, log=log)
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
    ceilings = None
    if s.ceilings.enabled:  # the ceiling tiles' points are binned in the same pass (the scan is read once)
        from .surfaces import ceiling_binning

        ceilings = ceiling_binning(seg, origin, library=library, expected=None if expected is None else expected.counts,
                                   s=s, scratch=Path(scratch), levels=levels)
    part_jobs = [dict(part=part, origin=origin, index=index, scratch=str(scratch), points=n, spilled=spilled,
                      ortho=s.orthoimage, also=ceilings) for part, (n, spilled) in zip(parts, sample_meta, strict=True)]
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
    parked = Path(scratch) / "images"
    parked.mkdir(exist_ok=True)
    # each task writes its surface's images itself: this process only receives the small results
    jobs = [(int(kept[w]), ("wall", w), _partition_wall_job,
             dict(scratch=str(scratch), w=w, wall_id=seg.walls[w].id, frame=seg.walls[w].frame,
                  templates=templates, prototypes=prototypes, s=s, images=str(parked)))
            for w in range(len(seg.walls))]
    tiles = _TilesAlong(ceilings, scratch=Path(scratch), classes=ceiling_classes, made=made_c, library=library, s=s)
    jobs += tiles.jobs(parked)
    # the ceiling tiles run in the same stream as the walls (no worker idles between them), the
    # biggest surfaces first, so that no worker is left with a big one at the end; the results
    # are put back in the walls' order (the consensus sees them as in memory) and the tiles'
    jobs.sort(key=lambda j: -j[0])
    with ThreadPoolExecutor(max_workers=1) as cleaner:  # frees the disk while the walls run, not at the end

        def results() -> Iterator[tuple[str, WallResult, dict[str, float]]]:
            walls_left = len(seg.walls)
            for k, res in _as_done(executor, [(fn, job) for _, _, fn, job in jobs], call_job, 2 * workers):
                kind, i = jobs[k][1]
                if kind == "tile":
                    tiles.add(i, res, progress=progress if not walls_left else None)
                    continue
                cleaner.submit(drop_wall_partition, scratch, i)  # its points are not read again
                walls_left -= 1
                yield res  # the walls' bar counts it (in _collect_walls) before the tiles' bar may start
                if not walls_left:
                    tiles.progress(progress)

        done = _collect_walls(results(), len(seg.walls), progress, timings)
    walls = {wall.id: done[wall.id] for wall in seg.walls}
    beyond = _beyond_walls(parts, origin, seg, levels=levels, columns=found_columns, pendants=pendants,
                           library=library, expected=expected, s=s, executor=executor,
                           scratch=Path(scratch), parked=parked, in_flight=2 * workers, progress=progress,
                           timings=timings, log=log, ceilings_done=tiles.results(levels, timings, log))
    walls.update(beyond.walls)
    if s.ceilings.enabled or found_columns:
        templates, classes = {**beyond.templates, **templates}, sorted(set(classes) | set(beyond.classes))
    result = _consensus(seg, walls, templates, classes, expected, s=s, progress=progress, timings=timings, log=log)
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

    Parameters
    ----------
    scans
        The registered scan files of one building (contract 1).
    models
        The model library's folder (contract 2).
    expected
        ``expected.json`` (contract 3) or the counts themselves; None: every class.
    out
        The output folder (contract 4): written whole, or not at all.
    settings_file, settings
        A JSON/YAML file of settings, or the settings; None: the defaults.
    log, progress
        Messages, and each stage's progress (:class:`~sbsc_core.stages.Stage`).
    scheduler
        A Dask scheduler's address; None: a local process pool.
    scratch
        Where the partitions go while the command runs.

    Returns
    -------
    dict
        The summary ``sbsc detect --json`` prints: counts per class, walls, points, seconds.
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
        from ..io.documents import read_expected_counts
        from ..io.models import load_model_library

        library = load_model_library(Path(models))
        if s.confidence.enabled and s.confidence.calibration:  # a bad file is told now, not after the recognition
            from ..recognition.confidence import load_calibration

            load_calibration(Path(s.confidence.calibration))
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


