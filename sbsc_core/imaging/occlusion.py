"""Orthographic occlusion in the orthoimage J_CD: wall points seen *behind* an object.

The orthoimage looks at a wall straight on (paper, section 3.2), so where an object stands
out, only its front is visible. A scanner looking at the wall obliquely, though, sees the
wall *behind* an object that stands off it (the 3 cm gap behind a bracket-mounted
extinguisher, the space between a radiator's ribs): those wall points fall into the same
pixels as the object's front. A station close to the wall samples it far more densely
than the others (point density ~ cos(incidence) / range^2), so in such pixels the hidden
wall can hold most of the points, and the per-pixel median
(:func:`~sbsc_core.imaging.orthoimage.rasterize_median`) jumps to the wall: the object's relief
and colour break into speckle and the object is no longer recognised.

Here a pixel's points are cut into depth layers (``gap_m`` apart); the frontmost layer not
beyond ``far_m`` (furniture stands farther out) is the pixel's *front surface*
(:func:`front_layers`). A surface is only trusted where it is coherent: a pixel whose
3 x 3 neighbourhood's median front surface lies more than ``gap_m`` in front of the
pixel's own value is occluded (:func:`hide_occluded`): it takes its own front layer when
that layer lies on the neighbourhood's surface, and otherwise has no data (a hidden wall
point is no measurement of what the orthoimage shows; the sampling-gap filling of
:func:`~sbsc_core.imaging.orthoimage.fill_sampling_gaps` closes such isolated holes). Stray front
points - mixed pixels at an object's silhouette, noise - have no coherent neighbourhood
and change nothing; the plain wall, flat objects (less relief than ``gap_m``) and the
object edges (a straight edge's outer pixel has 3 of 9 object neighbours) are untouched.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["FrontLayers", "front_layers", "hide_occluded", "stack_front"]

_MIN_NEIGHBOURS = 5  # pixels with data a 3 x 3 neighbourhood needs for its median front surface
_MIN_SHARE = 0.25  # share of a neighbourhood's points a front surface must hold (a 1-in-5 stray layer holds 0.2)


@dataclass(frozen=True)
class FrontLayers:
    """The pixels' front layers (:func:`front_layers`), images of the orthoimage's shape."""

    depth: np.ndarray  # (H, W) float32 median depth of the front layer, NaN where none
    colour: np.ndarray  # (H, W, 3) uint8 its colour (median luminance), 0 where none
    points: np.ndarray  # (H, W) int32 points of the pixel
    front_points: np.ndarray  # (H, W) int32 points of its front layer, 0 where none


def front_layers(pixel: np.ndarray, depth: np.ndarray, rgb: np.ndarray, shape: tuple[int, int], *,
                 gap_m: float, far_m: float | None) -> FrontLayers:
    """The front surface of every pixel with points in two or more depth layers.

    Parameters
    ----------
    pixel
        Flat pixel number (row * width + col) of each point.
    depth
        Signed distance of each point from the wall plane (metres, positive into the room).
    rgb
        (N, 3) uint8 colours of the points.
    shape
        (rows, columns) of the orthoimage.
    gap_m
        Sorted depths of a pixel more than this apart start a new layer.
    far_m
        Layers whose median lies beyond this are furniture, never a front (None: none is).

    Returns
    -------
    FrontLayers
        The median depth of each pixel's frontmost layer, NaN where the pixel has fewer than
        two layers (or none within ``far_m``); the colour of that layer's point with the
        median luminance; the pixel's and the layer's point counts.
    """
    h, w = shape
    npx = h * w
    front_depth = np.full(npx, np.nan, np.float32)
    front_colour = np.zeros((npx, 3), np.uint8)
    front_points = np.zeros(npx, np.int32)
    pixel = np.asarray(pixel, np.int64)
    d = np.ascontiguousarray(depth, np.float32)  # ufunc.at is slow on a strided view (a record field)
    points = np.bincount(pixel, minlength=npx).astype(np.int32)
    if len(pixel):
        lo = np.full(npx, np.inf, np.float32)
        hi = np.full(npx, -np.inf, np.float32)
        np.minimum.at(lo, pixel, d)
        np.maximum.at(hi, pixel, d)
        sel = np.flatnonzero((hi - lo)[pixel] > gap_m)  # only these pixels can hold two layers
        if len(sel):
            p, dd, cc = pixel[sel], d[sel], np.asarray(rgb)[sel]
            order = np.lexsort((dd, p))
            p, dd, cc = p[order], dd[order], cc[order]
            new = np.r_[True, (p[1:] != p[:-1]) | (np.diff(dd) > gap_m)]
            starts = np.flatnonzero(new)
            sizes = np.diff(np.r_[starts, len(p)])
            mid = 0.5 * (dd[starts + (sizes - 1) // 2] + dd[starts + sizes // 2])
            lp = p[starts]
            first_of_pixel = np.r_[True, lp[1:] != lp[:-1]]
            ok = ~first_of_pixel  # a front lies in front of another layer of its pixel
            if far_m is not None:
                ok &= mid <= far_m
            cand = np.flatnonzero(ok)
            last = cand[np.r_[lp[cand][1:] != lp[cand][:-1], True]] if len(cand) else cand
            front_depth[lp[last]] = mid[last]
            front_points[lp[last]] = sizes[last]
            if len(last):  # colour: the point of each front layer with the median luminance
                layer = np.repeat(np.arange(len(starts)), sizes)
                is_front = np.zeros(len(starts), bool)
                is_front[last] = True
                keep = is_front[layer]
                lay, col = layer[keep], cc[keep]
                luma = col.astype(np.int32) @ np.array([77, 150, 29], np.int32)
                o2 = np.lexsort((luma, lay))
                lay, col = lay[o2], col[o2]
                f0 = np.flatnonzero(np.r_[True, lay[1:] != lay[:-1]])
                n = np.diff(np.r_[f0, len(lay)])
                a, b = col[f0 + (n - 1) // 2].astype(np.int32), col[f0 + n // 2].astype(np.int32)
                front_colour[lp[lay[f0]]] = ((a + b + 1) // 2).astype(np.uint8)
    return FrontLayers(front_depth.reshape(h, w), front_colour.reshape(h, w, 3), points.reshape(h, w),
                       front_points.reshape(h, w))


def hide_occluded(depth: np.ndarray, colour: np.ndarray, mask: np.ndarray, front: FrontLayers, *,
                  gap_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels whose value lies behind their neighbourhood's coherent front surface.

    The front surface ``S`` of a pixel is its front layer's depth where it has one, else its
    ``depth``. Where the median ``C`` of ``S`` over a pixel's 3 x 3 neighbourhood (at least five
    pixels with data) lies more than ``gap_m`` in front of the pixel's ``depth``, and the
    neighbourhood's points on that surface (those of its pixels with ``S`` within ``gap_m`` of
    ``C``: a front layer's points, or all of a one-layer pixel's) are at least a quarter of
    its points, the pixel takes its own front layer if that lies within ``gap_m`` of ``C``, and
    otherwise has no data. Returns new arrays.

    Parameters
    ----------
    depth, colour, mask
        The orthoimage's per-pixel medians (:func:`~sbsc_core.imaging.orthoimage.rasterize_median`).
    front
        The pixels' front layers (:func:`front_layers`).
    gap_m
        How far in front of a pixel a surface must lie to hide it.
    """
    layered = np.isfinite(front.depth)
    surf = np.where(layered, front.depth, depth).astype(np.float32)
    on_surf = np.where(layered, front.front_points, front.points).astype(np.float32)
    filled = np.where(np.isfinite(surf), surf, np.float32(-1e3))
    nearest = cv2.dilate(filled, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=-1e3)
    rows, cols = np.nonzero(mask & (nearest > depth + np.float32(gap_m)))
    depth, colour, mask = depth.copy(), colour.copy(), mask.copy()
    if not len(rows):
        return depth, colour, mask

    def hood(img: np.ndarray, fill: float) -> np.ndarray:
        pad = np.pad(img, 1, constant_values=fill)
        return np.stack([pad[rows + i, cols + j] for i in range(3) for j in range(3)], axis=1)

    s = hood(surf, np.nan)
    enough = np.isfinite(s).sum(axis=1) >= _MIN_NEIGHBOURS
    med = np.full(len(rows), -np.inf, np.float32)
    med[enough] = np.nanmedian(s[enough], axis=1)
    with np.errstate(invalid="ignore"):
        share = (hood(on_surf, 0.0) * (np.abs(s - med[:, None]) <= gap_m)).sum(axis=1)
    share /= np.maximum(hood(front.points.astype(np.float32), 0.0).sum(axis=1), 1.0)
    occluded = enough & (med > depth[rows, cols] + gap_m) & (share >= _MIN_SHARE)
    rows, cols, med = rows[occluded], cols[occluded], med[occluded]
    fd = front.depth[rows, cols]
    take = np.isfinite(fd) & (np.abs(fd - med) <= gap_m)
    r, c = rows[take], cols[take]
    depth[r, c] = front.depth[r, c]
    colour[r, c] = front.colour[r, c]
    r, c = rows[~take], cols[~take]
    depth[r, c] = np.nan
    colour[r, c] = 0
    mask[r, c] = False
    return depth, colour, mask


def stack_front(bands: list[tuple[int, FrontLayers]], shape: tuple[int, int]) -> FrontLayers | None:
    """The front layers of a whole orthoimage from those of bands of rows (first row, layers),
    as :func:`~sbsc_core.imaging.partition.wall_orthoimage` bins a wall band by band; None without bands.
    Rows of no band have no points."""
    if not bands:
        return None
    h, w = shape
    out = FrontLayers(np.full((h, w), np.nan, np.float32), np.zeros((h, w, 3), np.uint8),
                      np.zeros((h, w), np.int32), np.zeros((h, w), np.int32))
    for r0, f in bands:
        r1 = r0 + f.depth.shape[0]
        out.depth[r0:r1], out.colour[r0:r1] = f.depth, f.colour
        out.points[r0:r1], out.front_points[r0:r1] = f.points, f.front_points
    return out
