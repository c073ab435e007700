"""Colour preparation of an orthoimage: illumination equalisation and highlights (section 3.2).

Several stations light and photograph a wall differently, so its colour changes in steps
from one station's area to another's, smoothly around each panorama, and brightens where
a flash made a specular highlight. Colour thresholding (section 4.3) needs the plain wall
to have one colour. We model the observed colour of the wall as its paint times an
illumination field that varies slowly except at station boundaries, estimate that field
from the wall itself and divide it out:

1. The image is cut into cells of ``cell_m``; each cell gets its median colour and depth.
2. Cells that are plain lit wall are those that do not stand out of the plane (objects
   do) and whose chromaticity is the wall's, or that are near-white and flat (a highlight
   on the wall), and that are uniform: a cell with a share of pixels of another
   chromaticity or depth holds an object's outline or print (the light text band of a
   thin sign can have nearly the wall's chromaticity) and is not a sample of the
   illumination. Other cells (objects, signs, openings, no data) take the field of the
   nearest wall cell.
3. A median filter over ``illumination_window_m`` removes what is left of small objects
   while keeping the straight steps between stations sharp.
4. The field is brought back to pixels with an edge-aware upsampling: each pixel takes,
   among the fields of the neighbouring cells, the one that explains its colour best when
   it is wall coloured (so a station boundary stays sharp inside a cell), and the smooth
   bilinear field otherwise.
5. Every channel is divided by the field and multiplied by the wall's reference colour.

An additive highlight on the wall is part of the field, so dividing restores the wall's
colour there too. Depth and mask are unchanged.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy import ndimage

from ..settings import ColourPrepSettings
from ..types import Orthoimage

__all__ = ["prepare_colour", "illumination_field"]


def prepare_colour(ortho: Orthoimage, settings: ColourPrepSettings | None = None) -> Orthoimage:
    """A new orthoimage whose colour is equalised (depth and mask are shared, unchanged)."""
    s = settings or ColourPrepSettings()
    field, ref = illumination_field(ortho, s)
    if field is None:
        colour = ortho.colour.copy()
    else:  # in place: the gain, then the equalised colour, then no data at 0
        gain = np.maximum(field, 1.0)
        np.divide(ref[None, None, :], gain, out=gain)
        np.clip(gain, 0.25, 4.0, out=gain)
        gain *= ortho.colour
        np.rint(gain, out=gain)
        np.clip(gain, 0, 255, out=gain)
        colour = gain.astype(np.uint8)
        colour *= ortho.mask[..., None]
    return Orthoimage(wall_id=ortho.wall_id, frame=ortho.frame, pixel_m=ortho.pixel_m, colour=colour,
                      depth=ortho.depth, mask=ortho.mask)


def illumination_field(ortho: Orthoimage, settings: ColourPrepSettings | None = None
                       ) -> tuple[np.ndarray | None, np.ndarray]:
    """(field (H, W, 3) float32, reference wall colour (3,)) or (None, zeros) without wall."""
    s = settings or ColourPrepSettings()
    h, w = ortho.shape
    g = max(1, int(round(s.cell_m / ortho.pixel_m)))
    hc, wc = math.ceil(h / g), math.ceil(w / g)
    col = np.full((hc * g, wc * g, 3), np.nan, np.float32)  # NaN: no data; the pixels with data copied in
    np.copyto(col[:h, :w], ortho.colour, where=ortho.mask[..., None])
    dep = np.full((hc * g, wc * g), np.nan, np.float32)
    np.copyto(dep[:h, :w], ortho.depth, where=ortho.mask)
    col_b = col.reshape(hc, g, wc, g, 3).transpose(0, 2, 1, 3, 4).reshape(hc, wc, g * g, 3)
    dep_b = dep.reshape(hc, g, wc, g).transpose(0, 2, 1, 3).reshape(hc, wc, g * g)
    cnt = np.isfinite(dep_b).sum(axis=2)
    valid = cnt >= max(1, s.min_cell_fraction * g * g)
    if not valid.any():
        return None, np.zeros(3)
    cell_col = np.zeros((hc, wc, 3), np.float32)
    cell_dep = np.zeros((hc, wc), np.float32)
    cell_col[valid] = _median_valid(col_b[valid], cnt[valid])
    cell_dep[valid] = _median_valid(dep_b[valid][..., None], cnt[valid])[:, 0]
    mixed = _mixed_fraction(col_b, dep_b, cell_col, cell_dep, valid, s=s)
    wall = _wall_cells(cell_col, cell_dep, valid, s, mixed)
    if not wall.any():
        return None, np.zeros(3)
    ref = np.median(cell_col[wall], axis=0)
    # fill non-wall cells from the nearest wall cell, then a step-preserving median
    _, (ii, jj) = ndimage.distance_transform_edt(~wall, return_indices=True)
    filled = cell_col[ii, jj]
    k = max(1, int(round(s.illumination_window_m / s.cell_m)))
    k += 1 - k % 2
    if k > 1:
        filled = _median_blur(filled, k)
    field = _upsample(filled, ortho.colour.astype(np.float32), ortho.mask, g=g, shape=(h, w),
                      snap=s.snap_tolerance)
    return field, ref.astype(np.float32)


def _median_blur(cells: np.ndarray, k: int) -> np.ndarray:
    """Each channel of ``cells`` (H, W, 3) float32 median-filtered over a ``k`` x ``k`` window,
    edges repeated (``ndimage.median_filter(..., mode="nearest")`` per channel).

    OpenCV filters float32 in one pass over the three channels for a window of 3 or 5
    (a selection among the window's values, as exact as scipy's); other sizes, and NaNs
    (which the two order differently), use scipy.
    """
    if k in (3, 5) and cells.dtype == np.float32 and np.isfinite(cells).all():
        return cv2.medianBlur(np.ascontiguousarray(cells), k)  # cv2's border: replicated, scipy's "nearest"
    return np.stack([ndimage.median_filter(cells[..., ch], size=k, mode="nearest") for ch in range(3)], axis=-1)


def _median_valid(values: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Median over axis 1 of (k, n, c) values whose NaNs (no data) are ignored; count = valid per row."""
    srt = np.sort(values, axis=1)  # NaN sorts last
    lo = ((count - 1) // 2)[:, None, None]
    hi = (count // 2)[:, None, None]
    shape = (len(values), 1, values.shape[2])
    a = np.take_along_axis(srt, np.broadcast_to(lo, shape), axis=1)[:, 0]
    b = np.take_along_axis(srt, np.broadcast_to(hi, shape), axis=1)[:, 0]
    return 0.5 * (a + b)


def _chroma(rgb: np.ndarray) -> np.ndarray:
    """rg-chromaticity (r, g) / (r + g + b) of (..., 3) colours: independent of the illumination's gain."""
    total = rgb[..., 0] + rgb[..., 1] + rgb[..., 2]  # as rgb.sum(axis=-1) adds them, without its slow reduction
    return rgb[..., :2] / np.maximum(total[..., None], 1.0)


def _mixed_fraction(col_b: np.ndarray, dep_b: np.ndarray, cell_col: np.ndarray, cell_dep: np.ndarray,
                    valid: np.ndarray, *, s: ColourPrepSettings) -> np.ndarray:
    """Per cell, the share of its pixels whose chromaticity or depth differs from the cell's median.

    A cell of plain wall is uniform under any illumination: a station step or a smooth
    light gradient changes every channel by the same gain, so the chromaticity stays put.
    A cell that holds part of an object's outline or its print (a sign's text band whose
    median colour is close to the wall's) has a share of pixels of another chromaticity or
    depth; such cells must not be taken as samples of the illumination.
    """
    out = np.ones(valid.shape, np.float32)
    if not valid.any():
        return out
    pix = col_b[valid]  # (k, n, 3), NaN where no data
    ok = np.isfinite(pix[..., 0])
    dch = _chroma(np.nan_to_num(pix)) - _chroma(cell_col[valid])[:, None, :]
    dc = np.sqrt(dch[..., 0] * dch[..., 0] + dch[..., 1] * dch[..., 1])  # np.linalg.norm's sum, without its reduction
    dd = np.abs(np.nan_to_num(dep_b[valid]) - cell_dep[valid][:, None])
    odd = ok & ((dc > s.chroma_tolerance) | (dd > s.wall_depth_tolerance_m))
    out[valid] = np.count_nonzero(odd, axis=1) / np.maximum(np.count_nonzero(ok, axis=1), 1)
    return out


def _wall_cells(cell_col: np.ndarray, cell_dep: np.ndarray, valid: np.ndarray, s: ColourPrepSettings,
                mixed: np.ndarray | None = None) -> np.ndarray:
    """Cells that show plain (lit) wall: flat, uniform, and of the wall's chromaticity or highlight-white.

    ``mixed`` is each cell's share of pixels of another chromaticity or depth
    (``_mixed_fraction``); cells above ``mixed_fraction`` (or, on a noisy wall,
    ``mixed_noise_factor`` x the typical share of the flat cells) hold an object's edge or
    print and are left out, so the field is never taken from inside an object.
    """
    flat = valid & (np.abs(cell_dep) <= s.wall_depth_tolerance_m)
    if not flat.any():
        return flat
    chroma = _chroma(cell_col)
    ref_chroma = np.median(chroma[flat], axis=0)
    close = np.linalg.norm(chroma - ref_chroma, axis=-1) <= s.chroma_tolerance
    vmax = cell_col.max(axis=-1)
    sat = 1.0 - cell_col.min(axis=-1) / np.maximum(vmax, 1.0)
    white = (vmax >= 255.0 * s.highlight_value) & (sat <= s.highlight_saturation)
    wall = flat & (close | white)
    if mixed is not None and s.mixed_fraction < 1.0 and wall.any():
        limit = max(s.mixed_fraction, s.mixed_noise_factor * float(np.median(mixed[wall])))
        wall &= mixed <= limit
    return wall


def _upsample(cells: np.ndarray, colour: np.ndarray, mask: np.ndarray, *, g: int, shape: tuple[int, int],
              snap: float) -> np.ndarray:
    """Cell field to pixels: bilinear, except near steps of the field (station boundaries).

    In cells whose neighbourhood holds a step, a wall-coloured pixel takes the field of the
    neighbouring cell that explains its colour best (within ``snap``), so that the step
    stays sharp inside the cell; other pixels keep the bilinear field.
    """
    h, w = shape
    hc, wc = cells.shape[:2]
    field = cv2.resize(cells, (wc * g, hc * g), interpolation=cv2.INTER_LINEAR)[:h, :w]
    pad = np.pad(cells, ((1, 1), (1, 1), (0, 0)), mode="edge")
    nb = np.stack([pad[1 + dr: 1 + dr + hc, 1 + dc: 1 + dc + wc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)])
    spread = np.abs(nb / np.maximum(cells[None], 1.0) - 1.0).max(axis=(0, 3))
    step = spread > snap / 4
    if not step.any():
        return field
    rows, cols = np.nonzero(np.repeat(np.repeat(step, g, axis=0), g, axis=1)[:h, :w] & mask)
    cand = nb[:, rows // g, cols // g]  # (9, k, 3)
    ratio = colour[rows, cols][None] / np.maximum(cand, 1.0)
    err = np.abs(ratio - 1.0).max(axis=-1)  # (9, k)
    best = np.argmin(err, axis=0)
    take = err[best, np.arange(len(best))] <= snap
    field = field.copy()
    field[rows[take], cols[take]] = cand[best[take], np.flatnonzero(take)]
    return field
