"""The stages beyond the walls: ceiling tiles, column faces and pendants, run as the walls' are.

The geometry (which ceilings and columns there are, their tiles and faces, their partition) is
``sbsc_core.scene``'s; here each tile or face goes through the walls' stages
(:func:`~sbsc_core.pipeline.walls.process_orthoimage`) on the executor of the run."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..imaging.partition import ScanPart
from ..scene.ceilings import (
    CeilingBinning,
    CeilingLevels,
    CeilingResults,
    CeilingTile,
    MemoryPart,
    binned_records,
    ceiling_part,
    ceiling_tiles,
    in_core,
    tile_orthoimage,
)
from ..scene.columns import (
    ColumnFace,
    ColumnResults,
    FoundColumn,
    column_faces,
    column_part,
    face_orthoimage,
)
from ..scene.pendants import PendantFace
from ..stages import Stage, no_progress
from ..types import Segmentation


def ceiling_tile_job(scratch: str, k: int, tile: CeilingTile, *, templates: dict, prototypes, s,
                     images: str | None = None) -> tuple:
    """One tile's work (what a worker runs): orthoimage, the walls' stages, candidates in its core;
    with ``images``, its images written there and left out of the result (:func:`~.walls.park_wall`)."""
    from .walls import WallResult, park_wall, process_orthoimage

    t = time.perf_counter()
    ortho = tile_orthoimage(scratch, k, tile, s.orthoimage)
    res, t_stage = process_orthoimage(ortho, templates, prototypes, s, {"orthoimage": time.perf_counter() - t})
    px = s.orthoimage.pixel_m
    res = WallResult(res.ortho, res.area, res.depth_rois, res.colour_rois,
                     in_core(res.depth_candidates, tile, px), in_core(res.colour_candidates, tile, px))
    return tile.id, res if images is None else park_wall(res, Path(images)), t_stage


def detect_ceilings(parts: list[ScanPart | MemoryPart], origin: np.ndarray, seg: Segmentation, *, library,
                    expected: dict | None, s, executor, scratch: Path, parked: Path, in_flight: int, progress,
                    timings: dict, log, levels: list[CeilingLevels] | None = None,
                    part_executor=None, binned: CeilingBinning | None = None) -> CeilingResults:
    """Bin the ceilings' points into tiles, then run the walls' stages on every tile (see the module).

    ``levels`` (:func:`ceiling_levels`) gives the storeys' lower ceilings their own tiles.
    Tiles that got no point are left out. ``binned``: the binning (:func:`ceiling_binning`)
    that the walls' partition pass already ran (the parts are not read again).
    """
    from .executors import surface_stage
    from .walls import search_classes

    t0 = time.perf_counter()
    tiles = ceiling_tiles(seg, s.ceilings, levels)
    classes = search_classes(library, expected, kind="ceiling")
    if not tiles or not classes:
        return CeilingResults({}, {}, classes, [])
    progress(Stage.CEILINGS, 0.0)
    walls = [w.frame for w in seg.walls]
    jobs = [dict(part=part, origin=origin, tiles=tiles, walls=walls, scratch=str(scratch), ortho=s.orthoimage,
                 wall_clear_m=s.ceilings.wall_clear_m) for part in parts]
    kept, results, templates = surface_stage(
        executor, stage=Stage.CEILINGS, part_fn=ceiling_part, part_jobs=jobs, job_fn=ceiling_tile_job, surfaces=tiles,
        library=library, classes=classes, s=s, scratch=scratch, parked=parked, in_flight=in_flight, progress=progress,
        part_executor=part_executor, binned=None if binned is None else binned_records(scratch, len(tiles)))
    timings[Stage.CEILINGS] = time.perf_counter() - t0
    return ceiling_results(tiles, kept, results, templates, classes, levels=levels,
                           log=log, said=f"in {timings['ceilings']:.1f} s")


def ceiling_results(tiles: list[CeilingTile], kept: np.ndarray, results: dict, templates: dict, classes: list[str],
                    *, levels: list[CeilingLevels] | None, log, said: str) -> CeilingResults:
    """The tiles' results (by tile id, in the tiles' order) for the consensus, told in ``log``
    with the points binned per tile (``kept``) and ``said`` (how long it took)."""
    lower = [f"{lv.storey + ' ' if lv.storey else ''}{z:.2f} m" for lv in levels or [] for z in lv.z]
    log(f"{len(results)} ceiling tiles" + (f" (lower ceilings at {', '.join(lower)})" if lower else "")
        + f": {int(kept.sum()):,} points, searched for {', '.join(classes)} {said}")
    return CeilingResults(results, templates, classes, [t for t in tiles if t.id in results])


def ceiling_binning(seg: Segmentation, origin: np.ndarray, *, library, expected: dict | None, s, scratch: Path,
                    levels: list[CeilingLevels] | None = None) -> CeilingBinning | None:
    """The binning of the ceiling tiles that :func:`detect_ceilings` searches, for the walls'
    partition pass to run on the chunks it reads; None when no tile or no class is searched."""
    from .walls import search_classes

    tiles = ceiling_tiles(seg, s.ceilings, levels)
    if not tiles or not search_classes(library, expected, kind="ceiling"):
        return None
    return CeilingBinning(tiles, [w.frame for w in seg.walls], str(scratch), np.asarray(origin, np.float64),
                          s.orthoimage, s.ceilings.wall_clear_m)


def column_face_job(scratch: str, k: int, face: ColumnFace, *, templates: dict, prototypes, s,
                    images: str | None = None) -> tuple:
    """One face's work (what a worker runs): orthoimage and the walls' stages; with ``images``,
    its images written there and left out of the result (:func:`~.walls.park_wall`)."""
    from .walls import WallResult, park_wall, process_orthoimage

    t = time.perf_counter()
    ortho = face_orthoimage(scratch, k, face, s.orthoimage)
    res, t_stage = process_orthoimage(ortho, templates, prototypes, s, {"orthoimage": time.perf_counter() - t})
    if face.radius_m is not None:  # one circumference of the wrapped image
        px = s.orthoimage.pixel_m
        res = WallResult(res.ortho, res.area, res.depth_rois, res.colour_rois,
                         [c for c in res.depth_candidates if face.owns((c.centre[1] + 0.5) * px)],
                         [c for c in res.colour_candidates if face.owns((c.centre[1] + 0.5) * px)])
    return face.id, res if images is None else park_wall(res, Path(images)), t_stage


def detect_columns(parts: list[ScanPart | MemoryPart], origin: np.ndarray,
                   columns: list[FoundColumn], *, library,
                   expected: dict | None, s, executor, scratch: Path, parked: Path, in_flight: int, progress,
                   timings: dict, log, part_executor=None) -> ColumnResults:
    """Bin the columns' points into their faces, then run the walls' stages on every face."""
    from .executors import surface_stage
    from .walls import search_classes

    t0 = time.perf_counter()
    faces = column_faces(columns, wrap_m=s.columns.wrap_m)
    classes = search_classes(library, expected, kind="column")
    if not faces or not classes:
        return ColumnResults({}, {}, classes, columns, [])
    progress(Stage.COLUMNS, 0.0)
    by_id = {c.id: c for c in columns}
    reach = [max(by_id[f.column].size_m) / 2 * math.sqrt(2) + s.orthoimage.depth_range_m[1] + 0.05 for f in faces]
    jobs = [dict(part=part, origin=origin, faces=faces, reach_m=reach, scratch=str(scratch),
                 ortho=s.orthoimage)
            for part in parts]
    kept, results, templates = surface_stage(
        executor, stage=Stage.COLUMNS, part_fn=column_part, part_jobs=jobs, job_fn=column_face_job, surfaces=faces,
        library=library, classes=classes, s=s, scratch=scratch, parked=parked, in_flight=in_flight, progress=progress,
        part_executor=part_executor)
    timings[Stage.COLUMNS] = time.perf_counter() - t0
    log(f"{len(columns)} columns ({', '.join(c.shape for c in columns)}), {len(faces)} faces: "
        f"{int(kept.sum()):,} points, searched for {', '.join(classes)} in {timings['columns']:.1f} s")
    return ColumnResults(results, templates, classes, columns, [f for f in faces if f.id in results])


def detect_pendants(parts: list[ScanPart | MemoryPart], origin: np.ndarray,
                    faces: list[PendantFace], *, library,
                    expected: dict | None, s, executor, scratch: Path, parked: Path, in_flight: int, progress,
                    timings: dict, log, part_executor=None) -> ColumnResults:
    """Bin the points near each pendant (:func:`~sbsc_core.scene.pendants.find_pendants`) into
    its surface, then run the walls' stages on it with the classes that may be on a ceiling.

    The surfaces are framed like a column's flat faces, so the columns' binning and job do
    the work; their progress is the ceilings' (reported done at the end).
    """
    from .executors import surface_stage
    from .walls import search_classes

    t0 = time.perf_counter()
    classes = search_classes(library, expected, kind="ceiling")
    if not faces or not classes:
        return ColumnResults({}, {}, classes, [], [])
    reach = [f.frame.width_m / 2 + s.orthoimage.depth_range_m[1] + 0.05 for f in faces]
    own = Path(scratch) / "pendants"  # beside the columns' partitions, not among them
    jobs = [dict(part=part, origin=origin, faces=faces, reach_m=reach, scratch=str(own), ortho=s.orthoimage)
            for part in parts]
    kept, results, templates = surface_stage(
        executor, stage=Stage.CEILINGS, part_fn=column_part, part_jobs=jobs, job_fn=column_face_job, surfaces=faces,
        library=library, classes=classes, s=s, scratch=own, parked=parked,
        in_flight=in_flight, progress=no_progress, part_executor=part_executor)
    progress(Stage.CEILINGS, 1.0)
    timings["pendants"] = time.perf_counter() - t0
    log(f"{len(faces)} pendant(s) hanging from the ceiling: {int(kept.sum()):,} points, searched for "
        f"{', '.join(classes)} in {timings['pendants']:.1f} s")
    return ColumnResults(results, templates, classes, [], [f for f in faces if f.id in results])
