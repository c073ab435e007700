"""Out-of-core data flow: a bounded sample for segmentation, then one partition file per wall.

No stage holds the whole cloud (paper, Figure 2, run on a building instead of a floor):

1. :func:`plan_parts` cuts the scan files into parts (a seekable (binary PLY / PCD) file into ranges of
   ``part_points``, and along its stations when it keeps each point's station; any other file
   whole, or per scan of an E57) that workers read side by side.
2. :func:`sample_part` streams one part (:func:`~sbsc_core.io.scans.iter_scan`) and keeps
   a regular sample - the points whose index over all files is a multiple of ``step`` -
   for segmentation. A part of a format that cannot be re-read cheaply (LAS/LAZ, E57,
   text) is spilled to the scratch folder as float32 + uint8 (15 bytes a point) on the way,
   so every file is decoded once.
3. Segmentation runs on the sample (a few million points, bounded).
4. :func:`partition_part` streams each part again (or its spill) and gives every point to
   at most one wall (:func:`assign_chunk`, a pure function of a chunk and the walls'
   frames); a wall's points are binned at once into its orthoimage pixels and appended to
   the wall's partition files as 11-byte records (pixel, depth, colour), one folder per
   band of orthoimage rows (``BAND_PIXELS`` pixels).
5. The orthoimage stage of a wall reads its partition band by band and only computes the
   per-pixel medians (:func:`~sbsc_core.imaging.orthoimage.rasterize_median`), so it holds the
   points of one band at a time, not the wall's.

The sample, the spills and the partitions live in a scratch folder (:func:`scratch_dir`)
that workers of a Dask cluster reach at the same path. The order in which parts are
processed does not change a wall's orthoimage (the medians do not depend on the order of
the points), so results are identical however the work is spread.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..io.merged_stations import station_label, station_runs
from ..io.scan_source import BLOCK_POINTS, CHUNK_POINTS, ScanChunk
from ..io.scans import iter_scan, open_scan, sample_scan
from ..settings import (
    DetectionSettings,
    OrthoimageSettings,
    SegmentationSettings,
)
from ..types import Orthoimage, PointCloud, Wall, WallFrame
from .occlusion import FrontLayers, stack_front
from .orthoimage import (
    front_images,
    layer_options,
    ortho_pixels,
    ortho_shape,
    orthoimage_from_images,
    rasterize_median,
    wall_coordinates,
)

__all__ = ["ScanPart", "WallIndex", "plan_parts", "station_names", "sample_part", "partition_part", "assign_chunk",
           "band_rows", "wall_records", "wall_orthoimage", "drop_wall_partition", "scratch_dir", "worker_ready",
           "RECORD", "SampleBuffer"]

BAND_PIXELS = 1 << 19  # orthoimage pixels of one band of a wall's partition (bounds the points binned at once)
PART_POINTS = 1 << 22  # points of a seekable (binary PLY / PCD) file read by one task (small: balanced workers)
RECORD = np.dtype([("pixel", "<i4"), ("depth", "<f4"), ("rgb", "u1", (3,))])  # 11 bytes, packed
_TEXT_BYTES_PER_POINT = 30  # to estimate the point count of a text file from its size


@dataclass(frozen=True)
class ScanPart:
    """Points ``start:stop`` of one scan file (the whole file when ``stop`` is None)."""

    path: str
    start: int
    stop: int | None
    first: int  # index over all files of the part's first point (for the regular sample)
    key: str  # unique name of the part (scratch file names)
    station: int = 0  # the station it belongs to: its file, or its scan in a file of several (E57) ...
    scan: int | None = None  # in a file of several scans, that scan (the whole part)
    label: str | None = None  # ... or its value of a merged file's station property (io.scans.STATION_FIELDS)
    pose: tuple[tuple[float, ...], ...] | None = None  # 4x4 rows: the file's refined registration (None: as given)

    def posed(self, pose: np.ndarray | None) -> ScanPart:
        """This part with its file's refined registration (:mod:`sbsc_core.scene.registration`)."""
        if pose is None or np.allclose(pose, np.eye(4), rtol=0, atol=1e-12):
            return replace(self, pose=None)
        return replace(self, pose=tuple(tuple(float(x) for x in row) for row in np.asarray(pose)))


@dataclass
class PartSample:
    """What :func:`sample_part` returns: the part's sample and its size."""

    xyz: np.ndarray
    rgb: np.ndarray
    points: int
    spilled: bool


def scratch_dir(out: Path, scratch: Path | str | None = None) -> Path:
    """A new scratch folder: in ``scratch`` (or ``$SBSC_SCRATCH_DIR``), else beside ``out``."""
    base = Path(scratch or os.environ.get("SBSC_SCRATCH_DIR") or Path(out).resolve().parent)
    base.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=".sbsc-partitions-", dir=base))


@contextlib.contextmanager
def scratch_folder(out: Path, scratch: Path | str | None = None) -> Iterator[Path]:
    """:func:`scratch_dir`, removed with everything in it at the end."""
    path = scratch_dir(out, scratch)
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


# --------------------------------------------------------------------------- pass 1


def plan_parts(paths: Sequence[Path | str], part_points: int | None = None) -> tuple[list[ScanPart], int]:
    """Parts of the scan files for the workers, and the (estimated) total point count.

    A seekable (binary PLY / PCD) file is cut into ranges of about ``part_points`` (default
    ``PART_POINTS``). Every header is read here, so a file that cannot be opened is refused
    before any work.

    A station is a file, or a scan of a file of several (E57), or in a seekable file merged
    from several stations that keeps each point's station (a property of
    :data:`~sbsc_core.io.scans.STATION_FIELDS`), the points of one value of the property:
    the property is read once here (:func:`~sbsc_core.io.merged_stations.station_runs`) and the
    file is cut along its runs (and within a long run at ``part_points``), every run of one
    value being the same station, named ``file#value`` (:func:`station_names`).
    """
    part_points = part_points or PART_POINTS
    parts: list[ScanPart] = []
    first = station = 0
    for k, p in enumerate(paths):
        src = open_scan(p)
        path = str(Path(p).resolve())
        n = src.count if src.count is not None else max(1, src.path.stat().st_size // _TEXT_BYTES_PER_POINT)
        runs = station_runs(src) if src.seekable else None
        if runs is not None:  # a merged file of several stations
            of_value: dict = {}
            j = 0
            for run in runs:
                st = of_value.setdefault(run.value, station + len(of_value))
                for a, b in _ranges(run.start, run.stop, part_points):
                    parts.append(ScanPart(path, a, b, first + a, f"f{k}-{j}", st, label=station_label(run.value)))
                    j += 1
            station += len(of_value)
            first += n
            continue
        if src.seekable and src.count is not None and n > part_points:
            parts += [ScanPart(path, a, b, first + a, f"f{k}-{j}", station)
                      for j, (a, b) in enumerate(_ranges(0, n, part_points))]
        elif len(src.scans) > 1:  # one part per scan (station) of the file
            at = first
            for j, m in enumerate(src.scans):
                if m:
                    parts.append(ScanPart(path, 0, None, at, f"f{k}-s{j}", station, j))
                    station += 1
                at += m
            first += n
            continue
        else:
            parts.append(ScanPart(path, 0, None, first, f"f{k}", station))
        station += 1
        first += n
    return parts, first


def _ranges(start: int, stop: int, part_points: int) -> list[tuple[int, int]]:
    """Points ``start:stop`` cut into as few equal ranges as keep each within ``part_points``."""
    pieces = max(1, math.ceil((stop - start) / part_points))
    cuts = [start + (stop - start) * j // pieces for j in range(pieces + 1)]
    return list(zip(cuts[:-1], cuts[1:], strict=True))


def station_names(parts: Sequence[ScanPart]) -> list[str]:
    """A name per station of :func:`plan_parts`' parts: its file's name, with ``#k`` for
    scan ``k`` of a file of several, or for value ``k`` of a merged file's station property."""
    names: dict[int, str] = {}
    for p in parts:
        tag = p.label if p.scan is None else str(p.scan)
        names.setdefault(p.station, Path(p.path).name + ("" if tag is None else f"#{tag}"))
    return [names[k] for k in range(len(names))]


def scan_origin(path: Path | str) -> np.ndarray:
    """The recentring origin of a set of scans: the one of their first file."""
    return next(iter_scan(path, chunk_points=BLOCK_POINTS)).origin


def part_chunks(part: ScanPart, origin: np.ndarray) -> Iterator[ScanChunk]:
    """The chunks of one scan part, streamed from its file (its point range, or the whole
    file), moved by the part's refined registration when it has one."""
    return _posed(part, _file_chunks(part, origin))


def _file_chunks(part: ScanPart, origin: np.ndarray) -> Iterator[ScanChunk]:
    """The chunks of one scan part as the file holds them."""
    if part.scan is not None:
        return iter_scan(part.path, origin, scan=part.scan)
    if part.stop is None:
        return iter_scan(part.path, origin)
    return iter_scan(part.path, origin, start=part.start, stop=part.stop)


def _posed(part: ScanPart, chunks: Iterator[ScanChunk]) -> Iterator[ScanChunk]:
    if part.pose is None:
        yield from chunks
        return
    pose = np.asarray(part.pose)
    for chunk in chunks:
        yield ScanChunk(apply_pose(chunk.xyz, pose), chunk.rgb, chunk.origin, chunk.start)


def _spill_paths(scratch: Path, part: ScanPart) -> tuple[Path, Path]:
    return scratch / f"spill-{part.key}.xyz", scratch / f"spill-{part.key}.rgb"


def sample_part(part: ScanPart, origin: np.ndarray, step: int, scratch: str | None) -> PartSample:
    """Stream one part: its regular sample (every ``step``-th point over all files), and
    a spill of its points into ``scratch`` unless the file is seekable (binary PLY / PCD)."""
    src = open_scan(part.path)
    pose = part.pose
    if src.seekable:  # fixed-size records: only the sampled points are converted
        xyz, rgb, n = sample_scan(src, origin, step, first=part.first, start=part.start, stop=part.stop)
        return PartSample(apply_pose(xyz, pose), rgb, n, False)
    spill = scratch is not None
    xs, cs = [], []
    n = 0
    files = None
    if spill:
        paths = _spill_paths(Path(scratch), part)
        files = (open(paths[0], "wb"), open(paths[1], "wb"))
    try:
        for chunk in _file_chunks(part, origin):  # the spill keeps the file's points (moved when read back)
            g0 = part.first + (chunk.start - part.start)  # global index of the chunk's first point
            i0 = (-g0) % step
            xs.append(apply_pose(chunk.xyz[i0::step].copy(), pose))
            cs.append(chunk.rgb[i0::step].copy())
            n += len(chunk)
            if files is not None:
                chunk.xyz.tofile(files[0])
                chunk.rgb.tofile(files[1])
    finally:
        if files is not None:
            for fh in files:
                fh.close()
    xyz = np.concatenate(xs) if xs else np.zeros((0, 3), np.float32)
    rgb = np.concatenate(cs) if cs else np.zeros((0, 3), np.uint8)
    return PartSample(xyz, rgb, n, spill)


def spilled_chunks(scratch: Path, part: ScanPart, origin: np.ndarray, points: int) -> Iterator[ScanChunk]:
    """The chunks of a part whose ``points`` points were spilled to ``scratch`` while sampling
    (moved by the part's refined registration when it has one)."""
    return _posed(part, _spilled(scratch, part, origin, points))


def _spilled(scratch: Path, part: ScanPart, origin: np.ndarray, points: int) -> Iterator[ScanChunk]:
    pxyz, prgb = _spill_paths(scratch, part)
    for a in range(0, points, CHUNK_POINTS):
        m = min(CHUNK_POINTS, points - a)
        xyz = np.fromfile(pxyz, np.float32, count=3 * m, offset=12 * a).reshape(m, 3)
        rgb = np.fromfile(prgb, np.uint8, count=3 * m, offset=3 * a).reshape(m, 3)
        yield ScanChunk(xyz, rgb, origin, part.start + a)


# --------------------------------------------------------------------------- walls


@dataclass
class WallIndex:
    """The walls' frames and a lookup grid telling which walls may own a point.

    Plan cells of ``cell_m`` (x, y) and Z bands between the walls' bottoms and tops; each
    cell of the grid holds the id of a combination of walls (``combos``; 0: none) whose
    slab touches it.
    """

    ids: list[str]
    frames: list[WallFrame]
    origin: np.ndarray  # the cloud's recentring origin
    lo: np.ndarray  # (2,) plan corner of the grid, relative to origin
    cell_m: float
    nx: int
    ny: int
    z_edges: np.ndarray  # band boundaries, relative to origin
    lut: np.ndarray  # (nz * ny * nx,) combination id per cell
    combos: list[np.ndarray]  # wall numbers per combination id
    behind_m: float
    front_m: float
    end_m: float  # a point this far beyond a wall's end is still looked at
    slab_m: float  # points this close to a wall's bottom / top are the floor's / ceiling's

    @classmethod
    def build(cls, walls: Sequence[Wall], origin: np.ndarray, s: SegmentationSettings) -> WallIndex:
        origin = np.asarray(origin, np.float64)
        cell = float(s.assign_cell_m)
        frames = [w.frame for w in walls]
        sl, tol = s.slab_tolerance_m, s.wall_plane_tolerance_m
        regions, zr = [], []
        for f in frames:
            o = f.origin - origin
            step = cell / 2
            us = np.arange(-tol, f.width_m + tol + step, step)
            ds = np.arange(-s.behind_depth_m, s.object_depth_m + step, step)
            uu, dd = np.meshgrid(us, ds)
            pts = o[:2] + uu.ravel()[:, None] * f.axis_u[:2] + dd.ravel()[:, None] * f.normal[:2]
            regions.append(pts)
            zr.append((o[2] + sl - _Z_SLACK, o[2] + f.height_m - sl + _Z_SLACK))
        allp = np.concatenate(regions) if regions else np.zeros((1, 2))
        lo = np.floor(allp.min(axis=0) / cell) * cell - cell
        nx, ny = (np.floor((allp.max(axis=0) - lo) / cell).astype(int) + 2).tolist()
        z_edges = np.unique(np.asarray(zr, np.float64).ravel()) if zr else np.zeros(1)
        nz = len(z_edges) + 1
        cells_of: dict[int, set[int]] = {}
        for w, (pts, (z0, z1)) in enumerate(zip(regions, zr, strict=True)):
            ij = np.floor((pts - lo) / cell).astype(np.int64)
            ij = np.unique(ij, axis=0)
            ij = np.unique((ij[:, None, :] + _NEIGHBOURS[None, :, :]).reshape(-1, 2), axis=0)
            ij = ij[(ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)]
            bands = np.flatnonzero((z_edges[:-1] >= z0) & (z_edges[1:] <= z1)) + 1
            for b in bands:
                for key in ((b * ny + ij[:, 1]) * nx + ij[:, 0]).tolist():
                    cells_of.setdefault(key, set()).add(w)
        combo_id: dict[tuple[int, ...], int] = {}
        combos: list[np.ndarray] = [np.zeros(0, np.int32)]
        lut = np.zeros(nz * ny * nx, np.int32)
        for key, ws in cells_of.items():
            t = tuple(sorted(ws))
            if t not in combo_id:
                combo_id[t] = len(combos)
                combos.append(np.asarray(t, np.int32))
            lut[key] = combo_id[t]
        if len(combos) < 32767:
            lut = lut.astype(np.int16)
        return cls([w.id for w in walls], frames, origin, lo, cell, int(nx), int(ny), z_edges, lut, combos,
                   s.behind_depth_m, s.object_depth_m, tol, sl)


_Z_SLACK = 0.005  # Z bands reach this beyond a wall's bottom and top (float32 rounding of the test)
_NEIGHBOURS = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)], np.int64)


def assign_chunk(xyz: np.ndarray, index: WallIndex) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """The points of a chunk that belong to each wall: (wall number, indices, their u v d).

    A pure function of the chunk (float32 ``xyz`` relative to ``index.origin``): a point
    belongs to a wall when it lies over the wall's frame (``u`` within ``end_m`` of
    ``0..width``, ``v`` more than ``slab_m`` above the bottom and below the top) between
    ``behind_m`` behind and ``front_m`` in front of the plane; of several such walls the
    nearest plane gets it (the first wall on a tie). ``u v d`` come from
    :func:`~sbsc_core.imaging.orthoimage.wall_coordinates`, so the orthoimage of the assigned points
    is the one :func:`~sbsc_core.imaging.orthoimage.build_orthoimage` gives.
    """
    if len(xyz) == 0 or not index.frames:
        return
    # grid cells; points beyond the grid are clamped to its border cells, which no wall's
    # slab reaches: the exact test below rejects them
    cell = np.float32(1.0 / index.cell_m)
    t = xyz[:, 0] - np.float32(index.lo[0])
    t *= cell
    np.clip(t, 0, index.nx - 1, out=t)
    key = t.astype(np.int32)
    t = xyz[:, 1] - np.float32(index.lo[1])
    t *= cell
    np.clip(t, 0, index.ny - 1, out=t)
    iy = t.astype(np.int32)
    del t
    z = xyz[:, 2]
    band = np.zeros(len(xyz), np.int32)
    for e in index.z_edges.astype(np.float32).tolist():  # a few edges: one comparison each
        band += z >= np.float32(e)
    band *= np.int32(index.ny)
    band += iy
    band *= np.int32(index.nx)
    key += band
    del band, iy
    combo = index.lut[key]
    del key
    sel = np.flatnonzero(combo)
    if len(sel) == 0:
        return
    c = combo[sel]
    order = np.argsort(c, kind="stable")
    sel, c = sel[order], c[order]
    bounds = np.flatnonzero(np.diff(c)) + 1
    starts = np.concatenate([[0], bounds])
    stops = np.concatenate([bounds, [len(c)]])
    per_wall: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
    for a, b in zip(starts.tolist(), stops.tolist(), strict=True):
        idx = sel[a:b]
        walls = index.combos[int(c[a])]
        pts = np.take(xyz, idx, axis=0)  # np.take, np.compress: as xyz[idx], uvd[ok], without fancy indexing's slow path
        best = None
        for w in walls.tolist():
            uvd = wall_coordinates(pts, index.frames[w], index.origin)
            ok = _inside(uvd, index.frames[w], index)
            if len(walls) == 1:
                if ok.any():
                    per_wall.setdefault(w, []).append((idx[ok], np.compress(ok, uvd, axis=0)))
                break
            ad = np.abs(uvd[:, 2])
            if best is None:
                best = np.full(len(idx), np.inf, np.float32)
                owner = np.full(len(idx), -1, np.int32)
                kept: dict[int, np.ndarray] = {}
            ok &= ad < best
            best[ok] = ad[ok]
            owner[ok] = w
            kept[w] = uvd
        if best is not None:
            for w, uvd in kept.items():
                mine = owner == w
                if mine.any():
                    per_wall.setdefault(w, []).append((idx[mine], np.compress(mine, uvd, axis=0)))
    for w in sorted(per_wall):
        pieces = per_wall[w]
        if len(pieces) == 1:
            yield w, pieces[0][0], pieces[0][1]
        else:
            yield w, np.concatenate([p[0] for p in pieces]), np.concatenate([p[1] for p in pieces])


def _inside(uvd: np.ndarray, f: WallFrame, index: WallIndex) -> np.ndarray:
    u, v, d = uvd[:, 0], uvd[:, 1], uvd[:, 2]
    return ((d >= -index.behind_m) & (d <= index.front_m) & (u >= -index.end_m) & (u <= f.width_m + index.end_m)
            & (v > index.slab_m) & (v < f.height_m - index.slab_m))


# --------------------------------------------------------------------------- pass 2


def _wall_dir(scratch: Path, w: int) -> Path:
    return scratch / f"wall-{w:04d}"


def _band_dir(scratch: Path, w: int, band: int) -> Path:
    return _wall_dir(scratch, w) / f"b{band:04d}"


def band_rows(frame: WallFrame, ortho: OrthoimageSettings) -> int:
    """Orthoimage rows of one band of a wall's partition: about ``BAND_PIXELS`` pixels."""
    return max(1, BAND_PIXELS // ortho_shape(frame, ortho.pixel_m)[1])


def partition_part(part: ScanPart, origin: np.ndarray, index: WallIndex, scratch: str, *, points: int,
                   spilled: bool, ortho: OrthoimageSettings,
                   also: Callable[[ScanChunk, str], object] | None = None) -> list[int]:
    """Stream one part again (or its spill) and append each wall's binned points to its partition.

    A wall's partition is cut into bands of orthoimage rows (:func:`band_rows`), one folder
    each, so that its orthoimage is made band by band. ``also`` is called with each chunk
    and the part's key: another binning of the same points (the ceilings',
    :class:`~sbsc_core.scene.ceilings.CeilingBinning`) without reading them again. Returns
    the number of records written per wall.
    """
    root = Path(scratch)
    chunks = spilled_chunks(root, part, origin, points) if spilled else part_chunks(part, origin)
    written = [0] * len(index.frames)
    band_px = [band_rows(f, ortho) * ortho_shape(f, ortho.pixel_m)[1] for f in index.frames]
    made: set[tuple[int, int]] = set()
    for chunk in chunks:
        if also is not None:
            also(chunk, part.key)
        for w, idx, uvd in assign_chunk(chunk.xyz, index):
            keep, pixel = ortho_pixels(uvd, index.frames[w], ortho)
            kept = np.flatnonzero(keep)
            band = pixel // band_px[w]
            b0, b1 = (int(band.min()), int(band.max())) if len(band) else (0, -1)
            if b0 != b1:  # the points grouped by band (a radix sort of small integers)
                band -= b0
                order = np.argsort(band.astype(np.uint16 if b1 - b0 < 65536 else np.int64), kind="stable")
                kept, pixel, band = kept[order], pixel[order], band[order]
                band += b0
            rec = np.empty(len(pixel), RECORD)
            rec["pixel"] = pixel
            rec["depth"] = uvd[:, 2][kept]
            rec["rgb"] = np.take(chunk.rgb, idx[kept], axis=0)
            cuts = np.searchsorted(band, np.arange(b0, b1 + 2))
            for b in range(b0, b1 + 1):
                a, z = int(cuts[b - b0]), int(cuts[b - b0 + 1])
                if z > a:
                    d = _band_dir(root, w, b)
                    if (w, b) not in made:  # one mkdir per band folder and part, not per chunk
                        d.mkdir(parents=True, exist_ok=True)
                        made.add((w, b))
                    with open(d / f"{part.key}.rec", "ab") as fh:
                        rec[a:z].tofile(fh)
            written[w] += len(rec)
    if spilled:
        for p in _spill_paths(root, part):
            p.unlink(missing_ok=True)
    return written


def drop_wall_partition(scratch: Path | str, w: int) -> None:
    """Delete the partition of wall number ``w`` (once its task is done: it is not read again)."""
    shutil.rmtree(_wall_dir(Path(scratch), w), ignore_errors=True)


def _read_records(files: Sequence[Path]) -> np.ndarray:
    sizes = [f.stat().st_size // RECORD.itemsize for f in files]
    out = np.empty(sum(sizes), RECORD)
    at = 0
    for f, n in zip(files, sizes, strict=True):
        with open(f, "rb") as fh:
            fh.readinto(memoryview(out[at:at + n].view(np.uint8)))
        at += n
    return out


def append_records(folder: Path, key: str, pixel: np.ndarray, depth: np.ndarray, rgb: np.ndarray) -> int:
    """Append binned points (orthoimage pixel, depth, colour) to ``folder/key.rec``; their count.

    The partition format of any surface (a ceiling tile, a column face): read it back with
    :func:`folder_records`.
    """
    rec = np.empty(len(pixel), RECORD)
    rec["pixel"] = pixel
    rec["depth"] = depth
    rec["rgb"] = rgb
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / f"{key}.rec", "ab") as fh:
        rec.tofile(fh)
    return len(rec)


def folder_records(folder: Path) -> np.ndarray:
    """Every record that :func:`append_records` wrote to ``folder``, in a fixed order of the parts."""
    return _read_records(sorted(folder.glob("*.rec")) if folder.is_dir() else [])


def wall_records(scratch: Path | str, w: int, band: int | None = None) -> np.ndarray:
    """The records of wall number ``w`` (of one band of it, or all), in a fixed order of the parts."""
    d = _wall_dir(Path(scratch), w)
    pattern = "b*/*.rec" if band is None else f"b{band:04d}/*.rec"
    return _read_records(sorted(d.glob(pattern)) if d.is_dir() else [])


def wall_orthoimage(scratch: Path | str, w: int, wall_id: str, frame: WallFrame,
                    settings: OrthoimageSettings) -> Orthoimage:
    """The orthoimage of wall number ``w`` from its partition (the bare per-pixel medians).

    The bands of the partition are binned one after the other, so the points held at once
    are those of one band, however many the wall has.
    """
    h, width = ortho_shape(frame, settings.pixel_m)
    rows = band_rows(frame, settings)
    depth = np.full((h, width), np.nan, np.float32)
    colour = np.zeros((h, width, 3), np.uint8)
    mask = np.zeros((h, width), bool)
    bands: list[tuple[int, FrontLayers]] = []
    for b, r0 in enumerate(range(0, h, rows)):
        rec = wall_records(scratch, w, b)
        if not len(rec):
            continue
        r1 = min(h, r0 + rows)
        pixel = rec["pixel"].astype(np.int64)
        pixel -= r0 * width
        pd, prgb = np.ascontiguousarray(rec["depth"]), np.ascontiguousarray(rec["rgb"])
        del rec
        d, c, m = rasterize_median(pixel, pd, prgb, (r1 - r0, width), depth_range=settings.depth_range_m,
                                   quantum=settings.depth_quantum_m, **layer_options(settings))
        depth[r0:r1], colour[r0:r1], mask[r0:r1] = d, c, m
        band_front = front_images(pixel, pd, prgb, (r1 - r0, width), settings)
        if band_front is not None:
            bands.append((r0, band_front))
        del pixel, pd, prgb
    return orthoimage_from_images(wall_id, frame, depth, colour, mask, settings=settings,
                                  front=stack_front(bands, (h, width)))


def worker_ready() -> bool:
    """A no-op run in each new worker process: it has started and imported the reading tasks
    (this module: numpy and the scan readers, not the recognition stages)."""
    return True


def sample_step(total_points: int, s: DetectionSettings) -> int:
    """Stride of the regular sample: at most twice the points segmentation fits walls on."""
    return max(1, math.ceil(total_points / (2 * s.segmentation.fit_max_points)))


class SampleBuffer:
    """The parts' samples gathered into one cloud while the other parts are still read.

    When every part is a range of a seekable file, the size of its sample is known in
    advance (the points whose index over all files is a multiple of ``step``): each sample
    is copied to its place as it arrives (:meth:`add`) and :meth:`cloud` is
    :func:`sample_cloud` of them without the final concatenation. Otherwise (or when a
    sample has another size) the samples are concatenated at the end.
    """

    def __init__(self, parts: Sequence[ScanPart], step: int) -> None:
        sizes = [None if p.stop is None else len(range((-p.first) % step, p.stop - p.start, step)) for p in parts]
        self.sizes = sizes
        self.copied: set[int] = set()
        self.xyz = self.rgb = None
        self.at: list[int] = []
        if sizes and all(n is not None for n in sizes):
            self.at = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64).tolist()
            self.xyz = np.empty((self.at[-1], 3), np.float32)
            self.rgb = np.empty((self.at[-1], 3), np.uint8)

    def add(self, k: int, smp: PartSample) -> PartSample:
        """Take part ``k``'s sample; returns it, without its points when they were copied."""
        if self.xyz is None or len(smp.xyz) != self.sizes[k] or len(smp.rgb) != self.sizes[k]:
            return smp  # not the expected size: kept whole
        a, b = self.at[k], self.at[k + 1]
        self.xyz[a:b] = smp.xyz
        self.rgb[a:b] = smp.rgb
        self.copied.add(k)
        return PartSample(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), smp.points, smp.spilled)

    def move(self, k: int, samples: list[PartSample], pose) -> None:
        """Move part ``k``'s sample by its file's refined registration (a 4x4 array or
        :attr:`ScanPart.pose`'s rows; None: as is), before :meth:`cloud`."""
        if pose is None:
            return
        if k in self.copied:
            a, b = self.at[k], self.at[k + 1]
            self.xyz[a:b] = apply_pose(self.xyz[a:b], pose)
        else:
            smp = samples[k]
            samples[k] = PartSample(apply_pose(smp.xyz, pose), smp.rgb, smp.points, smp.spilled)

    def cloud(self, samples: Sequence[PartSample], origin: np.ndarray, sources: Sequence[str], limit: int
              ) -> PointCloud:
        """:func:`sample_cloud` of the samples (``samples``: what :meth:`add` returned, in order)."""
        xyz, rgb = self.xyz, self.rgb
        self.xyz = self.rgb = None
        if xyz is None or len(self.copied) < len(samples):  # some kept whole: put the copied ones back
            whole = [PartSample(xyz[self.at[k]:self.at[k + 1]], rgb[self.at[k]:self.at[k + 1]], smp.points,
                                smp.spilled) if k in self.copied else smp for k, smp in enumerate(samples)]
            return sample_cloud(whole, origin, sources, limit)
        if len(xyz) > limit:
            k = math.ceil(len(xyz) / limit)
            xyz, rgb = xyz[::k].copy(), rgb[::k].copy()
        return PointCloud(xyz=xyz, rgb=rgb, origin=np.asarray(origin, np.float64), sources=tuple(sources))


def sample_cloud(samples: Sequence[PartSample], origin: np.ndarray, sources: Sequence[str], limit: int
                 ) -> PointCloud:
    """The parts' samples as one cloud, thinned regularly to at most ``limit`` points."""
    xyz = np.concatenate([p.xyz for p in samples])
    rgb = np.concatenate([p.rgb for p in samples])
    if len(xyz) > limit:
        k = math.ceil(len(xyz) / limit)
        xyz, rgb = xyz[::k].copy(), rgb[::k].copy()
    return PointCloud(xyz=xyz, rgb=rgb, origin=np.asarray(origin, np.float64), sources=tuple(sources))


def apply_pose(xyz: np.ndarray, pose: np.ndarray | Sequence[Sequence[float]] | None) -> np.ndarray:
    """``xyz`` (recentred, float32) moved by a station's 4x4 ``pose`` (None: as is)."""
    if pose is None:
        return xyz
    P = np.asarray(pose, np.float64)
    out = np.asarray(xyz, np.float64) @ P[:3, :3].T
    out += P[:3, 3]
    return out.astype(np.float32)
