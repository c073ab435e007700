"""The 4D orthoimage J_CD of a wall: colour and depth at 5 mm (paper, section 3.2).

Each point of the wall is expressed in the wall frame (u along the wall, v up, d the
signed distance from the fitted wall plane, positive into the room) and binned into
pixels of ``pixel_m``; row 0 is the top of the wall (see :mod:`sbsc_core.types`). Several
points in one pixel are combined robustly: the depth is their median, the colour that of
the point with the median luminance (a real measured colour; bright or dark outliers such
as highlights or mixed edge returns are rejected). Both medians are computed for all
pixels at once by sorting one packed integer key per point (pixel number, then the
quantised value) - no Python loop over points.

A pixel whose points lie behind a coherent surface of its neighbourhood - the wall seen
obliquely behind an object standing off it - shows that surface instead, as a view straight
on would (:mod:`sbsc_core.imaging.occlusion`, ``occlusion_gap_m``).

Pixels without points have ``mask`` False, depth NaN and colour 0: holes stay holes. Only
sampling gaps - no-data pixels with data on every side within ``fill_gaps_px`` - are
filled with the mean of their neighbours, so that a scan somewhat coarser than the pixel
does not look like a sieve; the edges of openings and shadows do not move.
"""

from __future__ import annotations

import math
import sys

import cv2
import numpy as np

from ..settings import OrthoimageSettings
from ..types import Orthoimage, PointCloud, Wall, WallFrame
from .occlusion import FrontLayers, front_layers, hide_occluded

__all__ = ["build_orthoimage", "ortho_shape", "ortho_pixels", "orthoimage_from_pixels", "orthoimage_from_images",
           "wall_coordinates", "near_wall", "near_walls", "rasterize_median", "fill_sampling_gaps", "layer_options", "front_images"]


def build_orthoimage(cloud: PointCloud, wall: Wall, settings: OrthoimageSettings | None = None) -> Orthoimage:
    """Orthoimage J_CD of ``wall`` from its points ``wall.point_index`` of ``cloud``."""
    s = settings or OrthoimageSettings()
    idx = np.asarray(wall.point_index)
    uvd = wall_coordinates(cloud.xyz[idx], wall.frame, np.asarray(cloud.origin, np.float64))
    keep, pixel = ortho_pixels(uvd, wall.frame, s)
    return orthoimage_from_pixels(wall.id, wall.frame, pixel, uvd[keep, 2], cloud.rgb[idx[keep]], settings=s)


def ortho_shape(frame: WallFrame, pixel_m: float) -> tuple[int, int]:
    """(rows, columns) of the orthoimage of a wall frame."""
    px = float(pixel_m)
    return (max(1, math.ceil(frame.height_m / px - 1e-9)), max(1, math.ceil(frame.width_m / px - 1e-9)))


def ortho_pixels(uvd: np.ndarray, frame: WallFrame, settings: OrthoimageSettings | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Which points (``uvd`` from :func:`wall_coordinates`) fall into the orthoimage, and their pixels.

    Returns the keep mask and the flat pixel numbers (row * width + col, int64) of the kept
    points: inside the frame and within ``depth_range_m`` of the plane.
    """
    s = settings or OrthoimageSettings()
    px = float(s.pixel_m)
    h, w = ortho_shape(frame, px)
    d0, d1 = s.depth_range_m
    col = np.floor(uvd[:, 0] * np.float32(1.0 / px)).astype(np.int32)
    row = np.floor((np.float32(frame.height_m) - uvd[:, 1]) * np.float32(1.0 / px)).astype(np.int32)
    keep = (col >= 0) & (col < w) & (row >= 0) & (row < h) & (uvd[:, 2] >= d0) & (uvd[:, 2] <= d1)
    pixel = row[keep].astype(np.int64)
    pixel *= w
    pixel += col[keep]
    return keep, pixel


def orthoimage_from_pixels(wall_id: str, frame: WallFrame, pixel: np.ndarray, depth: np.ndarray,
                           rgb: np.ndarray, *, settings: OrthoimageSettings | None = None) -> Orthoimage:
    """Orthoimage J_CD from points already binned: flat pixel numbers, depths and colours.

    This is all the orthoimage stage does on a wall's partition (see :mod:`sbsc_core.imaging.partition`):
    the per-pixel medians and the filling of sampling gaps.
    """
    s = settings or OrthoimageSettings()
    px = float(s.pixel_m)
    d0, d1 = s.depth_range_m
    shape = ortho_shape(frame, px)
    images = rasterize_median(pixel, depth, rgb, shape, depth_range=(d0, d1),
                              quantum=s.depth_quantum_m, **layer_options(s))
    return orthoimage_from_images(wall_id, frame, *images, settings=s,
                                  front=front_images(pixel, depth, rgb, shape, s))


def front_images(pixel: np.ndarray, depth: np.ndarray, rgb: np.ndarray, shape: tuple[int, int],
                 settings: OrthoimageSettings) -> FrontLayers | None:
    """The pixels' front layers (:func:`~sbsc_core.imaging.occlusion.front_layers`) for the
    occlusion test, or None when ``settings.occlusion_gap_m`` is None."""
    if settings.occlusion_gap_m is None:
        return None
    return front_layers(pixel, depth, rgb, shape, gap_m=settings.occlusion_gap_m, far_m=settings.furniture_depth_m)


def layer_options(settings: OrthoimageSettings) -> dict[str, float | None]:
    """The keyword options of :func:`rasterize_median` that ``settings`` give (the per-pixel layers)."""
    if settings.layer_gap_m is None:
        return {}
    return {"layer_gap": settings.layer_gap_m, "furniture_depth": settings.furniture_depth_m,
            "min_layer_share": settings.min_layer_share}


def orthoimage_from_images(wall_id: str, frame: WallFrame, depth: np.ndarray, colour: np.ndarray, mask: np.ndarray,
                           *, settings: OrthoimageSettings | None = None,
                           front: FrontLayers | None = None) -> Orthoimage:
    """Orthoimage J_CD from the per-pixel medians (:func:`rasterize_median`): the pixels hidden
    behind a coherent front surface (``front``, from :func:`front_images`; see
    :mod:`sbsc_core.imaging.occlusion`) replaced, then the sampling gaps filled."""
    s = settings or OrthoimageSettings()
    if front is not None and s.occlusion_gap_m is not None:
        depth, colour, mask = hide_occluded(depth, colour, mask, front, gap_m=s.occlusion_gap_m)
    if s.fill_gaps_px > 0:
        depth, colour, mask = fill_sampling_gaps(depth, colour, mask, s.fill_gaps_px, s.fill_min_fraction)
    return Orthoimage(wall_id=wall_id, frame=frame, pixel_m=float(s.pixel_m), colour=colour, depth=depth, mask=mask)


def wall_coordinates(xyz: np.ndarray, frame: WallFrame, cloud_origin: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) float32 columns u, v, d of float32 points given relative to ``cloud_origin``."""
    o = frame.origin - (np.zeros(3) if cloud_origin is None else np.asarray(cloud_origin, np.float64))
    xyz = np.asarray(xyz, np.float32)
    out = np.empty((len(xyz), 3), np.float32)
    for k, axis in enumerate((frame.axis_u, frame.axis_v, frame.normal)):
        a = np.asarray(axis, np.float64)
        f = a.astype(np.float32)
        # the products, summed in axis order; a zero component (a wall's axis_v, an upright
        # wall's normal, a ceiling's frame) adds a zero: left out, the sum is the same
        terms = [i for i in range(3) if f[i] != 0]
        col = xyz[:, terms[0]] * f[terms[0]] if terms else np.zeros(len(xyz), np.float32)
        for i in terms[1:]:
            col += xyz[:, i] * f[i]
        col -= np.float32(o @ a)
        out[:, k] = col
    return out


_PLAN_MARGIN_M = 0.01  # plan boxes are grown by this: float32 rounding never drops a point the exact test keeps


def near_wall(xyz: np.ndarray, frame: WallFrame, clear_m: float, cloud_origin: np.ndarray | None = None
              ) -> np.ndarray:
    """Which points (float32, relative to ``cloud_origin``) lie within ``clear_m`` of a wall's
    plane, over its span grown by ``clear_m`` at each end.

    The exact test (:func:`wall_coordinates`) runs only on the points over the plan box of
    that slab (grown by :data:`_PLAN_MARGIN_M`): a cloud holds many walls, and most points are
    far from any one of them.
    """
    keep = np.zeros(len(xyz), bool)
    idx = np.arange(len(xyz))
    if _upright(frame):  # a plan box
        idx = np.flatnonzero(in_plan_box(xyz, *_slab_box(frame, clear_m), cloud_origin, margin_m=_PLAN_MARGIN_M))
    uvd = wall_coordinates(np.take(xyz, idx, axis=0), frame, cloud_origin)  # take: as xyz[idx], faster
    keep[idx] = (np.abs(uvd[:, 2]) < clear_m) & (uvd[:, 0] > -clear_m) & (uvd[:, 0] < frame.width_m + clear_m)
    return keep


def _upright(frame: WallFrame) -> bool:
    return abs(float(frame.axis_u[2])) < 1e-9 and abs(float(frame.normal[2])) < 1e-9


def _slab_box(frame: WallFrame, clear_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Plan box (world x, y) of an upright wall's slab within ``clear_m`` (what :func:`near_wall` tests)."""
    u, n = np.asarray(frame.axis_u[:2], np.float64), np.asarray(frame.normal[:2], np.float64)
    o = np.asarray(frame.origin[:2], np.float64)
    corners = np.array([o + a * u + b * n for a in (-clear_m, frame.width_m + clear_m) for b in (-clear_m, clear_m)])
    return corners.min(axis=0), corners.max(axis=0)


_NEAR_CELL_M = 0.5  # plan cells of :func:`near_walls`' lookup grid ...
_NEAR_MAX_CELLS = 1 << 22  # ... at most this many (larger cells over a large site)


def near_walls(xyz: np.ndarray, frames: list[WallFrame], clear_m: float, cloud_origin: np.ndarray | None = None
               ) -> np.ndarray:
    """Which points lie within ``clear_m`` of any of the walls' planes: :func:`near_wall` of
    each wall, or-ed, with each point tested only against the walls whose slab may hold it.

    A plan grid of ``_NEAR_CELL_M`` cells tells which upright walls' slabs (their plan boxes
    grown by a cell: float rounding of a point's cell never loses one) touch each cell; the
    points are grouped by that set and :func:`near_wall` runs on each group for each of its
    walls (on a point it gives what it gives on all points). A wall that is not upright is
    tested on every point.
    """
    out = np.zeros(len(xyz), bool)
    if not len(xyz) or not frames:
        return out
    upright = [f for f in frames if _upright(f)]
    for f in frames:
        if not _upright(f):
            out |= near_wall(xyz, f, clear_m, cloud_origin)
    if not upright:
        return out
    o = np.zeros(2) if cloud_origin is None else np.asarray(cloud_origin, np.float64)[:2]
    boxes = [_slab_box(f, clear_m) for f in upright]
    span = np.max([b[1] for b in boxes], axis=0) - np.min([b[0] for b in boxes], axis=0)
    cell = max(_NEAR_CELL_M, math.sqrt(float((span[0] + 1) * (span[1] + 1)) / _NEAR_MAX_CELLS))  # a site: coarser
    lo = np.min([b[0] for b in boxes], axis=0) - o - 2 * cell  # the grid, relative to the cloud's origin
    hi = np.max([b[1] for b in boxes], axis=0) - o + 2 * cell
    nx, ny = (np.ceil((hi - lo) / cell).astype(np.int64) + 1).tolist()
    cells_of: dict[int, list[int]] = {}
    for w, (b0, b1) in enumerate(boxes):
        i0, j0 = np.maximum(np.floor((b0 - o - lo) / cell).astype(np.int64) - 1, 0)
        i1, j1 = np.minimum(np.floor((b1 - o - lo) / cell).astype(np.int64) + 1, (nx - 1, ny - 1))
        jj, ii = np.mgrid[j0:j1 + 1, i0:i1 + 1]
        for key in (jj * nx + ii).ravel().tolist():
            cells_of.setdefault(key, []).append(w)
    combo_id: dict[tuple[int, ...], int] = {}
    lut = np.zeros(nx * ny, np.int32)
    for key, ws in cells_of.items():
        lut[key] = combo_id.setdefault(tuple(ws), len(combo_id) + 1)
    combos = sorted(combo_id, key=combo_id.__getitem__)
    combo = _grid_lookup(xyz, lut, lo=lo, cell=cell, nx=nx, ny=ny)
    sel = np.flatnonzero(combo)
    small = combo.astype(np.uint16 if len(combos) < 65536 else np.int32)
    if len(sel) == len(combo):  # every point near some slab (as in a storey's points): no subset to take
        order = np.argsort(small, kind="stable")
    else:
        order = sel[np.argsort(small[sel], kind="stable")]
    del small
    cuts = np.searchsorted(combo[order], np.arange(1, len(combos) + 2))
    for c, ws in enumerate(combos):
        pts = order[cuts[c]:cuts[c + 1]]
        if not len(pts):
            continue
        sub = np.take(xyz, pts, axis=0)
        hit = np.zeros(len(pts), bool)
        for w in ws:
            hit |= near_wall(sub, upright[w], clear_m, cloud_origin)
        out[pts[hit]] = True
    return out


def _grid_lookup(xyz: np.ndarray, lut: np.ndarray, *, lo: np.ndarray, cell: float, nx: int, ny: int) -> np.ndarray:
    """``lut`` (int32, one entry per cell of an ``nx`` x ``ny`` plan grid of ``cell`` from
    ``lo``) at each point's cell; 0 for a point beyond the grid.

    The cell of a point is ``floor((x - lo) / cell)`` in float64 along each axis; the flat
    cell number ``iy * nx + ix`` is computed in float64 too (whole numbers far below 2**53:
    exact), in place, with the points beyond the grid pointed at an extra 0 entry.
    """
    fx = xyz[:, 0].astype(np.float64)
    fx -= lo[0]
    fx /= cell
    np.floor(fx, out=fx)
    fy = xyz[:, 1].astype(np.float64)
    fy -= lo[1]
    fy /= cell
    np.floor(fy, out=fy)
    inside = (fx >= 0) & (fx < nx) & (fy >= 0) & (fy < ny)  # beyond the grid: far from every slab
    fy *= nx
    fy += fx
    del fx
    np.copyto(fy, nx * ny, where=~inside)
    return np.append(lut, np.int32(0))[fy.astype(np.int64)]


def in_plan_box(xyz: np.ndarray, lo: np.ndarray, hi: np.ndarray, cloud_origin: np.ndarray | None = None, *,
                margin_m: float = 0.0) -> np.ndarray:
    """Which points (relative to ``cloud_origin``) lie over the plan box ``lo`` to ``hi``
    (x, y; world coordinates) grown by ``margin_m``."""
    o = np.zeros(2) if cloud_origin is None else np.asarray(cloud_origin, np.float64)[:2]
    x, y = xyz[:, 0], xyz[:, 1]
    return ((x >= lo[0] - o[0] - margin_m) & (x <= hi[0] - o[0] + margin_m)
            & (y >= lo[1] - o[1] - margin_m) & (y <= hi[1] - o[1] + margin_m))


def rasterize_median(pixel: np.ndarray, depth: np.ndarray, rgb: np.ndarray, shape: tuple[int, int],
                     *, depth_range: tuple[float, float], quantum: float, layer_gap: float | None = None,
                     furniture_depth: float | None = None, min_layer_share: float = 0.5
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-pixel median depth and the colour of the point with the median luminance.

    ``pixel`` holds flat pixel numbers (row * width + col) of each point. Returns depth
    (H, W) float32 with NaN where no point fell, colour (H, W, 3) uint8 with 0 there, and
    the mask of pixels with data. The median of an even count is the mean of the two middle
    values; depth is resolved to ``quantum``.

    With ``layer_gap`` (metres) the medians are those of one layer of each pixel, not of
    all its points (see :func:`_pixel_layers`): a pixel's points, in depth order, are cut
    into layers wherever two neighbours are more than ``layer_gap`` apart. A pixel with a
    point beyond ``furniture_depth`` saw furniture (no wall object stands out so far): only
    its layer on the wall plane is kept, and without one the pixel has no data - furniture
    in front of a wall hides it, it is no relief of it. Elsewhere the layer nearest the wall
    plane holding at least ``min_layer_share`` of the pixel's points is kept (else the
    largest one): the median of a mixture of two surfaces is neither.
    """
    h, w = shape
    npx = h * w
    pixel = np.asarray(pixel, np.int64)
    counts = np.bincount(pixel, minlength=npx)
    mask = counts > 0
    depth_img = np.full(npx, np.nan, np.float32)
    colour = np.zeros((npx, 3), np.uint8)
    if len(pixel):
        start = (np.cumsum(counts) - counts)[mask]
        n = counts[mask]
        # depth: sort (pixel, quantised depth) keys
        nq = int(math.ceil((depth_range[1] - depth_range[0]) / quantum)) + 1
        q = np.asarray(depth, np.float32) - np.float32(depth_range[0])
        q *= np.float32(1.0 / quantum)
        np.rint(q, out=q)
        np.clip(q, 0, nq - 1, out=q)
        if npx * nq < (1 << 32):  # the key fits 32 bits: half the bytes to sort, the same order
            key = pixel.astype(np.uint32)
            key *= np.uint32(nq)
            key += q.astype(np.uint32)
        else:
            key = pixel * nq
            key += q.astype(np.int64)
        key.sort()
        if layer_gap is None:
            lo_i, hi_i = start + (n - 1) // 2, start + n // 2
            med = 0.5 * ((key[lo_i] % nq) + (key[hi_i] % nq))
        else:
            far = nq if furniture_depth is None else int(round((furniture_depth - depth_range[0]) / quantum))
            zero = int(round(-depth_range[0] / quantum))
            sq = key % nq
            first, size = _pixel_layers(sq, start, n, gap_q=int(round(layer_gap / quantum)), far_q=far, zero_q=zero, min_share=min_layer_share)
            good = size > 0
            first, size = first[good], size[good]
            med = 0.5 * (sq[first + (size - 1) // 2] + sq[first + size // 2])
            # the colour is that of the kept layer's points: each point against its pixel's bounds
            lo_p = np.full(npx, nq, sq.dtype)
            hi_p = np.zeros(npx, sq.dtype)
            where = np.flatnonzero(mask)[good]
            lo_p[where], hi_p[where] = sq[first], sq[first + size - 1]
            del sq
            qp = q.astype(lo_p.dtype)
            keep = (qp >= lo_p[pixel]) & (qp <= hi_p[pixel])
            del qp, lo_p, hi_p
            pixel, rgb = pixel[keep], np.asarray(rgb)[keep]
            mask[:] = False
            mask[where] = True
            start = np.cumsum(size) - size  # the kept points of each pixel, in pixel order
            lo_i, hi_i = start + (size - 1) // 2, start + size // 2
        del q, key
        depth_img[mask] = (depth_range[0] + med * quantum).astype(np.float32)
        # colour: that of the point with the median luminance; the colour rides in the sort key
        packed = rgb[:, 0].astype(np.int64)  # 24 bits r, g, b
        packed <<= 8
        packed |= rgb[:, 1]
        packed <<= 8
        packed |= rgb[:, 2]
        luma = rgb[:, 0].astype(np.int64) * 77  # 0..65280, 16 bits
        luma += rgb[:, 1].astype(np.int64) * 150
        luma += rgb[:, 2].astype(np.int64) * 29
        if npx < (1 << 22):
            key = pixel << 40
            luma <<= 24
            key |= luma
            del luma
            key |= packed
            del packed
            key.sort()
            c_lo, c_hi = key[lo_i] & 0xFFFFFF, key[hi_i] & 0xFFFFFF
        else:  # too many pixels to pack: sort indices instead
            key = pixel * 65536
            key += luma
            order = np.argsort(key)
            c_lo, c_hi = packed[order[lo_i]], packed[order[hi_i]]
        del key
        colour[mask] = _mean_of_packed(c_lo, c_hi)
    return depth_img.reshape(h, w), colour.reshape(h, w, 3), mask.reshape(h, w)


def _mean_of_packed(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 r, g, b of two colours packed in int64 as ``r << 16 | g << 8 | b``, each
    channel ``(a + b + 1) // 2`` (the mean, halves up).

    The channels are the packed values' bytes (read through a byte view, the low byte first
    on a little-endian machine; shifted out elsewhere), added in 16 bits: what the shifts
    and masks of int64 give, in a few passes over 3 bytes a colour instead of 8.
    """
    def channels(p: np.ndarray) -> np.ndarray:
        p = np.ascontiguousarray(p, np.int64)
        if sys.byteorder == "little":
            return p.view(np.uint8).reshape(-1, 8)[:, 2::-1].astype(np.uint16)
        return np.stack([(p >> s) & 255 for s in (16, 8, 0)], axis=-1).astype(np.uint16)

    out = channels(a)
    out += channels(b)
    out += 1
    out >>= 1
    return out.astype(np.uint8)


def _pixel_layers(q: np.ndarray, start: np.ndarray, n: np.ndarray, *, gap_q: int, far_q: int, zero_q: int,
                  min_share: float) -> tuple[np.ndarray, np.ndarray]:
    """The kept layer of each pixel: (index of its first point in ``q``, its point count; 0: none).

    ``q`` holds the quantised depths sorted per pixel (pixel ``k``'s are
    ``q[start[k]:start[k] + n[k]]``). A new layer begins where a depth exceeds the previous
    one by more than ``gap_q``. A pixel with a point beyond ``far_q`` saw furniture: only a
    layer on the wall plane (median within ``gap_q`` of ``zero_q``) may be kept there, the
    largest; without one the pixel has no data (the furniture's other points - a desk top
    seen edge-on, a cabinet's side - are no relief of the wall). Elsewhere the layers with at
    least ``min_share`` of the pixel's points qualify and the one whose median is nearest
    the wall plane is kept, else the largest.
    """
    total = len(q)
    pid = np.repeat(np.arange(len(n)), n)
    brk = np.zeros(total, bool)
    brk[start] = True
    brk[1:] |= (q[1:].astype(np.int64) - q[:-1]) > gap_q
    s0 = np.flatnonzero(brk)
    size = np.diff(np.append(s0, total))
    lp = pid[s0]
    del pid, brk
    mid = (q[s0 + (size - 1) // 2].astype(np.int64) + q[s0 + size // 2]) // 2
    off = np.abs(mid - zero_q)
    furniture = (q[start + n - 1] > far_q)[lp]  # the layer's pixel saw furniture
    usable = ~furniture | (off <= gap_q)
    share_ok = ~furniture & (size >= min_share * n[lp])
    # rank: qualifying layers first, by distance to the plane; then the others by size
    big = np.int64(1) << 40
    rank = np.where(share_ok, off, big - size)
    rank[~usable] = big << 1
    # the best-ranked layer of each pixel (its layers are consecutive, pixel by pixel): the
    # first layer holding its pixel's minimum rank
    pix_first = np.flatnonzero(np.r_[True, lp[1:] != lp[:-1]])
    low = np.minimum.reduceat(rank, pix_first)
    cand = np.flatnonzero(rank == low[lp])
    best = cand[np.r_[True, lp[cand[1:]] != lp[cand[:-1]]]]
    first = s0[best]
    count = np.where(usable[best], size[best], 0)
    return first, count


def fill_sampling_gaps(depth: np.ndarray, colour: np.ndarray, mask: np.ndarray, radius: int,
                       min_fraction: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fill no-data pixels that lie *between* data: sampling gaps, not holes.

    A no-data pixel is filled when each of the four quadrants of its (2r+1)^2 window
    (a pinwheel split, each touching one axis) holds data and at least ``min_fraction`` of
    the window has data; the value is the mean of the data in the window. A pixel at the
    edge of a hole has data on one side only and stays empty, so openings and occlusion
    shadows keep their size. Returns new arrays.
    """
    r = int(radius)
    if r <= 0 or mask.all() or not mask.any():
        return depth, colour, mask
    h, w = mask.shape
    ii = cv2.integral(np.pad(mask, r).astype(np.uint8), sdepth=cv2.CV_32S)

    def window(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        """Data count over rows r+r0 .. r+r1, cols c+c0 .. c+c1 (inclusive) for every pixel."""
        a0, a1, b0, b1 = r + r0, r + r1 + 1, r + c0, r + c1 + 1
        return ii[a1:a1 + h, b1:b1 + w] - ii[a0:a0 + h, b1:b1 + w] - ii[a1:a1 + h, b0:b0 + w] + ii[a0:a0 + h, b0:b0 + w]

    k = 2 * r + 1
    total = window(-r, r, -r, r)
    fill = ~mask & (total >= min_fraction * (k * k - 1))
    for q in ((-r, -1, -r, 0), (-r, 0, 1, r), (1, r, 0, r), (0, r, -r, -1)):  # a pinwheel of quadrants
        fill &= window(*q) > 0
    rows, cols = np.nonzero(fill)
    if not len(rows):
        return depth, colour, mask

    def box(table: np.ndarray) -> np.ndarray:
        """Sums over the whole window at the pixels to fill (np.take of flat indices: as
        ``table[rows + k, cols + k] - ...``, without fancy indexing's slow path)."""
        tw = table.shape[1]
        flat = table.reshape(-1, *table.shape[2:])
        at = rows * tw
        at += cols
        return (np.take(flat, at + (k * tw + k), axis=0) - np.take(flat, at + k, axis=0)
                - np.take(flat, at + k * tw, axis=0) + np.take(flat, at, axis=0))

    cnt = total[rows, cols].astype(np.float64)
    d_ii = cv2.integral(np.pad(np.where(mask, depth, 0.0), r).astype(np.float64), sdepth=cv2.CV_64F)
    c_ii = cv2.integral(np.pad(np.where(mask[..., None], colour, 0), ((r, r), (r, r), (0, 0))).astype(np.uint8),
                        sdepth=cv2.CV_32S)
    dsum = box(d_ii)
    csum = box(c_ii)
    depth = depth.copy()
    colour = colour.copy()
    mask = mask.copy()
    depth[rows, cols] = (dsum / cnt).astype(np.float32)
    colour[rows, cols] = np.clip(np.rint(csum / cnt[:, None]), 0, 255).astype(np.uint8)
    mask[rows, cols] = True
    return depth, colour, mask
