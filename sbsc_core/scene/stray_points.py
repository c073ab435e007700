"""The dense part of a scan, and its stray points.

Real scans hold a few points far from the building: reflections, people walking by, the sky
or a street seen through a window. They must not size any grid. The dense part is found
on a coarse voxel occupancy grid (``stray_cell_m``) of a regular subsample: a voxel is
dense when it holds at least ``stray_min_fraction`` of the points of the voxel a typical
point lies in (the point-weighted median voxel count), so the test is the same for a full
cloud and for any regular subsample of it. The dense extent is the box of the dense voxels
grown by ``stray_margin_m``; the points outside it are stray: ignored and counted. A dense
part wider than ``max_extent_m`` is refused with one line (a survey of a town, not of a
building, or a file in the wrong units).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..settings import SegmentationSettings

__all__ = ["DenseBox", "dense_box", "inside_box"]

_CELL_BITS = 21  # voxel indices kept in +-2**20 (21 bits per axis in one int64 key)
_CHUNK = 1 << 22


@dataclass(frozen=True)
class DenseBox:
    """The axis-aligned box of the dense part, in the cloud's own (relative) frame."""

    lo: np.ndarray  # (3,) float64
    hi: np.ndarray  # (3,) float64

    @property
    def size(self) -> np.ndarray:
        return self.hi - self.lo


def dense_box(xyz: np.ndarray, settings: SegmentationSettings | None = None, where: str = "scan") -> DenseBox:
    """Box of the dense part of ``xyz`` (N, 3), in the same frame.

    Only a regular subsample of at most ``stray_sample_points`` points is looked at; far
    coordinates (up to the float32 range) are never turned into grid sizes. Raises
    :class:`~sbsc_core.errors.InputError` (``where``: reason) when there is no dense part or
    when it is wider than ``max_extent_m``.
    """
    s = settings or SegmentationSettings()
    n = len(xyz)
    if n == 0:
        raise InputError(where, "no points")
    step = max(1, math.ceil(n / s.stray_sample_points))
    p = np.asarray(xyz[::step], np.float64)
    finite = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1]) & np.isfinite(p[:, 2])  # one axis at a time
    if not finite.all():
        p = p[finite]
    if len(p) == 0:
        raise InputError(where, "no points with finite coordinates")
    cell = s.stray_cell_m
    half = float(1 << (_CELL_BITS - 1))
    # the voxel grid is centred on the bulk: np.median(p, axis=0), a column at a time (the same values, faster)
    centre = np.floor(np.array([np.median(p[:, a]) for a in range(3)]) / cell) * cell
    with np.errstate(invalid="ignore", over="ignore"):
        f = np.floor((p - centre) / cell)
    near = (np.abs(f[:, 0]) < half - 1) & (np.abs(f[:, 1]) < half - 1) & (np.abs(f[:, 2]) < half - 1)
    ijk = (f[near] if not near.all() else f).astype(np.int64)  # farther voxels cannot be keyed: stray anyway
    ijk += int(half)
    key = (ijk[:, 0] << (2 * _CELL_BITS)) | (ijk[:, 1] << _CELL_BITS) | ijk[:, 2]
    uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    typical = float(np.median(counts[inv]))
    dense = counts >= max(s.stray_min_points, s.stray_min_fraction * typical)
    if not dense.any():
        raise InputError(where, f"no dense part: {n:,} points scattered with no {cell:g} m voxel holding "
                         f"{s.stray_min_points} of them")
    mask = (1 << _CELL_BITS) - 1
    d = uniq[dense]
    cells = np.stack([d >> (2 * _CELL_BITS), (d >> _CELL_BITS) & mask, d & mask], axis=1) - int(half)
    lo = centre + cells.min(axis=0) * cell - s.stray_margin_m
    hi = centre + (cells.max(axis=0) + 1) * cell + s.stray_margin_m
    size = hi - lo
    if float(size[:2].max()) > s.max_extent_m or float(size[2]) > s.max_extent_m:
        raise InputError(where, f"the dense part of the scan spans {size[0] / 1000:.1f} x {size[1] / 1000:.1f} "
                         f"x {size[2] / 1000:.1f} km, more than the {s.max_extent_m / 1000:g} km of a "
                         "building (wrong units, or not a building scan?)")
    return DenseBox(lo.astype(np.float64), hi.astype(np.float64))


def inside_box(xyz: np.ndarray, box: DenseBox) -> np.ndarray:
    """Boolean mask of the points of ``xyz`` (N, 3) inside ``box``, computed chunk by chunk."""
    out = np.empty(len(xyz), bool)
    lo, hi = box.lo.astype(np.float32), box.hi.astype(np.float32)
    for a in range(0, len(xyz), _CHUNK):
        c = xyz[a: a + _CHUNK]
        m = out[a: a + _CHUNK]
        np.greater_equal(c[:, 0], lo[0], out=m)  # one axis at a time: no (chunk, 3) temporaries
        m &= c[:, 0] <= hi[0]
        for k in (1, 2):
            m &= c[:, k] >= lo[k]
            m &= c[:, k] <= hi[k]
    return out
