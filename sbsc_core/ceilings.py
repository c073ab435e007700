"""Objects on ceilings (issue 11, item 1): the ceiling seen from below as orthoimages.

Each storey's ceiling is a plane at the storey's ``ceiling_z`` seen from below: frame
``axis_u`` = +x, ``axis_v`` = -y, ``normal`` = -z (contract 4: a ceiling's normal points
down into the room, ``axis_v`` lies in the ceiling plane), so the depth of a point is how
far it hangs below the ceiling, and an object seen from below is drawn like one on a wall.
The plane is cut into tiles of at most ``tile_m`` (a storey's ceiling at 5 mm pixels would
be one huge image), each grown by ``overlap_m`` on every side so that an object whose centre
lies in a tile's own part (its *core*) is whole in its image. A tile is a surface of kind
``ceiling`` (contract 4 ``surfaces``), id ``C01``, ... (``S2-C01`` with several storeys).

The scan is read once more: the points within the orthoimage's depth range of a storey's
ceiling, minus those on a wall's plane (the tops of the walls seen edge-on), are binned
into each tile's partition like a wall's (:mod:`partition`). Each tile then goes through
the walls' stages unchanged (:func:`~sbsc_core.pipeline.process_orthoimage`: colour
preparation, visible area, depth and colour recognition) with the classes whose ``mount``
has ``ceiling``; only candidates centred in the tile's core are kept, so that an object in
the overlap of two tiles is found once. The consensus runs over walls and ceilings together
(the expected counts are the floor's).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .orthoimage import ortho_pixels, orthoimage_from_pixels, wall_coordinates
from .partition import ScanPart, _part_chunks, append_records, folder_records
from .settings import CeilingSettings, OrthoimageSettings
from .types import Candidate, Orthoimage, Segmentation, WallFrame

CEILING_SKIN_M = 0.01  # points this close to the ceiling plane are the ceiling's, even at a wall


@dataclass(frozen=True)
class CeilingTile:
    """One tile of a storey's ceiling: its frame and the part of it (u, v in metres) it owns."""

    id: str
    storey: str | None
    frame: WallFrame
    core: tuple[float, float, float, float]  # u_min, u_max, v_min, v_max

    def owns(self, u: float, v: float) -> bool:
        return self.core[0] <= u < self.core[1] and self.core[2] <= v < self.core[3]

    def surface(self) -> dict:
        """The tile as a contract-4 ``surfaces`` entry."""
        doc = {"id": self.id, "kind": "ceiling", **self.frame.to_dict()}
        if self.storey is not None:
            doc["storey"] = self.storey
        return doc


def ceiling_tiles(seg: Segmentation, s: CeilingSettings) -> list[CeilingTile]:
    """The tiles of every storey's ceiling, over the plan extent of the storey's walls."""
    storeys = [(st.id, st.ceiling_z) for st in seg.storeys] or [(None, seg.ceiling_z)]
    several = len(storeys) > 1
    tiles: list[CeilingTile] = []
    for sid, cz in storeys:
        walls = [w for w in seg.walls if sid is None or w.storey in (sid, None)]
        if not walls:
            continue
        ends = np.array([p for w in walls for p in (w.frame.origin[:2], w.frame.origin[:2]
                                                     + w.frame.width_m * w.frame.axis_u[:2])])
        x0, y0 = ends.min(axis=0)
        x1, y1 = ends.max(axis=0)
        nx = max(1, math.ceil((x1 - x0) / s.tile_m - 1e-9))
        ny = max(1, math.ceil((y1 - y0) / s.tile_m - 1e-9))
        xs = np.linspace(x0, x1, nx + 1)
        ys = np.linspace(y1, y0, ny + 1)  # v runs along -y: the first row of tiles is at the top (max y)
        k = 0
        for j in range(ny):
            for i in range(nx):
                k += 1
                g = s.overlap_m
                tx0, tx1 = max(x0, xs[i] - g), min(x1, xs[i + 1] + g)
                ty1, ty0 = min(y1, ys[j] + g), max(y0, ys[j + 1] - g)
                frame = WallFrame(origin=np.array([tx0, ty1, cz], np.float64), axis_u=np.array([1.0, 0.0, 0.0]),
                                  axis_v=np.array([0.0, -1.0, 0.0]), normal=np.array([0.0, 0.0, -1.0]),
                                  width_m=float(tx1 - tx0), height_m=float(ty1 - ty0))
                core = (float(xs[i] - tx0), float(xs[i + 1] - tx0) + (1e-6 if i == nx - 1 else 0.0),
                        float(ty1 - ys[j]), float(ty1 - ys[j + 1]) + (1e-6 if j == ny - 1 else 0.0))
                tid = (f"{sid}-" if several else "") + f"C{k:02d}"
                tiles.append(CeilingTile(tid, sid, frame, core))
    return tiles


def _tile_dir(scratch: Path, k: int) -> Path:
    return scratch / "ceilings" / f"{k:05d}"


def ceiling_part(part: ScanPart, origin: np.ndarray, tiles: list[CeilingTile], walls: list[WallFrame],
                 scratch: str, ortho: OrthoimageSettings, wall_clear_m: float) -> list[int]:
    """Stream one part of a scan and append each tile's binned points to its partition.

    A point goes to every tile whose image it falls in (tiles overlap), unless it hangs
    more than ``CEILING_SKIN_M`` below the ceiling within ``wall_clear_m`` of a wall's plane
    over the wall (the wall's top, seen edge-on). Returns records per tile.
    """
    root = Path(scratch)
    written = [0] * len(tiles)
    d0, d1 = ortho.depth_range_m
    zs = sorted({float(t.frame.origin[2]) for t in tiles})
    for chunk in _part_chunks(part, origin):
        z = chunk.xyz[:, 2].astype(np.float64) + float(origin[2])
        near = np.zeros(len(z), bool)
        for cz in zs:
            near |= (z >= cz - d1) & (z <= cz - d0)
        idx = np.flatnonzero(near)
        if not len(idx):
            continue
        xyz = chunk.xyz[idx]
        below = np.ones(len(idx), bool)  # hangs below every ceiling plane: may be a wall's top
        for cz in zs:
            below &= z[idx] < cz - CEILING_SKIN_M
        on_wall = np.zeros(len(idx), bool)
        for f in walls:
            uvd = wall_coordinates(xyz[below], f, origin)
            on_wall[below] |= (np.abs(uvd[:, 2]) < wall_clear_m) & (uvd[:, 0] > -wall_clear_m) \
                & (uvd[:, 0] < f.width_m + wall_clear_m)
        idx, xyz = idx[~on_wall], xyz[~on_wall]
        for k, t in enumerate(tiles):
            uvd = wall_coordinates(xyz, t.frame, origin)
            keep, pixel = ortho_pixels(uvd, t.frame, ortho)
            if not len(pixel):
                continue
            written[k] += append_records(_tile_dir(root, k), part.key, pixel, uvd[keep, 2], chunk.rgb[idx[keep]])
    return written


def tile_orthoimage(scratch: str | Path, k: int, tile: CeilingTile, ortho: OrthoimageSettings) -> Orthoimage:
    """The orthoimage of tile number ``k`` from its partition."""
    rec = folder_records(_tile_dir(Path(scratch), k))
    return orthoimage_from_pixels(tile.id, tile.frame, rec["pixel"].astype(np.int64), rec["depth"], rec["rgb"], ortho)


def in_core(cands: list[Candidate], tile: CeilingTile, pixel_m: float) -> list[Candidate]:
    """The candidates centred in the tile's core (an object in an overlap is found by one tile)."""
    h = tile.frame.height_m
    return [c for c in cands if tile.owns((c.centre[1] + 0.5) * pixel_m, h - (c.centre[0] + 0.5) * pixel_m)]


def ceiling_tile_job(scratch: str, k: int, tile: CeilingTile, templates: dict, prototypes, s) -> tuple:
    """One tile's work (what a worker runs): orthoimage, the walls' stages, candidates in its core."""
    from .pipeline import WallResult, process_orthoimage

    t = time.perf_counter()
    ortho = tile_orthoimage(scratch, k, tile, s.orthoimage)
    res, t_stage = process_orthoimage(ortho, templates, prototypes, s, {"orthoimage": time.perf_counter() - t})
    px = s.orthoimage.pixel_m
    res = WallResult(res.ortho, res.area, res.depth_rois, res.colour_rois,
                     in_core(res.depth_candidates, tile, px), in_core(res.colour_candidates, tile, px))
    return tile.id, res, t_stage


@dataclass
class CeilingResults:
    """What :func:`detect_ceilings` hands to the consensus: the tiles' results, templates and classes."""

    walls: dict  # tile id -> WallResult (parked: images written to ``parked``)
    templates: dict
    classes: list[str]
    tiles: list[CeilingTile]

    def surfaces(self) -> list[dict]:
        return [t.surface() for t in self.tiles]


def detect_ceilings(parts: list[ScanPart], origin: np.ndarray, seg: Segmentation, library, expected: dict | None,
                    s, *, executor, scratch: Path, parked: Path, in_flight: int, progress, timings: dict,
                    log) -> CeilingResults:
    """Bin the ceilings' points into tiles, then run the walls' stages on every tile (see the module)."""
    from .pipeline import _search_classes, surface_stage

    t0 = time.perf_counter()
    tiles = ceiling_tiles(seg, s.ceilings)
    classes = _search_classes(library, expected, kind="ceiling")
    if not tiles or not classes:
        return CeilingResults({}, {}, classes, [])
    progress("ceilings", 0.0)
    walls = [w.frame for w in seg.walls]
    jobs = [(part, origin, tiles, walls, str(scratch), s.orthoimage, s.ceilings.wall_clear_m) for part in parts]
    kept, results, templates = surface_stage(
        executor, stage="ceilings", part_fn=ceiling_part, part_jobs=jobs, job_fn=ceiling_tile_job, surfaces=tiles,
        library=library, classes=classes, s=s, scratch=scratch, parked=parked, in_flight=in_flight, progress=progress)
    timings["ceilings"] = time.perf_counter() - t0
    log(f"{len(tiles)} ceiling tiles: {int(kept.sum()):,} points, searched for {', '.join(classes)} "
        f"in {timings['ceilings']:.1f} s")
    return CeilingResults(results, templates, classes, tiles)
