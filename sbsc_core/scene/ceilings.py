"""Objects on ceilings (issue 11, item 1): the ceiling seen from below as orthoimages.

Each storey's ceiling is a plane at the storey's ``ceiling_z`` seen from below: frame
``axis_u`` = +x, ``axis_v`` = -y, ``normal`` = -z (contract 4: a ceiling's normal points
down into the room, ``axis_v`` lies in the ceiling plane), so the depth of a point is how
far it hangs below the ceiling, and an object seen from below is drawn like one on a wall.
The plane is cut into tiles of at most ``tile_m`` (a storey's ceiling at 5 mm pixels would
be one huge image), each grown by ``overlap_m`` on every side so that an object whose centre
lies in a tile's own part (its *core*) is whole in its image. A tile is a surface of kind
``ceiling`` (contract 4 ``surfaces``), id ``C01``, ... (``S2-C01`` with several storeys).

**Stepped ceilings.** Rooms within a storey may have lower ceilings than the storey's
(highest) one. :func:`ceiling_levels` measures the top of the points over plan cells of
``level_cell_m`` in the segmentation sample; cells whose top lies ``level_tolerance_m`` from
a lower level that covers at least ``level_min_area_m2`` are under that level. Each lower
level gets tiles of its own over its cells, at its own height, and takes only the points over
its cells; the storey's ceiling takes the points over every other cell. Tiles with no point
are left out (no surface, no work).

The scan is read once more: the points within the orthoimage's depth range of a storey's
ceiling, minus those on a wall's plane (the tops of the walls seen edge-on), are binned
into each tile's partition like a wall's (:mod:`partition`). Each tile then goes through
the walls' stages unchanged (:func:`~sbsc_core.pipeline.walls.process_orthoimage`: colour
preparation, visible area, depth and colour recognition) with the classes whose ``mount``
has ``ceiling``; only candidates centred in the tile's core are kept, so that an object in
the overlap of two tiles is found once. The consensus runs over walls and ceilings together
(the expected counts are the floor's).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..imaging.orthoimage import near_walls, ortho_pixels, orthoimage_from_pixels, wall_coordinates
from ..imaging.partition import RECORD, ScanPart, append_records, folder_records
from ..imaging.partition import part_chunks as file_chunks
from ..io.scan_source import ScanChunk
from ..settings import CeilingSettings, OrthoimageSettings
from ..types import Candidate, Orthoimage, PointCloud, Segmentation, WallFrame

CEILING_SKIN_M = 0.01  # points this close to the ceiling plane are the ceiling's, even at a wall
_MAX_LOWER_LEVELS = 4
_MEMORY_PART_POINTS = 4_000_000


@dataclass(frozen=True)
class MemoryPart:
    """Consecutive points of an in-memory cloud (:func:`~sbsc_core.pipeline.detect.detect`), used
    like a scan part by the ceiling and column stages (``xyz`` relative to the cloud's origin)."""

    xyz: np.ndarray  # (n, 3) float32
    rgb: np.ndarray  # (n, 3) uint8
    key: str
    start: int = 0


def memory_parts(cloud: PointCloud, points: int = _MEMORY_PART_POINTS) -> list[MemoryPart]:
    """``cloud`` as parts of at most ``points`` points (views, no copy)."""
    return [MemoryPart(cloud.xyz[a:a + points], cloud.rgb[a:a + points], f"m{k:05d}", a)
            for k, a in enumerate(range(0, len(cloud), points))]


def part_chunks(part: ScanPart | MemoryPart, origin: np.ndarray) -> Iterator[ScanChunk]:
    """The chunks of a scan part (streamed from its file) or of a :class:`MemoryPart`."""
    if isinstance(part, MemoryPart):
        yield ScanChunk(part.xyz, part.rgb, np.asarray(origin, np.float64), part.start)
        return
    yield from file_chunks(part, origin)


@dataclass(frozen=True)
class CeilingLevels:
    """The ceiling levels of one storey over a plan grid: ``labels[j, i]`` is 0 under the
    storey's ceiling (or unknown) and ``k`` under the lower level ``z[k - 1]``."""

    storey: str | None
    ceiling_z: float
    x0: float
    y0: float
    cell_m: float
    labels: np.ndarray  # (ny, nx) int8
    z: tuple[float, ...]  # the lower levels, highest first

    def label(self, xy: np.ndarray) -> np.ndarray:
        """The level number (0: the storey's ceiling) over each plan point (N, 2) float64."""
        ny, nx = self.labels.shape
        i = np.floor((xy[:, 0] - self.x0) / self.cell_m).astype(np.int64)
        j = np.floor((xy[:, 1] - self.y0) / self.cell_m).astype(np.int64)
        inside = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
        out = np.zeros(len(xy), np.int8)
        out[inside] = self.labels[j[inside], i[inside]]
        return out

    def extent(self, k: int) -> tuple[float, float, float, float]:
        """x0, x1, y0, y1 of the cells under lower level ``k``."""
        jj, ii = np.nonzero(self.labels == k)
        c = self.cell_m
        return (self.x0 + ii.min() * c, self.x0 + (ii.max() + 1) * c,
                self.y0 + jj.min() * c, self.y0 + (jj.max() + 1) * c)


@dataclass(frozen=True)
class CeilingTile:
    """One tile of a storey's ceiling: its frame and the part of it (u, v in metres) it owns.

    With ``levels``, the tile is under level ``level`` of them (0: the storey's ceiling) and
    takes only the points over that level's cells.
    """

    id: str
    storey: str | None
    frame: WallFrame
    core: tuple[float, float, float, float]  # u_min, u_max, v_min, v_max
    level: int = 0
    levels: CeilingLevels | None = None

    def owns(self, u: float, v: float) -> bool:
        return self.core[0] <= u < self.core[1] and self.core[2] <= v < self.core[3]

    def surface(self) -> dict:
        """The tile as a contract-4 ``surfaces`` entry."""
        doc = {"id": self.id, "kind": "ceiling", **self.frame.to_dict()}
        if self.storey is not None:
            doc["storey"] = self.storey
        return doc


def _by_cell_highest_first(cell: np.ndarray, z32: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``cell`` (N,) int64 >= 0 (below 2**31) and ``z32`` (N,) float32 sorted by cell, then by ``z32``
    from the highest: ``np.lexsort((-z32, cell))`` applied to both, as one sort of packed int64 keys.

    Each key is the cell in the high 32 bits and, in the low 32, the bits of ``z32`` mapped so
    that their unsigned order is the reverse of the values' order (IEEE 754 floats compare
    as sign-magnitude integers); equal keys hold equal values, so any order among them is the
    same output.
    """
    if z32.dtype != np.float32:  # not the cloud's float32: sorted as the values are
        order = np.lexsort((-z32, cell))
        return cell[order], z32[order]
    u = z32.view(np.uint32).astype(np.int64)
    up = np.where(u >> 31 == 1, ~u & 0xFFFFFFFF, u | 0x80000000)  # ascending with the value
    key = (cell.astype(np.int64) << 32) | (0xFFFFFFFF - up)  # descending
    key.sort()
    up = 0xFFFFFFFF - (key & 0xFFFFFFFF)
    bits = np.where(up >> 31 == 0, ~up & 0xFFFFFFFF, up & 0x7FFFFFFF).astype(np.uint32)
    return key >> 32, bits.view(np.float32)


def _plan_cells(coord: np.ndarray, idx: np.ndarray, origin: float, cell_m: float) -> tuple[float, np.ndarray]:
    """(lowest world coordinate, cell numbers from it) of the points ``idx`` along one plan axis.

    ``coord`` is a float32 column of the cloud (relative to ``origin``); the cells are
    ``floor((coord[idx] + origin - lowest) / cell_m)`` in float64, as int64.
    """
    w = coord.take(idx).astype(np.float64)
    w += origin
    lo = float(w.min())
    w -= lo
    w /= cell_m
    np.floor(w, out=w)
    return lo, w.astype(np.int64)


def ceiling_levels(cloud: PointCloud, seg: Segmentation, s: CeilingSettings) -> list[CeilingLevels]:
    """The ceiling levels of every storey measured in ``cloud`` (the segmentation sample).

    Over plan cells of ``s.level_cell_m``, the top of a cell is its third-highest point
    between ``level_max_drop_m`` below the storey's ceiling and 5 cm above it (a stray point
    does not lift it). Cells whose top is more than ``level_tolerance_m`` below the storey's
    ceiling form lower levels: the most common top among them, refined as the median of the
    tops within the tolerance, is a level when its cells (closed and opened by a cell, the
    smaller pieces dropped) cover ``level_min_area_m2``; then the next, up to four. Each
    level is then the median of its cells' points within the tolerance. A storey with no
    lower level gets no entry.
    """
    import cv2

    storeys = [(st.id, st.ceiling_z) for st in seg.storeys] or [(None, seg.ceiling_z)]
    origin = np.asarray(cloud.origin, np.float64)
    z_all = cloud.xyz[:, 2].astype(np.float64) + origin[2]
    c = s.level_cell_m
    min_cells = s.level_min_area_m2 / (c * c)
    out: list[CeilingLevels] = []
    for sid, cz in storeys:
        idx = np.flatnonzero((z_all > cz - s.level_max_drop_m) & (z_all < cz + 0.05))
        if len(idx) < 100:
            continue
        z = z_all[idx]
        # plan cells, x and y apart: the values of the (N, 2) float64 arithmetic, in a third of the time
        x0, ix = _plan_cells(cloud.xyz[:, 0], idx, origin[0], c)
        y0, iy = _plan_cells(cloud.xyz[:, 1], idx, origin[1], c)
        nx, ny = int(ix.max()) + 1, int(iy.max()) + 1
        cell = iy * nx
        cell += ix
        del ix, iy
        # a cell is free (its top more than the tolerance below the storey's ceiling) when it has
        # three points but fewer than three at that height or above: only the free cells' tops
        # are measured (by sorting their points), the others' are never looked at
        low = cz - s.level_tolerance_m
        free = ((np.bincount(cell, minlength=nx * ny) >= 3)
                & (np.bincount(cell[z >= low], minlength=nx * ny) < 3))
        mine = np.flatnonzero(free[cell])
        cell_s, z32_s = _by_cell_highest_first(cell[mine], cloud.xyz[:, 2][idx[mine]])
        z_s = z32_s.astype(np.float64) + origin[2]  # as z_all: the same values, in this order
        first = np.flatnonzero(np.r_[True, cell_s[1:] != cell_s[:-1]]) if len(cell_s) else np.zeros(0, np.int64)
        top = np.full(nx * ny, np.nan)
        top[cell_s[first + 2]] = z_s[first + 2]  # the third-highest point: below ``low``
        labels = np.zeros(nx * ny, np.int8)
        levels: list[float] = []
        kernel = np.ones((3, 3), np.uint8)
        while len(levels) < _MAX_LOWER_LEVELS and free.sum() >= min_cells:
            bins = np.floor((top[free] - (cz - s.level_max_drop_m)) / 0.01).astype(np.int64)
            hist = np.convolve(np.bincount(bins), np.ones(3), "same")
            peak = cz - s.level_max_drop_m + (int(np.argmax(hist)) + 0.5) * 0.01
            near = free & (np.abs(top - peak) < s.level_tolerance_m)
            level = float(np.median(top[near]))
            under = free & (np.abs(top - level) < s.level_tolerance_m)
            free &= ~near & ~under
            grid = under.reshape(ny, nx).astype(np.uint8)
            grid = cv2.morphologyEx(cv2.morphologyEx(grid, cv2.MORPH_CLOSE, kernel), cv2.MORPH_OPEN, kernel)
            n, lab, stats, _ = cv2.connectedComponentsWithStats(grid, connectivity=4)
            big = [m for m in range(1, n) if stats[m, cv2.CC_STAT_AREA] >= min_cells]
            if not big:
                continue
            mine = np.isin(lab, big).ravel() & (labels == 0)
            levels.append(level)
            labels[mine] = len(levels)
        if levels:  # each level refined on its cells' points near it (the tops lie a little high)
            at = labels[cell]
            for k, lz in enumerate(levels, start=1):
                on = (at == k) & (np.abs(z - lz) < s.level_tolerance_m)
                levels[k - 1] = float(np.median(z[on])) if on.any() else lz
            out.append(CeilingLevels(sid, float(cz), float(x0), float(y0), c, labels.reshape(ny, nx),
                                     tuple(levels)))
    return out


def _cut(x0: float, x1: float, y0: float, y1: float, z: float, *, s: CeilingSettings
         ) -> list[tuple[WallFrame, tuple[float, float, float, float]]]:
    """The plan box cut into tiles of at most ``s.tile_m``, each grown by ``s.overlap_m``:
    (frame at height ``z``, core), row by row from the top (max y; v runs along -y)."""
    nx = max(1, math.ceil((x1 - x0) / s.tile_m - 1e-9))
    ny = max(1, math.ceil((y1 - y0) / s.tile_m - 1e-9))
    xs = np.linspace(x0, x1, nx + 1)
    ys = np.linspace(y1, y0, ny + 1)
    out = []
    for j in range(ny):
        for i in range(nx):
            g = s.overlap_m
            tx0, tx1 = max(x0, xs[i] - g), min(x1, xs[i + 1] + g)
            ty1, ty0 = min(y1, ys[j] + g), max(y0, ys[j + 1] - g)
            frame = WallFrame(origin=np.array([tx0, ty1, z], np.float64), axis_u=np.array([1.0, 0.0, 0.0]),
                              axis_v=np.array([0.0, -1.0, 0.0]), normal=np.array([0.0, 0.0, -1.0]),
                              width_m=float(tx1 - tx0), height_m=float(ty1 - ty0))
            core = (float(xs[i] - tx0), float(xs[i + 1] - tx0) + (1e-6 if i == nx - 1 else 0.0),
                    float(ty1 - ys[j]), float(ty1 - ys[j + 1]) + (1e-6 if j == ny - 1 else 0.0))
            out.append((frame, core))
    return out


def ceiling_tiles(seg: Segmentation, s: CeilingSettings, levels: list[CeilingLevels] | None = None
                  ) -> list[CeilingTile]:
    """The tiles of every storey's ceiling, over the plan extent of the storey's walls, then
    (numbered on) those of each lower level of ``levels`` over the extent of its cells."""
    storeys = [(st.id, st.ceiling_z) for st in seg.storeys] or [(None, seg.ceiling_z)]
    several = len(storeys) > 1
    by_storey = {lv.storey: lv for lv in levels or []}
    tiles: list[CeilingTile] = []
    for sid, cz in storeys:
        walls = [w for w in seg.walls if sid is None or w.storey in (sid, None)]
        if not walls:
            continue
        ends = np.array([p for w in walls for p in (w.frame.origin[:2], w.frame.origin[:2]
                                                     + w.frame.width_m * w.frame.axis_u[:2])])
        x0, y0 = ends.min(axis=0)
        x1, y1 = ends.max(axis=0)
        lv = by_storey.get(sid)
        boxes = [(0, cz, (x0, x1, y0, y1))]
        if lv is not None:
            for k, z in enumerate(lv.z, start=1):
                e = lv.extent(k)
                box = (max(x0, e[0]), min(x1, e[1]), max(y0, e[2]), min(y1, e[3]))
                if box[1] > box[0] and box[3] > box[2]:
                    boxes.append((k, z, box))
        k = 0
        for level, z, (bx0, bx1, by0, by1) in boxes:
            for frame, core in _cut(bx0, bx1, by0, by1, z, s=s):
                k += 1
                tid = (f"{sid}-" if several else "") + f"C{k:02d}"
                tiles.append(CeilingTile(tid, sid, frame, core, level, lv))
    return tiles


def _tile_dir(scratch: Path, k: int) -> Path:
    return scratch / "ceilings" / f"{k:05d}"


def ceiling_part(part: ScanPart | MemoryPart, origin: np.ndarray, tiles: list[CeilingTile], walls: list[WallFrame],
                 scratch: str, *, ortho: OrthoimageSettings, wall_clear_m: float) -> list[int]:
    """Stream one part of a scan and append each tile's binned points to its partition.

    A point goes to every tile of its ceiling level whose image it falls in (tiles overlap),
    unless it hangs more than ``CEILING_SKIN_M`` below the level within ``wall_clear_m`` of
    a wall's plane over the wall (the wall's top, seen edge-on). A tile of a storey with
    several levels takes only the points over its level's cells. ``part`` is a scan part or
    a :class:`MemoryPart`. Returns records per tile.
    """
    binning = CeilingBinning(tiles, walls, scratch, np.asarray(origin, np.float64), ortho, wall_clear_m)
    written = np.zeros(len(tiles), np.int64)
    for chunk in part_chunks(part, origin):
        written += binning(chunk, part.key)
    return written.tolist()


@dataclass(frozen=True)
class CeilingBinning:
    """:func:`ceiling_part` of one chunk at a time: called with each chunk of a part and the
    part's key, it appends the tiles' binned points and returns the records per tile. The walls'
    partition pass calls it on the chunks it reads
    (:func:`~sbsc_core.imaging.partition.partition_part`'s ``also``), so the scan is read once
    for both; :func:`binned_records` then counts what each tile got."""

    tiles: list[CeilingTile]
    walls: list[WallFrame]
    scratch: str
    origin: np.ndarray  # the scan's recentring origin (the chunks' points are relative to it)
    ortho: OrthoimageSettings
    wall_clear_m: float

    def __call__(self, chunk: ScanChunk, key: str) -> np.ndarray:
        tiles, origin, ortho = self.tiles, self.origin, self.ortho
        root = Path(self.scratch)
        written = np.zeros(len(tiles), np.int64)
        d0, d1 = ortho.depth_range_m
        groups: dict[tuple, list[int]] = {}  # tiles at one height under one level of one storey
        for k, t in enumerate(tiles):
            groups.setdefault((float(t.frame.origin[2]), t.storey, t.level), []).append(k)
        margin = 0.01 + 2 * float(ortho.pixel_m)  # an image's last pixel may reach past its frame; float32 rounding
        z = chunk.xyz[:, 2].astype(np.float64) + float(origin[2])
        for (cz, _, level), ks in groups.items():
            idx = np.flatnonzero((z >= cz - d1) & (z <= cz - d0))
            levels = tiles[ks[0]].levels
            if len(idx) and levels is not None:
                xy = np.take(chunk.xyz, idx, axis=0)[:, :2].astype(np.float64) + origin[:2]
                idx = idx[levels.label(xy) == level]
            if not len(idx):
                continue
            # np.take and np.compress: as xyz[idx] and xyz[mask], without fancy indexing's slow path
            xyz = np.take(chunk.xyz, idx, axis=0)
            below = np.flatnonzero(z[idx] < cz - CEILING_SKIN_M)  # hangs below the ceiling: may be a wall's top
            on_wall = np.zeros(len(idx), bool)
            on_wall[below[near_walls(np.take(xyz, below, axis=0), self.walls, self.wall_clear_m, origin)]] = True
            if on_wall.any():
                off = ~on_wall
                idx, xyz = idx[off], np.compress(off, xyz, axis=0)
            spans: dict[tuple[int, float, float], np.ndarray] = {}  # tiles of one grid row or column share a span
            for k in ks:
                t = tiles[k]
                x0, y1 = float(t.frame.origin[0]), float(t.frame.origin[1])  # axis_u +x, axis_v -y
                x1, y0 = x0 + t.frame.width_m, y1 - t.frame.height_m
                inside = np.flatnonzero(_in_span(xyz, 0, x0, x1, origin=origin, margin=margin, cache=spans)
                                        & _in_span(xyz, 1, y0, y1, origin=origin, margin=margin, cache=spans))
                uvd = wall_coordinates(np.take(xyz, inside, axis=0), t.frame, origin)
                keep, pixel = ortho_pixels(uvd, t.frame, ortho)
                if not len(pixel):
                    continue
                written[k] += append_records(_tile_dir(root, k), key, pixel, uvd[:, 2][keep],
                                             np.take(chunk.rgb, idx[inside[keep]], axis=0))
        return written


def binned_records(scratch: str | Path, tiles: int) -> np.ndarray:
    """The records in each of the first ``tiles`` tiles' partitions (what :class:`CeilingBinning` wrote)."""
    out = np.zeros(tiles, np.int64)
    for k in range(tiles):
        d = _tile_dir(Path(scratch), k)
        if d.is_dir():
            out[k] = sum(f.stat().st_size for f in d.glob("*.rec")) // RECORD.itemsize
    return out


def _in_span(xyz: np.ndarray, axis: int, lo: float, hi: float, *, origin: np.ndarray, margin: float,
             cache: dict[tuple[int, float, float], np.ndarray]) -> np.ndarray:
    """Which points lie within [``lo``, ``hi``] grown by ``margin`` along plan ``axis`` (0: x,
    1: y); kept in ``cache`` for the next tile of the same span."""
    key = (axis, lo, hi)
    if key not in cache:
        c, o = xyz[:, axis], float(origin[axis])
        cache[key] = (c >= lo - o - margin) & (c <= hi - o + margin)
    return cache[key]


def tile_orthoimage(scratch: str | Path, k: int, tile: CeilingTile, ortho: OrthoimageSettings) -> Orthoimage:
    """The orthoimage of tile number ``k`` from its partition."""
    rec = folder_records(_tile_dir(Path(scratch), k))
    return orthoimage_from_pixels(tile.id, tile.frame, rec["pixel"].astype(np.int64), rec["depth"], rec["rgb"], settings=ortho)


def in_core(cands: list[Candidate], tile: CeilingTile, pixel_m: float) -> list[Candidate]:
    """The candidates centred in the tile's core (an object in an overlap is found by one tile)."""
    h = tile.frame.height_m
    return [c for c in cands if tile.owns((c.centre[1] + 0.5) * pixel_m, h - (c.centre[0] + 0.5) * pixel_m)]


@dataclass
class CeilingResults:
    """What :func:`detect_ceilings` hands to the consensus: the tiles' results, templates and classes."""

    walls: dict  # tile id -> WallResult (parked: images written to ``parked``)
    templates: dict
    classes: list[str]
    tiles: list[CeilingTile]

    def surfaces(self) -> list[dict]:
        return [t.surface() for t in self.tiles]


