"""Storeys, floor, ceiling and walls of a registered scan (paper, section 3.1).

Stray points far from the building are set aside first (:mod:`~sbsc_core.scene.stray_points`):
every grid below is sized by the dense part of the scan. A scan may hold several storeys:
they are the parts of the Z range between slabs (thin Z ranges with almost no points
between a ceiling level and a floor level, :func:`find_storeys`), and everything below
runs on each storey as on a floor; the walls of all storeys are one list, each wall naming
its storey. Within a storey rooms may have different ceilings: the storey's ceiling is the
highest, and each wall's height is the top of its own points (its room's ceiling).

The floor and the ceiling are the two maxima of the Z histogram. Walls are found among
the points between them: a regular subsample is cut into voxels, each voxel holding a
planar patch gives a local normal (eigen-decomposition of its covariance, accumulated with
``bincount``); vertical patches are grouped by direction (histogram of normal angles, so
walls at any angle work) and, within a direction, by plane offset. A wall's room side -
the side it was scanned from - is the side where the floor and ceiling continue; behind a
wall face there is the wall's body, with no floor or ceiling points. Each room-facing
side is therefore its own wall, a partition between two rooms gives two walls with
opposite normals. Each plane is split along its length where its points stop for more
than ``wall_gap_m`` and where another wall ends against it from the room side (a
T-junction between two rooms: collinear walls of neighbouring rooms); a wall's end at a
junction or a corner is the crossing of the two planes. Every point between floor and
ceiling is then given to the wall whose plane it is closest to, among the walls whose slab
(``behind_depth_m`` behind to ``object_depth_m`` in front, over the wall's length) holds
it, and each wall is refitted by trimmed least squares on its own points; a free end (no
wall met there) is where the wall's points stop. The frame follows contract 4. A plane set
back in an opening of a wall of the same facing that does not reach that wall's top (a
door leaf recessed in its frame) is no wall. :func:`assign_points_to_walls` gives points
to walls from the final frames alone, chunk by chunk, for clouds streamed from disk.

Everything is vectorized with numpy; the whole-floor cost is a few passes over the points
plus one radix sort of 16-bit bucket numbers.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, NoWallsError
from ..io.scan_source import BLOCK_POINTS, ORIGIN_SAMPLE
from ..settings import SegmentationSettings
from ..types import PointCloud, Segmentation, Storey, Wall, WallFrame
from .stray_points import DenseBox, dense_box, inside_box

__all__ = ["segment_floor_ceiling_walls", "find_scan_storeys", "ScanStoreys", "segment_storeys",
           "segment_storey", "storey_bounds", "StoreyPoints", "find_storeys", "find_floor_ceiling", "fit_line_2d",
           "assign_points_to_walls"]

_DENSE_VOXELS = 1 << 24  # voxel grids up to this size are grouped with bincount, larger ones by sorting
_CHUNK = 1 << 22  # points handled at once where temporaries would otherwise grow with the wall
_PLANE_BLOCK = 1 << 15  # voxels compared with every plane at once (bounds a (voxels, planes) array)
_ORIGIN_POINTS = min(BLOCK_POINTS, ORIGIN_SAMPLE)  # first points of a file that set its origin
_ASSIGN_THREADS = 2  # threads assigning points to walls
_THREAD_MIN_POINTS = 1 << 22  # clouds smaller than this are assigned in one thread


@dataclass
class _Segment:
    """A wall candidate in the cloud's relative XY frame: n . p = s on the plane."""

    n: np.ndarray  # (2,) unit normal, into the room once oriented
    s: float
    cells: np.ndarray  # (k, 3) centroids of its planar voxels
    u0: float = 0.0
    u1: float = 0.0
    e0: np.ndarray | None = None  # fixed end points (XY) where the wall meets another one, else free ends
    e1: np.ndarray | None = None

    @property
    def t(self) -> np.ndarray:
        """Horizontal axis u = z x n (to the right seen from the room)."""
        return np.array([-self.n[1], self.n[0]])

    def extents(self, pad: float) -> None:
        u = self.cells[:, :2] @ self.t
        self.u0, self.u1 = float(u.min()) - pad, float(u.max()) + pad

    def flip(self) -> None:
        self.n, self.s = -self.n, -self.s
        self.u0, self.u1 = -self.u1, -self.u0
        self.e0, self.e1 = self.e1, self.e0

    def point(self, u: float, d: float = 0.0) -> np.ndarray:
        return (self.s + d) * self.n + u * self.t


# --------------------------------------------------------------------------- public


StoreyPoints = Callable[[list[tuple[float, float]], list[float]], Iterator[PointCloud]]
"""Given the Z range of each storey (relative to the scan's origin, bottom up) and the share
of the scan's sample in each, yields each storey's cloud in turn, in the scan's frame (the
callee may change it): see :func:`segment_storeys`."""


@dataclass
class ScanStoreys:
    """What :func:`find_scan_storeys` finds in a cloud (or a regular sample of a scan)."""

    levels: list[tuple[float, float]]  # (floor, ceiling) of each storey, bottom up, relative to ``origin``
    origin: np.ndarray  # (3,) the cloud's origin
    box: DenseBox  # its dense part
    stray: int  # its points outside the dense part
    shares: list[float]  # share of its points in each storey's Z range (:func:`storey_bounds`)
    sample: np.ndarray | None = None  # one storey: the dense part's sample its walls are fitted on


def find_scan_storeys(cloud: PointCloud, settings: SegmentationSettings | None = None) -> ScanStoreys:
    """The dense part of ``cloud`` and the storeys in it (:func:`find_storeys`).

    Raises :class:`~sbsc_core.errors.NoWallsError` when the cloud has no floor / ceiling pair,
    :class:`~sbsc_core.errors.InputError` when its dense part is not a building's.
    """
    s = settings or SegmentationSettings()
    if len(cloud) == 0:
        raise NoWallsError("no walls found: the scan has no points")
    box, stray, sample = _dense_sample(cloud, s)
    levels = find_storeys(sample[:, 2], s, sample[:, :2])
    shares = [1.0]
    if len(levels) > 1:  # each storey is sampled again on its own: this sample is not needed
        del sample
        sample = None
        shares = [sum(np.count_nonzero(m) for _, m in _z_masks(cloud.xyz, lo, hi)) / len(cloud)
                  for lo, hi in storey_bounds(levels)]
    return ScanStoreys(levels, np.asarray(cloud.origin, np.float64).copy(), box, int(stray), shares, sample)


def segment_floor_ceiling_walls(cloud: PointCloud, settings: SegmentationSettings | None = None, *,
                                storeys: ScanStoreys | None = None) -> Segmentation:
    """Storeys, their floor and ceiling levels and the walls of ``cloud`` with frames and points.

    Stray points (outside the dense part, see :mod:`~sbsc_core.scene.stray_points`) are ignored and
    counted. The storeys are the parts of the Z range between slabs (:func:`find_storeys`);
    the paper's method runs on each storey as on a floor. Walls get ids ``W01, W02, ...``
    ordered by their centre (north to south, then west to east, in plan) and their direction;
    with several storeys the ids carry the storey (``S1-W01``).

    With several storeys each storey is segmented on its own points as if it had been scanned
    alone (:func:`segment_storeys`): a storey's walls do not depend on how many storeys are
    above or below it. ``storeys``: what :func:`find_scan_storeys` found in ``cloud``
    (found here without it). Raises :class:`~sbsc_core.errors.NoWallsError` when the cloud
    has no floor / ceiling pair or no wall, :class:`~sbsc_core.errors.InputError` when its
    dense part is not a building's.
    """
    s = settings or SegmentationSettings()
    found = storeys or find_scan_storeys(cloud, s)
    if len(found.levels) > 1:
        picked: list[np.ndarray] = []

        def own_points(bounds: list[tuple[float, float]], shares: list[float]) -> Iterator[PointCloud]:
            for lo, hi in bounds:
                sel = _z_index(cloud.xyz, lo, hi)
                picked.append(sel)
                yield PointCloud(xyz=cloud.xyz[sel], rgb=cloud.rgb[sel], origin=cloud.origin, sources=cloud.sources)

        seg = segment_storeys(found, own_points, s)
        for wall, sel in zip(seg.walls, [picked[int(w.storey[1:]) - 1] for w in seg.walls], strict=True):
            wall.point_index = sel[wall.point_index]
        return seg
    z0 = float(cloud.origin[2])
    floor, ceiling = found.levels[0]
    sample = found.sample if found.sample is not None else _dense_sample(cloud, s, found.box)[2]
    found.sample = None  # not kept beyond the walls' fit
    walls = _storey_walls(cloud.xyz, sample, found.box, floor, ceiling, origin=cloud.origin, s=s)
    return Segmentation(floor_z=floor + z0, ceiling_z=ceiling + z0, storeys=[Storey("S1", floor + z0, ceiling + z0)],
                        walls=[Wall(id=f"W{i + 1:02d}", frame=f, point_index=idx, storey="S1")
                               for i, (f, idx) in enumerate(walls)], stray_points=found.stray)


def segment_storeys(storeys: ScanStoreys, storey_points: StoreyPoints,
                    settings: SegmentationSettings | None = None, *, point_index: bool = True) -> Segmentation:
    """The walls of each of several storeys, each segmented as if it had been scanned alone.

    Each storey's points are those between the middles of the slabs below and above it
    (:func:`storey_bounds`); ``storey_points`` gives them, storey by storey (a scan read out
    of core gives them at the density the storey alone would be sampled with). Each is
    recentred on its own origin and segmented by :func:`segment_storey`: its own sample
    density, dense part and levels, so that its walls are those of its points scanned alone.
    The walls' ``point_index`` index their storey's cloud (empty without ``point_index``: not
    kept from one storey to the next).
    """
    s = settings or SegmentationSettings()
    levels = storeys.levels
    out: list[Storey] = []
    walls: list[Wall] = []
    clouds = storey_points(storey_bounds(levels), list(storeys.shares))
    for k, ((floor, ceiling), sub) in enumerate(zip(levels, clouds, strict=False)):
        sid = f"S{k + 1}"
        if not np.allclose(sub.origin, storeys.origin):
            raise ValueError(f"storey {sid}: its cloud has another origin than the scan's")
        shift = sub.origin - _own_origin(sub)
        if shift.any():  # the storey's cloud is ours: recentred in place
            sub = _recentred(sub, shift, in_place=True)
        box = DenseBox(storeys.box.lo + shift, storeys.box.hi + shift)
        one = segment_storey(sub, sid, (floor + shift[2], ceiling + shift[2]), s, box)
        del sub
        if not point_index:
            for wall in one.walls:
                wall.point_index = np.zeros(0, np.int64)
        out += one.storeys
        walls += one.walls
    if len(out) != len(levels):
        raise ValueError(f"storey points: {len(out)} storey clouds for {len(levels)} storeys")
    return Segmentation(floor_z=out[0].floor_z, ceiling_z=out[-1].ceiling_z, walls=walls, storeys=out,
                        stray_points=storeys.stray)


def segment_storey(cloud: PointCloud, sid: str, levels: tuple[float, float],
                   settings: SegmentationSettings | None = None, box: DenseBox | None = None) -> Segmentation:
    """The walls of one storey's points ``cloud``, segmented as if the storey had been scanned alone.

    Its dense part, sample and levels are its own (as :func:`segment_floor_ceiling_walls`
    finds them on a one-storey scan), unless its points do not show one storey (then
    ``levels``, its (floor, ceiling) in the cloud's frame, and ``box``, the building's dense
    part, apply). Walls get ids ``{sid}-W01, ...`` and the storey ``sid``; their
    ``point_index`` index ``cloud``.
    """
    s = settings or SegmentationSettings()
    z0 = float(cloud.origin[2])
    floor, ceiling = levels
    if len(cloud) == 0:
        raise NoWallsError(f"storey {sid} (z = {floor + z0:.2f} to {ceiling + z0:.2f} m): no walls found: no points")
    shift = cloud.origin - _own_origin(cloud)
    if shift.any():  # in the storey's own frame, as a scan of it alone (the frames are world coordinates)
        cloud = _recentred(cloud, shift)
        floor, ceiling = floor + shift[2], ceiling + shift[2]
        z0 -= shift[2]
        if box is not None:
            box = DenseBox(box.lo + shift, box.hi + shift)
    try:
        own_box, _, sample = _dense_sample(cloud, s)
        own = find_storeys(sample[:, 2], s, sample[:, :2])
    except (NoWallsError, InputError):
        own = []
    if len(own) == 1:
        box = own_box
        floor, ceiling = own[0]
    else:  # not one storey on its own: the levels and the dense part found in the whole scan
        sample = _dense_sample(cloud, s, box)[2]
    try:
        found = _storey_walls(cloud.xyz, sample, box, floor, ceiling, origin=cloud.origin, s=s)
    except NoWallsError as exc:
        raise NoWallsError(f"storey {sid} (z = {floor + z0:.2f} to {ceiling + z0:.2f} m): {exc}") from None
    return Segmentation(floor_z=floor + z0, ceiling_z=ceiling + z0, storeys=[Storey(sid, floor + z0, ceiling + z0)],
                        walls=[Wall(id=f"{sid}-W{i + 1:02d}", frame=f, point_index=idx, storey=sid)
                               for i, (f, idx) in enumerate(found)])


def _own_origin(cloud: PointCloud) -> np.ndarray:
    """The recentring origin a scan of ``cloud``'s points alone would have: the rounded median
    of its first points (as :func:`~sbsc_core.io.scans.iter_scan` sets a file's)."""
    first = cloud.xyz[:_ORIGIN_POINTS].astype(np.float64) + cloud.origin
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns
        med = np.nanmedian(first, axis=0)
    return np.where(np.isfinite(med), np.round(med), 0.0) + 0.0


def _recentred(cloud: PointCloud, shift: np.ndarray, *, in_place: bool = False) -> PointCloud:
    """``cloud`` recentred on ``origin - shift``: its float32 coordinates plus ``shift``, added
    in float64 chunk by chunk (no full-size temporary); ``in_place`` changes ``cloud.xyz``
    itself instead of a copy."""
    xyz = cloud.xyz if in_place else cloud.xyz.copy()
    for a in range(0, len(xyz), _CHUNK):
        np.add(xyz[a: a + _CHUNK], shift, out=xyz[a: a + _CHUNK], casting="unsafe")
    return PointCloud(xyz=xyz, rgb=cloud.rgb, origin=cloud.origin - shift, sources=cloud.sources)


def storey_bounds(levels: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The Z range ``[lo, hi)`` of each storey's points, from its (floor, ceiling) levels
    bottom up: from the middle of the slab below to the middle of the slab above (open at
    the bottom of the lowest storey and the top of the highest)."""
    mids = [0.5 * (levels[k][1] + levels[k + 1][0]) for k in range(len(levels) - 1)]
    return list(zip([-math.inf, *mids], [*mids, math.inf], strict=True))


def _dense_sample(cloud: PointCloud, s: SegmentationSettings, box: DenseBox | None = None
                  ) -> tuple[DenseBox, int, np.ndarray]:
    """The dense part of ``cloud`` (``box``, or found), the number of points outside it and a
    regular subsample of the points inside (at most about ``2 * fit_max_points``)."""
    xyz = cloud.xyz
    n = len(xyz)
    if box is None:
        box = dense_box(xyz, s, where=", ".join(cloud.sources) or "scan")
    step = max(1, math.ceil(n / (2 * s.fit_max_points)))
    if step == 1:  # the sample is the dense part itself: one test of the box
        inside = inside_box(xyz, box)
        stray = n - int(np.count_nonzero(inside))
        sample = xyz[inside]
        del inside
    else:
        stray = n - _count_inside(xyz, box)
        sample = xyz[::step]
        sample = sample[inside_box(sample, box)]
    return box, stray, sample


def _z_masks(xyz: np.ndarray, lo: float, hi: float) -> Iterator[tuple[int, np.ndarray]]:
    """(first index, mask of lo <= z < hi) of each chunk of ``xyz``."""
    for a in range(0, len(xyz), _CHUNK):
        z = xyz[a: a + _CHUNK, 2]
        yield a, (z >= lo) & (z < hi)


def _z_index(xyz: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Indices of the points with lo <= z < hi, chunk by chunk."""
    parts = [np.flatnonzero(m) + a for a, m in _z_masks(xyz, lo, hi)]
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


def _storey_walls(xyz: np.ndarray, sample: np.ndarray, box: DenseBox, floor: float, ceiling: float,
                  *, origin: np.ndarray, s: SegmentationSettings) -> list[tuple[WallFrame, np.ndarray]]:
    """Section 3.1 on one storey: its walls (frame, point indices into ``xyz``) in id order."""
    height = ceiling - floor
    zs = sample[:, 2]
    # np.compress: as sample[mask], without fancy indexing's slow path
    band = np.compress((zs > floor + s.slab_margin_m) & (zs < ceiling - s.slab_margin_m), sample, axis=0)
    if len(band) > s.fit_max_points:
        band = band[:: math.ceil(len(band) / s.fit_max_points)]
    cells = _planar_cells(band, s)
    segs = _wall_planes(cells, floor, height, s)
    if not segs:
        raise NoWallsError("no walls found: no vertical plane between floor and ceiling is large enough")
    slab = np.compress((np.abs(zs - floor) < s.slab_tolerance_m) | (np.abs(zs - ceiling) < s.slab_tolerance_m), sample,
                       axis=0)
    segs = _orient(segs, slab[:, :2].astype(np.float64), s)
    segs = _drop_standing_in_front(segs, s)
    segs = _split_at_junctions(segs, s)
    _snap_corners(segs, s)
    segs = [g for g in segs if _big_enough(g, floor, height, s)]
    segs = _drop_recessed(segs, s)
    if not segs:
        raise NoWallsError("no walls found: no wall face is long and high enough")
    del band, slab

    index = _assign_points(xyz, segs, floor + s.slab_tolerance_m, ceiling - s.slab_tolerance_m, s=s, box=box)
    walls: list[tuple[WallFrame, np.ndarray]] = []
    threads = min(_ASSIGN_THREADS, os.cpu_count() or 1) if len(xyz) >= _THREAD_MIN_POINTS else 1
    with ThreadPoolExecutor(max_workers=threads) as pool:  # each wall on its own (numpy releases the GIL)
        for done in pool.map(lambda job: _final_frame(xyz, job[1], job[0], floor, ceiling,
                                                      origin=origin, s=s),
                             zip(segs, index, strict=True)):
            if done is not None and done[0].width_m >= s.min_wall_length_m:
                walls.append(done)
    if not walls:
        raise NoWallsError("no walls found: no wall kept its points")
    walls.sort(key=_order_key)
    return walls


def _count_inside(xyz: np.ndarray, box: DenseBox) -> int:
    return sum(int(inside_box(xyz[a: a + _CHUNK], box).sum()) for a in range(0, len(xyz), _CHUNK))



def _z_histogram_sample(z: np.ndarray, s: SegmentationSettings) -> tuple[np.ndarray, int, np.ndarray]:
    """The finite values (float64) of a regular subsample of ``z`` of at most
    ``s.histogram_max_points``, its step, and which of the subsample's values are finite.
    Raises NoWallsError when there are none."""
    z = np.asarray(z)
    step = max(1, math.ceil(len(z) / s.histogram_max_points))
    zs = z[::step]
    keep = np.isfinite(zs)
    zs = zs[keep].astype(np.float64)
    if len(zs) == 0:
        raise NoWallsError("no walls found: the scan has no points")
    return zs, step, keep

def find_storeys(z: np.ndarray, settings: SegmentationSettings | None = None,
                 xy: np.ndarray | None = None) -> list[tuple[float, float]]:
    """(floor, ceiling) of every storey, bottom up, in the frame of ``z``.

    Storeys are separated by slabs: Z ranges of at least ``min_slab_m`` where the histogram
    of Z (``storey_bin_m`` bins) holds less than ``slab_gap_fraction`` of its median bin
    between the lowest and the highest point (a floor's walls fill every bin between its
    floor and its ceiling; inside a slab there is nothing to see but a stairwell), with a
    horizontal surface (a bin, or two neighbouring bins together, of ``slab_level_factor``
    times the median) within
    ``slab_level_reach_m`` below (a ceiling) and above (a floor). A part lower than
    ``min_room_height_m`` is no storey of its own: it joins the part below it (the lowest
    part joins the one above). Each part's floor and ceiling are then found by :func:`find_floor_ceiling`. The
    thresholds are fractions, so a regular subsample gives the same storeys.
    """
    s = settings or SegmentationSettings()
    zs, step, keep = _z_histogram_sample(z, s)
    xs = None if xy is None else np.asarray(xy)[::step][keep]
    lo, b = float(zs.min()), s.storey_bin_m
    counts = np.bincount(((zs - lo) / b).astype(np.int64)).astype(np.float64)
    median = float(np.median(counts))
    empty = np.convolve(counts, np.ones(3) / 3, mode="same") < s.slab_gap_fraction * median
    # bins of a horizontal surface: one bin, or two neighbours together (range noise and the
    # stations' registration error spread a floor over a bin edge, half on either side)
    level = counts >= s.slab_level_factor * median
    pair = counts[:-1] + counts[1:] >= s.slab_level_factor * median
    level[:-1] |= pair
    level[1:] |= pair
    near = max(1, int(round(s.slab_level_reach_m / b)))
    # runs of (almost) empty bins, (first, end) bin numbers, with a ceiling just below and a
    # floor just above (a stairwell's walls go on through the slab, a sparse band in a wall does not)
    edges = np.diff(np.concatenate(([0], empty.astype(np.int8), [0])))
    cuts = [(a, e) for a, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True)
            if (e - a) * b >= s.min_slab_m and 0 < a and e < len(counts)
            and level[max(0, a - near): a].any() and level[e: e + near].any()]
    # parts between the slabs: [start, end) bins, merged while one is too low for a storey
    parts = [[0, len(counts)]]
    for a, e in cuts:
        parts[-1][1] = a
        parts.append([e, len(counts)])
    while len(parts) > 1:
        heights = [(p1 - p0) * b for p0, p1 in parts]
        k = int(np.argmin(heights))
        if heights[k] >= s.min_room_height_m:
            break
        # a part too low for a storey is the top of the one below (the ceiling of a higher
        # room over a void above its neighbours' lower ceilings), the lowest one joins the next
        j = max(0, k - 1)
        parts[j] = [parts[j][0], parts[j + 1][1]]
        del parts[j + 1]
    out = []
    for p0, p1 in parts:
        z_a, z_b = lo + p0 * b, lo + p1 * b
        sel = (zs >= z_a) & (zs < z_b)
        out.append(find_floor_ceiling(zs[sel], s, None if xs is None else xs[sel]))
    return out


def find_floor_ceiling(z: np.ndarray, settings: SegmentationSettings | None = None,
                       xy: np.ndarray | None = None) -> tuple[float, float]:
    """(floor, ceiling) levels from the maxima of the Z histogram (paper, section 3.1).

    The levels are the histogram's peaks that stand out from their surroundings by at least
    ``min_level_fraction`` of the largest one. The floor is the lowest level and the ceiling
    the highest at least ``min_room_height_m`` above it, not the two largest: a table or
    cabinet top near the stations can hold more points than the floor, whose part under each
    station is outside the scanner's field of view. With ``xy`` (the points' plan
    coordinates, aligned with ``z``) a level must also cover at least ``min_level_area``
    of the plan area of the largest level; without a ceiling that wide (a scan without
    ceiling points, where door and window heads form small levels) the ceiling is the top
    of the cloud. A smaller level (at least ``min_ceiling_area_m2``) above the wide ceiling is
    the ceiling of a higher room: the highest such is the ceiling. Each level is refined as the median Z within 1.5 bins of its peak. Works
    in whatever frame ``z`` is given. Raises NoWallsError without a floor and a ceiling.
    """
    s = settings or SegmentationSettings()
    zs, step, keep = _z_histogram_sample(z, s)
    lo, b = float(zs.min()), s.z_bin_m
    counts = np.bincount(((zs - lo) / b).astype(np.int64)).astype(np.float64)
    smooth = np.convolve(counts, np.ones(3), mode="same")
    padded = np.concatenate(([0.0], smooth, [0.0]))  # a level in the first or last bin is a peak too
    from scipy.signal import find_peaks  # here: scipy.signal imports scipy.stats (0.4 s), which the
    # wall workers, importing this module with the pipeline, never need

    peaks, props = find_peaks(padded, prominence=s.min_level_fraction * float(smooth.max()))
    peaks = peaks - 1
    small = np.zeros(0, np.int64)
    if len(peaks) and xy is not None:
        areas = _level_areas(zs, np.asarray(xy)[::step][keep], lo + (peaks + 0.5) * b, b, s)
        wide = areas >= s.min_level_area * areas.max()
        small = peaks[~wide & (areas >= s.min_ceiling_area_m2)]
        peaks = peaks[wide]
    if len(peaks) == 0:
        raise NoWallsError("no walls found: the Z histogram has no level")

    def refined(p: int) -> float:
        return float(np.median(zs[np.abs(zs - (lo + (p + 0.5) * b)) <= 1.5 * b]))

    levels = [refined(p) for p in sorted(peaks)]
    floor = levels[0]
    above = [v for v in levels if v >= floor + s.min_room_height_m]
    if above:
        # a room higher than the others: its smaller ceiling above the wide ones is the top
        higher = [refined(p) for p in small if lo + (p + 0.5) * b > above[-1] + 2 * b]
        return floor, max([above[-1], *higher])
    top = float(np.quantile(zs, s.top_quantile))
    if xy is None or top < floor + s.min_room_height_m:
        raise NoWallsError("no walls found: the Z histogram has no floor and ceiling pair "
                           f"(one level at z = {floor:.2f} m only)")
    return floor, top


def _level_areas(z: np.ndarray, xy: np.ndarray, levels: np.ndarray, b: float, s: SegmentationSettings
                 ) -> np.ndarray:
    """Plan area (m^2) over which each level is a horizontal surface.

    A plan cell counts for a level when the slab of 3 bins around it holds at least
    ``level_dominance`` times the points of each equal slab just above and below: a floor,
    ceiling or table top does, a wall crossing the level (same points in every slab) does not.
    """
    cell = s.level_cell_m
    ij = np.floor(np.asarray(xy, np.float64) / cell).astype(np.int64)
    ij -= ij.min(axis=0)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    n = int(key.max()) + 1
    out = []
    for zc in levels:
        slab = [np.bincount(key[(z >= zc + k * b - 1.5 * b) & (z <= zc + k * b + 1.5 * b)], minlength=n)
                for k in (0, -4, 4)]
        flat = (slab[0] > 0) & (slab[0] >= s.level_dominance * np.maximum(slab[1], slab[2]))
        out.append(float(flat.sum()) * cell * cell)
    return np.asarray(out)


def fit_line_2d(xy: np.ndarray, tolerances: tuple[float, ...] = ()) -> tuple[np.ndarray, float]:
    """Total least-squares line through 2-D points: (unit normal n, offset s) with n . p = s.

    With ``tolerances`` the fit is repeated on the points within each tolerance of the
    previous line (trimmed least squares; objects on a wall do not pull its plane).
    """
    pts = np.asarray(xy, np.float64)
    n, s = _pca_line(pts)
    for tol in tolerances:
        keep = np.abs(pts @ n - s) <= tol
        if keep.sum() < 3:
            break
        n2, s2 = _pca_line(pts[keep])
        if n2 @ n < 0:
            n2, s2 = -n2, -s2
        n, s = n2, s2
    return n, s


# --------------------------------------------------------------------------- planes


def _pca_line(pts: np.ndarray) -> tuple[np.ndarray, float]:
    m = pts.mean(axis=0)
    q = pts - m
    w, v = np.linalg.eigh(q.T @ q)
    n = v[:, 0]
    return n, float(n @ m)


def _planar_cells(p: np.ndarray, s: SegmentationSettings) -> dict[str, np.ndarray]:
    """Centroid, unit normal and point count of every planar, vertical voxel of ``p``."""
    empty = {"c": np.zeros((0, 3)), "n": np.zeros((0, 3)), "count": np.zeros(0)}
    if len(p) == 0:
        return empty
    cell = s.fit_cell_m
    ijk = np.floor(p * np.float32(1.0 / cell)).astype(np.int32)
    q = p.astype(np.float32) - ijk * np.float32(cell)  # local coordinates in the voxel, 0..cell
    # per column: the values of ijk.min(axis=0) / .max(axis=0), without their slow reduction across 3 columns
    base = np.array([ijk[:, a].min() for a in range(3)], ijk.dtype)
    dims = (np.array([ijk[:, a].max() for a in range(3)], ijk.dtype) - base + 1).astype(np.int64)
    key = (ijk[:, 0] - base[0]).astype(np.int64) * (dims[1] * dims[2])
    key += (ijk[:, 1] - base[1]).astype(np.int64) * dims[2]
    key += ijk[:, 2] - base[2]
    if int(np.prod(dims)) <= _DENSE_VOXELS:  # linear-time grouping
        full = np.bincount(key)
        occupied = np.flatnonzero(full)
        lut = np.zeros(len(full), np.int64)
        lut[occupied] = np.arange(len(occupied))
        inv, cnt = lut[key], full[occupied]
        del full, lut
    else:
        _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    del key
    k = len(cnt)
    mean = np.stack([np.bincount(inv, q[:, a], k) for a in range(3)], axis=1) / cnt[:, None]
    cov = np.empty((k, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = cov[:, b, a] = np.bincount(inv, q[:, a] * q[:, b], k) / cnt - mean[:, a] * mean[:, b]
    first = np.zeros(k, np.int64)
    first[inv[::-1]] = np.arange(len(inv))[::-1]
    centre = mean + ijk[first].astype(np.float64) * cell
    ok = cnt >= s.min_cell_points
    w, v = np.linalg.eigh(cov[ok])
    normal = v[:, :, 0]
    planar = (w[:, 0] <= s.cell_planarity * w[:, 1]) & (w[:, 1] >= (0.1 * cell) ** 2)
    vertical = np.abs(normal[:, 2]) <= s.max_normal_z
    sel = planar & vertical
    return {"c": centre[ok][sel], "n": normal[sel], "count": cnt[ok][sel].astype(np.float64)}


def _min_cells(height: float, s: SegmentationSettings) -> float:
    """Voxels of the smallest wall we accept (a third of its area, for holes and sparse scans)."""
    return max(6.0, (s.min_wall_length_m / s.fit_cell_m) * (s.min_wall_height_fraction * height / s.fit_cell_m) / 3)


def _wall_planes(cells: dict[str, np.ndarray], floor: float, height: float, s: SegmentationSettings) -> list[_Segment]:
    """Vertical planes: dominant normal directions, then offset maxima, each refitted and kept once,
    then runs along u."""
    c, nrm = cells["c"], cells["n"]
    if len(c) == 0:
        return []
    min_cells = _min_cells(height, s)
    theta = np.arctan2(nrm[:, 1], nrm[:, 0]) % np.pi
    nb = int(round(180.0 / s.angle_bin_deg))
    tol = math.radians(s.angle_tolerance_deg)
    free = np.ones(len(c), bool)
    planes: list[tuple[np.ndarray, float]] = []
    while free.any():
        h = np.bincount((theta[free] / np.pi * nb).astype(np.int64) % nb, minlength=nb).astype(np.float64)
        win = max(1, int(round(s.angle_tolerance_deg / s.angle_bin_deg / 2)))
        hs = sum(np.roll(h, k) for k in range(-win, win + 1))
        p = int(np.argmax(hs))
        if hs[p] < min_cells:
            break
        th = (p + 0.5) * np.pi / nb
        for _ in range(2):
            diff = (theta - th + np.pi / 2) % np.pi - np.pi / 2
            mem = free & (np.abs(diff) < tol)
            if not mem.any():
                break
            th = th + float(np.mean(diff[mem]))
        diff = (theta - th + np.pi / 2) % np.pi - np.pi / 2
        mem = free & (np.abs(diff) < tol)
        free &= ~mem
        if mem.sum() < min_cells:
            continue
        planes += _offset_planes(c[mem], th, min_cells, s)
    if not planes:
        return []
    # refine each plane on its cells, then give every vertical cell to its nearest plane
    refined = []
    for n0, s0 in planes:
        d = c[:, :2] @ n0 - s0
        near = (np.abs(d) <= s.wall_plane_tolerance_m) & (np.abs(nrm[:, :2] @ n0) >= math.cos(3 * tol))
        if near.sum() >= 3:
            n1, s1 = fit_line_2d(c[near, :2], (s.wall_plane_tolerance_m, s.wall_plane_tolerance_m / 2))
            if n1 @ n0 < 0:
                n1, s1 = -n1, -s1
            refined.append((n1, s1, c[near, :2].mean(axis=0)))
    refined = _distinct_planes(refined, math.cos(tol), s.wall_plane_tolerance_m)
    if not refined:
        return []
    ns = np.array([p[0] for p in refined])
    ss = np.array([p[1] for p in refined])
    best, ok = _nearest_planes(c[:, :2], nrm[:, :2], ns, ss, min_cos=math.cos(3 * tol), tolerance=s.wall_plane_tolerance_m)
    segs: list[_Segment] = []
    for k in range(len(refined)):
        mine = c[ok & (best == k)]
        if len(mine) < min_cells:
            continue
        seg = _Segment(ns[k], float(ss[k]), mine)
        segs += _runs(seg, s)
    return [g for g in segs if _big_enough(g, floor, height, s)]



def _distinct_planes(planes: list[tuple[np.ndarray, float, np.ndarray]], min_cos: float, tolerance: float
                     ) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """The refined planes without repeats: a plane that lies within ``tolerance`` of an earlier
    (stronger) one, with its normal within the angle tolerance, over the cells it was fitted on
    (``planes``: normal, offset and the centroid of those cells), is the same wall found again.

    A wall finds itself again when things standing a few centimetres in front of it (boards,
    posters, trunking, the backs of cabinets and shelves) make a second maximum of the offset
    histogram beside its own, and the trimmed refit pulls that maximum back onto the wall.
    Kept twice, the wall's cells would be shared between two identical planes, and each of the
    two walls would get every other part of its points.
    """
    kept: list[tuple[np.ndarray, float, np.ndarray]] = []
    for n, s, centre in planes:
        if not any(abs(float(n @ m)) >= min_cos and abs(float(centre @ m) - t) <= tolerance for m, t, _ in kept):
            kept.append((n, s, centre))
    return kept


def _nearest_planes(xy: np.ndarray, nxy: np.ndarray, ns: np.ndarray, ss: np.ndarray, *, min_cos: float,
                    tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """For each cell (plan centroid ``xy``, normal ``nxy``) the nearest plane ``ns . p = ss`` among
    those whose normal is aligned with its own (``|cos| >= min_cos``): (plane index, within
    ``tolerance``). Blockwise over the cells: the (cells, planes) distances of a building with
    many walls are never held at once (memory bounded by ``_PLANE_BLOCK`` cells)."""
    best = np.zeros(len(xy), np.int64)
    ok = np.zeros(len(xy), bool)
    for a in range(0, len(xy), _PLANE_BLOCK):
        dist = np.abs(xy[a: a + _PLANE_BLOCK] @ ns.T - ss[None, :])  # (block, planes)
        dist[np.abs(nxy[a: a + _PLANE_BLOCK] @ ns.T) < min_cos] = np.inf
        b = np.argmin(dist, axis=1)
        best[a: a + len(b)] = b
        ok[a: a + len(b)] = dist[np.arange(len(b)), b] <= tolerance
    return best, ok

def _offset_planes(c: np.ndarray, th: float, min_cells: float, s: SegmentationSettings
                   ) -> list[tuple[np.ndarray, float]]:
    """Maxima of the offset histogram of the cells of one direction: (normal, offset) each."""
    n0 = np.array([math.cos(th), math.sin(th)])
    off = c[:, :2] @ n0
    lo, b = float(off.min()), s.offset_bin_m
    idx = ((off - lo) / b).astype(np.int64)
    h = np.bincount(idx).astype(np.float64)
    win = max(1, int(round(s.wall_plane_tolerance_m / 2 / b)))
    hs = np.convolve(h, np.ones(2 * win + 1), mode="same")
    out = []
    while True:
        p = int(np.argmax(hs))
        if hs[p] < min_cells:
            break
        centre = float(np.median(off[np.abs(idx - p) <= win]))  # the window holds hs[p] > 0 cells
        out.append((n0, float(np.median(off[np.abs(off - centre) <= win * b]))))
        hs[max(0, p - 2 * win): p + 2 * win + 1] = 0.0
    return out


def _runs(seg: _Segment, s: SegmentationSettings) -> list[_Segment]:
    """Split a plane where its cells stop for more than ``wall_gap_m`` along u."""
    u = seg.cells[:, :2] @ seg.t
    order = np.argsort(u)
    cuts = np.flatnonzero(np.diff(u[order]) > s.wall_gap_m) + 1
    out = []
    for part in np.split(order, cuts):
        g = _Segment(seg.n.copy(), seg.s, seg.cells[part])
        g.extents(s.fit_cell_m / 2)
        out.append(g)
    return out


def _big_enough(g: _Segment, floor: float, height: float, s: SegmentationSettings) -> bool:
    if len(g.cells) == 0 or g.u1 - g.u0 < s.min_wall_length_m:
        return False
    layers = np.unique(np.floor((g.cells[:, 2] - floor) / s.fit_cell_m))
    return len(layers) * s.fit_cell_m >= s.min_wall_height_fraction * height


def _within_run(g: _Segment, h: _Segment, s: SegmentationSettings) -> bool:
    """Whether all of ``g`` lies within ``h``'s length (its run along ``h.t``, one voxel slack)."""
    ug = g.cells[:, :2] @ h.t
    return bool(ug.min() >= h.u0 - s.fit_cell_m and ug.max() <= h.u1 + s.fit_cell_m)


def _drop_hidden_by(segs: list[_Segment], hides: Callable[[_Segment, _Segment, bool], bool],
                    s: SegmentationSettings) -> list[_Segment]:
    """The planes ``g`` for which no other plane ``h`` ``hides(g, h, higher)``; ``higher``: ``h``
    reaches higher than ``g`` by more than two voxels (a wall going on above a door or a cabinet)."""
    tops = [float(g.cells[:, 2].max()) for g in segs]
    return [g for g, top_g in zip(segs, tops, strict=True)
            if not any(hides(g, h, top_h > top_g + 2 * s.fit_cell_m)
                       for h, top_h in zip(segs, tops, strict=True) if h is not g)]


def _drop_recessed(segs: list[_Segment], s: SegmentationSettings) -> list[_Segment]:
    """Drop planes set back in an opening of a wall: a door leaf a few cm behind the wall face.

    A plane is such a recess when another plane of the same facing stands in front of it by
    at most ``recess_max_m``, spans its whole length, and reaches higher than it by more
    than two voxels (the wall goes on above the door; the leaf stops at the door head).
    """
    def recessed_behind(g: _Segment, h: _Segment, higher: bool) -> bool:
        if float(g.n @ h.n) < math.cos(math.radians(s.angle_tolerance_deg)):
            return False
        ahead = h.s - float(g.cells[:, :2].mean(axis=0) @ h.n)  # how far h's face is in front of g
        return 0.5 * s.wall_plane_tolerance_m < ahead <= s.recess_max_m and _within_run(g, h, s) and higher

    return _drop_hidden_by(segs, recessed_behind, s)


def _drop_standing_in_front(segs: list[_Segment], s: SegmentationSettings) -> list[_Segment]:
    """Drop planes that stand in front of a wall: furniture (fronts and sides) and door casings.

    A plane ``g`` is such a thing when a wall ``h`` that reaches higher than ``g`` by more
    than two voxels (the wall goes on up to its ceiling above a tall cabinet, a shelf or a
    door casing) has all of ``g`` on its room side, at most ``furniture_depth_m`` in front
    of its face (or less than half ``wall_plane_tolerance_m`` behind it: a door casing
    1.5 cm proud is the wall found a second time) and within its length. ``g`` may be
    parallel to ``h`` (a cabinet front, a casing) or not (a cabinet's side, which would
    otherwise split the wall behind it at a T-junction). ``g``'s own facing is not used: a
    cabinet front has ceiling points on both sides (above the cabinet), so it may face
    either way. Run on the unsplit planes, right after :func:`_orient`, so that a wall's
    extent is its whole run. The points of such a plane that fall within a wall's slab then
    go to that wall (the casing, and the objects on the wall around it, are the wall's); the
    rest belong to no wall.
    """
    def standing_in_front(g: _Segment, h: _Segment, higher: bool) -> bool:
        if not higher:
            return False
        ahead = np.percentile(g.cells[:, :2] @ h.n - h.s, (2, 98))  # how far g stands in front of h's face
        return bool(ahead[0] > -0.5 * s.wall_plane_tolerance_m and ahead[1] <= s.furniture_depth_m) \
            and _within_run(g, h, s)

    return _drop_hidden_by(segs, standing_in_front, s)


# --------------------------------------------------------------------------- room side


def _orient(segs: list[_Segment], slab_xy: np.ndarray, s: SegmentationSettings) -> list[_Segment]:
    """Turn each normal towards the side where floor / ceiling points continue (the room).

    A plane with no floor or ceiling in front of it over at least ``min_room_evidence`` of
    its length (something seen through a door or a window, outside the scanned rooms) is
    dropped; when the scan has no floor / ceiling points at all, walls face its middle.
    """
    kept = []
    if len(slab_xy) == 0:
        centre = np.mean([g.cells[:, :2].mean(axis=0) for g in segs], axis=0)
        occ = None
    else:
        cell = s.xy_cell_m
        # one column at a time (no (n, 2) temporaries); the same cells
        lo = np.array([float(slab_xy[:, 0].min()), float(slab_xy[:, 1].min())]) - cell
        ix = ((slab_xy[:, 0] - lo[0]) / cell).astype(np.int64)
        iy = ((slab_xy[:, 1] - lo[1]) / cell).astype(np.int64)
        occ = np.zeros((int(ix.max()) + 2, int(iy.max()) + 2), bool)
        occ[ix, iy] = True
        del ix, iy
    probes = np.linspace(s.facing_probe_m[0], s.facing_probe_m[1], 4)
    for g in segs:
        if occ is None:  # nothing but walls: face the middle of the scan
            if float(centre @ g.n - g.s) < 0:
                g.flip()
            kept.append(g)
            continue
        u = np.arange(g.u0, g.u1, s.xy_cell_m)
        seen = []
        for sign in (1.0, -1.0):
            hit = np.zeros(len(u), bool)
            for d in probes:
                pts = (g.s + sign * d) * g.n[None, :] + u[:, None] * g.t[None, :]
                ij = np.floor((pts - lo) / s.xy_cell_m).astype(np.int64)
                inside = (ij >= 0).all(axis=1) & (ij[:, 0] < occ.shape[0]) & (ij[:, 1] < occ.shape[1])
                hit[inside] |= occ[ij[inside, 0], ij[inside, 1]]
            seen.append(float(hit.mean()) if len(u) else 0.0)
        if max(seen) < s.min_room_evidence:
            continue
        if seen[1] > seen[0]:
            g.flip()
        kept.append(g)
    return kept


def _split_at_junctions(segs: list[_Segment], s: SegmentationSettings) -> list[_Segment]:
    """Split a wall where another wall ends against it from the room side (T-junction).

    The pieces end exactly on the other wall's plane (the voxels next to a junction are
    not planar, so the voxel extents stop short of it).
    """
    tol = s.junction_tolerance_m
    reach = tol + s.fit_cell_m  # voxel extents stop short of a junction
    out = []
    for i, g in enumerate(segs):
        cuts = []
        for j, h in enumerate(segs):
            if i == j or abs(float(g.n @ h.n)) > math.cos(math.radians(30)):
                continue
            ends = [h.point(h.u0), h.point(h.u1)]
            for e, other in ((ends[0], ends[1]), (ends[1], ends[0])):
                d_end, d_other = float(e @ g.n - g.s), float(other @ g.n - g.s)
                if abs(d_end) <= reach and d_other > reach:
                    u = _crossing(g, h)
                    if g.u0 + tol < u < g.u1 - tol:
                        cuts.append(u)
        if not cuts:
            out.append(g)
            continue
        cuts = np.sort(cuts)
        u = g.cells[:, :2] @ g.t
        piece = np.searchsorted(cuts, u)
        for k in np.unique(piece):
            h = _Segment(g.n.copy(), g.s, g.cells[piece == k], e0=g.e0, e1=g.e1)
            h.extents(s.fit_cell_m / 2)
            if k > 0:
                h.u0 = float(cuts[k - 1])
                h.e0 = h.point(h.u0)
            if k < len(cuts):
                h.u1 = float(cuts[k])
                h.e1 = h.point(h.u1)
            out.append(h)
    return out


def _snap_corners(segs: list[_Segment], s: SegmentationSettings) -> None:
    """Move a free wall end onto the plane of a wall of the same room that it meets there.

    Voxel extents stop short of a corner (the corner voxels are not planar, sparse scans
    leave some voxels without a normal); the end is set to the corner itself.
    """
    reach = s.junction_tolerance_m + s.fit_cell_m
    for i, g in enumerate(segs):
        for end in (0, 1):
            if (g.e0, g.e1)[end] is not None:
                continue
            u_end = (g.u0, g.u1)[end]
            best = None
            for j, h in enumerate(segs):
                if i == j or abs(float(g.n @ h.n)) > math.cos(math.radians(30)):
                    continue
                u = _crossing(g, h)
                x = g.point(u)
                uh = float(x @ h.t)
                if abs(u - u_end) > reach or not h.u0 - reach <= uh <= h.u1 + reach:
                    continue
                g_front = float(g.point(0.5 * (g.u0 + g.u1)) @ h.n - h.s) > 0
                h_front = float(h.point(0.5 * (h.u0 + h.u1)) @ g.n - g.s) > 0
                near_h_end = min(abs(uh - h.u0), abs(uh - h.u1)) <= reach
                # inside corner or T (g stands in h's room), or outside corner (both ends meet)
                if g_front or (not h_front and near_h_end):
                    if best is None or abs(u - u_end) < abs(best - u_end):
                        best = u
            if best is not None:
                if end == 0 and best < g.u1:
                    g.u0, g.e0 = best, g.point(best)
                elif end == 1 and best > g.u0:
                    g.u1, g.e1 = best, g.point(best)


def _crossing(g: _Segment, h: _Segment) -> float:
    """u along ``g`` where the (non-parallel) plane of ``h`` crosses it."""
    # points g.point(u) with h.n . p = h.s:  (g.s g.n + u g.t) . h.n = h.s
    return float((h.s - g.s * (g.n @ h.n)) / (g.t @ h.n))


# --------------------------------------------------------------------------- points


def _margins(g: _Segment, s: SegmentationSettings) -> tuple[float, float]:
    """How far beyond each end points are looked at: little at a junction, more at a free end."""
    fixed = s.wall_plane_tolerance_m
    return (s.extent_margin_m if g.e0 is None else fixed, s.extent_margin_m if g.e1 is None else fixed)


def _region_cells(g: _Segment, s: SegmentationSettings, lo: np.ndarray, nx: int, ny: int) -> np.ndarray:
    """Bucket numbers (y * nx + x) touched by the wall's slab."""
    step = s.assign_cell_m / 2
    m0, m1 = _margins(g, s)
    us = np.arange(g.u0 - m0, g.u1 + m1 + step, step)
    ds = np.arange(-s.behind_depth_m, s.object_depth_m + step, step)
    uu, dd = np.meshgrid(us, ds)
    pts = (g.s + dd.ravel())[:, None] * g.n[None, :] + uu.ravel()[:, None] * g.t[None, :]
    ij = np.floor((pts - lo) / s.assign_cell_m).astype(np.int64)
    ij[:, 0] = np.clip(ij[:, 0], 0, nx - 1)
    ij[:, 1] = np.clip(ij[:, 1], 0, ny - 1)
    return np.unique(ij[:, 1] * nx + ij[:, 0])


def _band_index(xyz: np.ndarray, z_lo: float, z_hi: float, box: DenseBox | None = None,
                chunk: int = 1 << 23) -> np.ndarray:
    """Indices of the points with z_lo < z < z_hi inside ``box`` (int32 when they fit), chunk by chunk."""
    dtype = np.int32 if len(xyz) < 2**31 - 1 else np.int64
    parts = []
    for a in range(0, len(xyz), chunk):
        zc = xyz[a: a + chunk, 2]
        ok = (zc > z_lo) & (zc < z_hi)
        if box is not None:
            ok &= inside_box(xyz[a: a + chunk], box)
        parts.append((np.flatnonzero(ok) + a).astype(dtype))
    return np.concatenate(parts) if parts else np.zeros(0, dtype)


def _bucket(a: np.ndarray, lo: float, cell: float, n: int) -> np.ndarray:
    """int32 bucket numbers 0..n-1 of float32 coordinates."""
    t = a - np.float32(lo)
    t *= np.float32(1.0 / cell)
    out = t.astype(np.int32)
    del t
    np.minimum(out, n - 1, out=out)
    return out


def _assign_points(xyz: np.ndarray, segs: list[_Segment], z_lo: float, z_hi: float,
                   *, s: SegmentationSettings, box: DenseBox | None = None) -> list[np.ndarray]:
    """Indices of the points of each wall: in its slab and nearer to its plane than to any other's.

    Every point is decided on its own, so a large cloud is cut into consecutive parts that
    threads assign side by side (numpy releases the GIL); each wall's indices stay sorted.
    """
    n = len(xyz)
    parts = min(_ASSIGN_THREADS, os.cpu_count() or 1) if n >= _THREAD_MIN_POINTS else 1
    if parts <= 1:
        return _assign_part(xyz, segs, z_lo, z_hi, s=s, box=box)
    cuts = [n * k // parts for k in range(parts + 1)]
    with ThreadPoolExecutor(max_workers=parts) as pool:
        done = list(pool.map(lambda k: _assign_part(xyz[cuts[k]:cuts[k + 1]], segs, z_lo, z_hi, s=s, box=box),
                             range(parts)))
    return [np.concatenate([idx[w] + cuts[k] for k, idx in enumerate(done)]) for w in range(len(segs))]


def _assign_part(xyz: np.ndarray, segs: list[_Segment], z_lo: float, z_hi: float,
                 *, s: SegmentationSettings, box: DenseBox | None = None) -> list[np.ndarray]:
    """:func:`_assign_points` on one part of the cloud (indices relative to the part)."""
    band = _band_index(xyz, z_lo, z_hi, box)
    if len(band) == 0:
        return [np.zeros(0, np.int64) for _ in segs]
    x = xyz[band, 0]
    y = xyz[band, 1]
    cell = s.assign_cell_m
    lo = np.array([float(x.min()), float(y.min())])
    nx = int((float(x.max()) - lo[0]) / cell) + 1
    ny = int((float(y.max()) - lo[1]) / cell) + 1
    key = _bucket(x, lo[0], cell, nx)
    key += _bucket(y, lo[1], cell, ny) * np.int32(nx)  # nx * ny buckets: far below 2**31
    regions = [_region_cells(g, s, lo, nx, ny) for g in segs]
    touched = np.unique(np.concatenate(regions))
    lut = np.zeros(nx * ny, np.int32)
    lut[touched] = np.arange(1, len(touched) + 1, dtype=np.int32)
    bucket = lut[key]
    del key
    if len(touched) < 65535:
        bucket = bucket.astype(np.uint16)  # radix sort
    order = np.argsort(bucket, kind="stable")
    if len(band) < 2**31 - 1:
        order = order.astype(np.int32)
    starts = np.concatenate([[0], np.cumsum(np.bincount(bucket, minlength=len(touched) + 1))])
    del bucket
    best = np.full(len(band), np.inf, np.float32)
    owner = np.full(len(band), -1, np.int16 if len(segs) < 32767 else np.int32)
    for w, (g, cells) in enumerate(zip(segs, regions, strict=True)):
        ids = lut[cells]
        every = np.concatenate([order[starts[b]: starts[b + 1]] for b in ids])
        m0, m1 = _margins(g, s)
        for a in range(0, len(every), _CHUNK):  # bounded temporaries on long walls
            cand = every[a: a + _CHUNK]
            px, py = x[cand], y[cand]
            d = px * np.float32(g.n[0]) + py * np.float32(g.n[1]) - np.float32(g.s)
            u = px * np.float32(g.t[0]) + py * np.float32(g.t[1])
            del px, py
            ok = (d >= -s.behind_depth_m) & (d <= s.object_depth_m) & (u >= g.u0 - m0) & (u <= g.u1 + m1)
            cand = cand[ok]
            ad = np.abs(d[ok])
            better = ad < best[cand]
            best[cand[better]] = ad[better]
            owner[cand[better]] = w
    del best, order, x, y
    grouped = np.argsort(owner, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(np.bincount(owner.astype(np.int64) + 1, minlength=len(segs) + 1))])
    return [band[grouped[bounds[w + 1]: bounds[w + 2]]].astype(np.int64) for w in range(len(segs))]


def _final_frame(xyz: np.ndarray, idx: np.ndarray, g: _Segment, floor: float, ceiling: float,
                 *, origin: np.ndarray, s: SegmentationSettings) -> tuple[WallFrame, np.ndarray] | None:
    """Trimmed least-squares plane on the wall's own points, extents and contract-4 frame.

    The wall's height is its own: the top of the points on its plane (its room's ceiling,
    which may be lower than the storey's highest one), or the storey's ceiling when the
    points reach it. Points at and above a lower top (its room's ceiling) leave the wall.
    Returns the frame and the wall's point indices.
    """
    if len(idx) < 10:
        return None
    sub = idx[:: max(1, math.ceil(len(idx) / s.refit_max_points))]
    xy = xyz[sub, :2].astype(np.float64)
    tol = s.wall_plane_tolerance_m
    near = np.abs(xy @ g.n - g.s) <= tol
    if near.sum() >= 10:
        n, off = fit_line_2d(xy[near], (tol, tol / 2, tol / 4))
        if n @ g.n < 0:
            n, off = -n, -off
    else:
        n, off = g.n, g.s
    t = np.array([-n[1], n[0]])
    x, y = xyz[idx, 0], xyz[idx, 1]
    d = x * np.float32(n[0]) + y * np.float32(n[1]) - np.float32(off)
    on = np.abs(d) <= tol
    if on.sum() < 10:
        return None
    u = x[on] * np.float32(t[0]) + y[on] * np.float32(t[1])
    f0, f1 = _free_extent(u, float(g.point(0.5 * (g.u0 + g.u1)) @ t), s.extent_gap_m)
    u0 = f0 if g.e0 is None else float(g.e0 @ t)
    u1 = f1 if g.e1 is None else float(g.e1 @ t)
    if u1 - u0 <= 0:
        return None
    top = float(np.quantile(xyz[idx[on], 2], s.wall_top_quantile))
    if top >= ceiling - s.slab_tolerance_m - s.slab_margin_m:
        top = ceiling
    else:  # a lower room ceiling: it is the wall's top, its points are no wall points
        idx = idx[xyz[idx, 2] < top - s.slab_tolerance_m]
    corner = np.array([*(off * n + u0 * t), floor]) + origin
    frame = WallFrame(origin=corner, axis_u=np.array([t[0], t[1], 0.0]), axis_v=np.array([0.0, 0.0, 1.0]),
                      normal=np.array([n[0], n[1], 0.0]), width_m=u1 - u0, height_m=top - floor)
    return frame, idx


def assign_points_to_walls(xyz: np.ndarray, origin: np.ndarray, walls: list[Wall],
                           settings: SegmentationSettings | None = None) -> list[np.ndarray]:
    """Indices into ``xyz`` of the points of each wall, from the walls' frames alone.

    A pure function of one chunk of points (``xyz`` float32 relative to ``origin``), so
    a cloud too large for memory is assigned chunk by chunk (add the chunk's offset to the
    indices). A point belongs to a wall when it lies over the wall's frame (``u`` within
    ``wall_plane_tolerance_m`` of ``0..width``, ``slab_tolerance_m`` above its floor and
    below its top) between ``behind_depth_m`` behind and ``object_depth_m`` in front of the
    plane; of several such walls the one whose plane is nearest gets it. Points are
    bucketed on an XY grid (``assign_cell_m``) spanning the walls, not the points, so that
    each wall only looks at the buckets its slab covers and stray points cost nothing.
    """
    s = settings or SegmentationSettings()
    n = len(xyz)
    if n == 0 or not walls:
        return [np.zeros(0, np.int64) for _ in walls]
    tol, sl, cell = s.wall_plane_tolerance_m, s.slab_tolerance_m, s.assign_cell_m
    org = np.asarray(origin, np.float64)
    corners = []
    for wall in walls:
        f = wall.frame
        for u in (-tol, f.width_m + tol):
            for d in (-s.behind_depth_m, s.object_depth_m):
                corners.append((f.origin - org + u * f.axis_u + d * f.normal)[:2])
    lo = np.min(corners, axis=0) - cell
    hi = np.max(corners, axis=0) + cell
    nx, ny = int((hi[0] - lo[0]) / cell) + 1, int((hi[1] - lo[1]) / cell) + 1
    key = np.full(n, nx * ny, np.int64)  # nx * ny: outside every wall's slab
    for a in range(0, n, _CHUNK):
        c = xyz[a: a + _CHUNK]
        fx = (c[:, 0] - np.float32(lo[0])) / np.float32(cell)
        fy = (c[:, 1] - np.float32(lo[1])) / np.float32(cell)
        ok = (fx >= 0) & (fx < nx) & (fy >= 0) & (fy < ny)
        key[a: a + _CHUNK][ok] = fy[ok].astype(np.int64) * nx + fx[ok].astype(np.int64)
    order = np.argsort(key, kind="stable")
    starts = np.concatenate([[0], np.cumsum(np.bincount(key, minlength=nx * ny + 1))])
    del key
    best = np.full(n, np.inf, np.float32)
    owner = np.full(n, -1, np.int32)
    step = cell / 2
    for w, wall in enumerate(walls):
        f = wall.frame
        o = f.origin - org
        us = np.arange(-tol, f.width_m + tol + step, step)
        ds = np.arange(-s.behind_depth_m, s.object_depth_m + step, step)
        uu, dd = np.meshgrid(us, ds)
        pts = o[:2] + uu.ravel()[:, None] * f.axis_u[:2] + dd.ravel()[:, None] * f.normal[:2]
        ij = np.clip(np.floor((pts - lo) / cell).astype(np.int64), 0, [nx - 1, ny - 1])
        buckets = np.unique(ij[:, 1] * nx + ij[:, 0])
        cand = np.concatenate([order[starts[b]: starts[b + 1]] for b in buckets])
        if len(cand) == 0:
            continue
        c = xyz[cand] - o.astype(np.float32)
        u = c[:, 0] * np.float32(f.axis_u[0]) + c[:, 1] * np.float32(f.axis_u[1])
        d = c[:, 0] * np.float32(f.normal[0]) + c[:, 1] * np.float32(f.normal[1])
        v = c[:, 2]
        ad = np.abs(d)
        ok = ((d >= -s.behind_depth_m) & (d <= s.object_depth_m) & (u >= -tol) & (u <= f.width_m + tol)
              & (v > sl) & (v < f.height_m - sl) & (ad < best[cand]))
        best[cand[ok]] = ad[ok]
        owner[cand[ok]] = w
    grouped = np.argsort(owner, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(np.bincount(owner.astype(np.int64) + 1, minlength=len(walls) + 1))])
    return [grouped[bounds[w + 1]: bounds[w + 2]].astype(np.int64) for w in range(len(walls))]


def _free_extent(u: np.ndarray, centre: float, gap: float) -> tuple[float, float]:
    """Ends of the run of points along u around ``centre`` with no empty stretch above ``gap``.

    Stray points (beyond a gap) do not stretch the wall.
    """
    bin_m = min(0.01, gap / 2)
    lo = float(u.min())
    occ = np.bincount(((u - lo) / bin_m).astype(np.int64)) > 0
    full = np.flatnonzero(occ)
    k = int(np.clip(np.searchsorted(full, (centre - lo) / bin_m), 0, len(full) - 1))
    breaks = np.flatnonzero(np.diff(full) * bin_m > gap)
    first = full[breaks[breaks < k][-1] + 1] if (breaks < k).any() else full[0]
    last = full[breaks[breaks >= k][0]] if (breaks >= k).any() else full[-1]
    inside = u[(u >= lo + first * bin_m) & (u < lo + (last + 1) * bin_m)]
    return float(inside.min()), float(inside.max())


def _order_key(item: tuple[WallFrame, np.ndarray]) -> tuple[float, float, float]:
    f = item[0]
    centre = f.origin + 0.5 * f.width_m * f.axis_u
    angle = math.degrees(math.atan2(f.normal[1], f.normal[0])) % 360.0
    return (-round(float(centre[1]), 1), round(float(centre[0]), 1), round(angle, 1))
