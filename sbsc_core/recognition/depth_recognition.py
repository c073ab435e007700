"""Recognition with geometry (paper, section 4.2, Algorithm I).

Two stages on the depth image J_D of one wall:

1. **RoIs.** A Canny filter on J_D finds the depth discontinuities; closed boundary
   regions become rectangles, and overlapping rectangles (parts of one complex object)
   are clustered into one RoI (paper, Figure 3).
2. **Matching.** Every expected class's depth model is cross-correlated with the RoIs
   (normalised cross-correlation, ``cv2.TM_CCOEFF_NORMED``); matches with a coefficient
   rho_D >= mu_D (0.75) form the candidate list {D} of the class, with the position of the
   best match (paper, Figure 4).

Additions to the paper, each a named setting:

* Canny's two thresholds are physical (a fraction of ``min_relief_m`` per pixel, raised to
  ``noise_k`` sigmas of the gradient noise measured on the plain wall) instead of Matlab's
  automatic ones, so plain noisy walls produce no edges; the regions standing out by more
  than ``min_relief_m`` (or ``noise_k`` sigmas) are added to the edge map, so smooth reliefs
  whose outline is soft still give a RoI.
* No-data pixels and openings are set to the wall plane (0 m) so that holes in the scan
  do not create discontinuities (the paper's Figure 16 problem), and a residual plane
  fitted to the visible wall is removed.
* Each depth model is padded with a border of wall plane (``template_pad_px``): a model
  then only correlates where the object stands alone on the wall, not on a part of a
  larger object with a similar local shape.
* Depth is metric, so the relief amplitude must agree as well: the least-squares gain
  between scene and model must lie in ``gain_range`` (the correlation alone is blind to
  scale in depth).
* Models are also tried rotated in the wall plane (``rotations``), lifting the paper's
  stated limitation that depth matching is not rotation invariant; several instances per
  RoI are found by non-maximum suppression on the correlation map.
* Unseen wall (no depth data reaching the image's border, e.g. below a scanner's field of
  view) is unknown, not wall: a footprint partly seen is also correlated over its seen
  pixels only (masked NCC), needs ``min_known_share`` of it seen, and the plausibility
  checks ignore unseen pixels.
* An object made of parts that do not touch (a radiator's columns with the wall showing
  between them) gives a RoI per part: each model is also searched around the groups of
  RoIs that fit together in its footprint (:func:`~sbsc_core.recognition.matching.group_boxes`, parts
  at most ``part_gap_fraction`` of the model's shorter side apart), whose centre may lie
  in a gap, out of reach of a search around any one part.
* A see-through object (a tube radiator) shows the wall between its parts in the model's
  front view, but its own sides in an oblique scan: a model whose relief encloses gaps
  where the wall shows (below ``see_through_fraction`` of its relief: not a recess of
  the object itself) is also tried with them closed (:func:`close_see_through`).
* A slowly varying level of the plain wall (a step of a few mm where a misregistered
  station alone sees the wall) is subtracted before relief is thresholded for RoIs and
  the plausibility checks; the correlation keeps the scene's own relief.
* Furniture standing close in front of the wall (a desk's modesty panel and legs, a bin, a
  chair) lies within the wall's depth band and makes one RoI, much larger than any model,
  with the objects beside it. Matching inside that RoI is by depth layers
  (:func:`model_view`): relief beyond ``foreground_factor`` x a model's peak, with its edge
  (:func:`foreground_source`), is another object in front, unknown to that model (masked
  NCC, plausibility checks on the rest). A match must then be seen over its footprint (not
  behind the object) and, as that side's isolation is unverified, correlate at least
  ``foreground_mu_d``.
* In the shadow of furniture the wall is seen sparsely, through gaps, and the mixed pixels
  of the furniture's edges scatter relief blobs over it; the sampling gaps and holes are
  filled, so such a patch looks known. A match whose window (its footprint with the side
  strips) is seen on less than ``min_seen_share`` of the wall's own share of seen pixels
  (:func:`seen_share`: pixels with points or inside an object's own solid occlusion
  shadow; openings and unseen wall reaching the border are not seen) stands on
  interpolated data and unverified surroundings: like a match beside an object in front,
  it must correlate at least ``foreground_mu_d``.
* A kept match's position (``Candidate.position``, used for placement) is read from its
  relief's sharp edges (:mod:`~sbsc_core.recognition.edge_position`, ``sharp_edge_position``): seen
  obliquely, one side of an object trails into its occlusion shadow (mixed pixels) and the
  correlation's centre leans into that ramp by a few mm.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import ndimage

from ..settings import DepthRecognitionSettings
from ..types import Box, Candidate, Orthoimage, WallArea
from .edge_position import EdgeSettings, sharp_edge_centre
from .matching import (
    box_at,
    boxes_from_mask,
    cluster_boxes,
    crop_padded,
    estimate_turn,
    group_boxes,
    match_in_rois,
    nms,
    padded_template,
    rotate_template,
    rotated_variants,
    turn_angles,
)
from .medians import median
from .templates import ModelTemplate

_DEPTH_UNIT_M = 1e-5  # int16 gradient unit for cv2.Canny(dx, dy, ...)
_LEVEL_EDGE_PX = 2  # wall level: pixels this close to relief (an object's sloped edge) are no plain wall
_GAP_PX = 2  # seen share: the visible wall's own sampling gaps reach this far from its pixels with data


# --------------------------------------------------------------------------- J_D


def fill_gaps(values: np.ndarray, ok: np.ndarray, sigma_px: float, min_weight: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Fill small gaps of a sparse image by normalised convolution (Gaussian ``sigma_px``).

    ``values`` is (H, W) or (H, W, C); pixels outside ``ok`` whose Gaussian-weighted share of
    known neighbours is at least ``min_weight`` get the weighted mean of those neighbours.
    Returns (filled float32 values, new ok mask); larger holes are left as they are.
    """
    if sigma_px <= 0 or ok.all() or not ok.any():
        return np.asarray(values, np.float32), ok
    w = cv2.GaussianBlur(ok.astype(np.float32), (0, 0), sigma_px)
    v = np.where(ok[..., None] if values.ndim == 3 else ok, values, 0).astype(np.float32, copy=False)
    num = cv2.GaussianBlur(v, (0, 0), sigma_px)
    fill = ~ok & (w >= min_weight)
    out = np.array(values, np.float32)  # a copy
    den = np.maximum(w, 1e-6)
    # the quotient at the pixels to fill only (np.take of flat indices: as (num / den)[fill])
    at = np.flatnonzero(fill)
    n = fill.size
    out.reshape(n, -1)[at] = np.take(num.reshape(n, -1), at, axis=0) / np.take(den.reshape(n), at)[:, None]
    return out, ok | fill


def depth_image(ortho: Orthoimage, area: WallArea, settings: DepthRecognitionSettings) -> np.ndarray:
    """The depth image J_D: metres out of the wall plane, openings at 0 (see :func:`depth_image_known`)."""
    return depth_image_known(ortho, area, settings)[0]


def depth_image_known(ortho: Orthoimage, area: WallArea, settings: DepthRecognitionSettings
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(J_D, known): J_D in metres out of the wall plane, openings at 0; ``known`` marks its
    pixels that have depth data (after the gap filling), lie in a hole enclosed by data
    (filled from its rim: a shadow beside an object, a socket's recess, whose fill is a
    good guess and tells classes apart) or in an opening (no wall, hence no object: 0).
    Only no-data regions reaching the image's border (wall the scanner did not see, e.g.
    below its field of view) are unknown.

    Sampling gaps of a sparse scan are filled from their neighbours (``gap_fill_sigma_px``)
    and each larger hole (an occlusion shadow beside an object, an unseen recess in it)
    takes the lowest relief found around it, so holes neither break an object's relief
    nor create false discontinuities (the paper's Figure 16 problem). A residual plane
    fitted to the visible wall is removed and a median filter takes out speckle.
    """
    d = np.asarray(ortho.depth, np.float32)
    ok = np.isfinite(d)
    opening = np.zeros(d.shape, bool)
    if area.opening_mask is not None and area.opening_mask.shape == d.shape:
        opening = area.opening_mask
    ok &= ~opening
    d, ok = fill_gaps(np.where(ok, d, 0.0), ok, settings.gap_fill_sigma_px, settings.gap_fill_min_weight)
    ok &= ~opening
    out = np.where(ok, d, 0.0).astype(np.float32)
    if settings.refit_plane:
        plane = _residual_plane(out, ok & area.visible if area.visible.shape == d.shape else ok)
        if plane is not None:
            out = np.where(ok, out - plane, 0.0).astype(np.float32)
    out = fill_holes_low(out, ok, ~ok & ~opening)
    if settings.median_px in (3, 5):  # speckle (outliers, isolated no-data pixels) off
        out = cv2.medianBlur(out, settings.median_px)
    return np.where(opening, 0.0, out).astype(np.float32), ok | opening | _enclosed(~ok & ~opening)


def _enclosed(holes: np.ndarray) -> np.ndarray:
    """The 8-connected regions of ``holes`` that do not reach the image's border."""
    lab, n = ndimage.label(holes, structure=np.ones((3, 3), bool))
    if n == 0:
        return np.zeros_like(holes)
    edge = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    return (lab > 0) & ~np.isin(lab, edge)


def fill_holes_low(values: np.ndarray, ok: np.ndarray, holes: np.ndarray) -> np.ndarray:
    """Fill each 8-connected hole with the lowest (lightly smoothed) value on its 1-pixel rim.

    A shadow cast on the wall beside a protruding object is bounded by wall and object: its
    rim minimum is the wall. A hole inside an object's face is bounded by that face. Holes
    with no known rim stay 0.
    """
    if not holes.any():
        return values
    lab, n = ndimage.label(holes, structure=np.ones((3, 3), bool))
    rim = ndimage.grey_dilation(lab, size=(3, 3)) * (ok & ~holes)
    sm = cv2.GaussianBlur(np.where(ok, values, 0).astype(np.float32), (0, 0), 1.0)
    w = cv2.GaussianBlur(ok.astype(np.float32), (0, 0), 1.0)
    sm = np.where(w > 1e-3, sm / np.maximum(w, 1e-3), 0.0)
    on = rim > 0
    low = np.asarray(ndimage.minimum(sm[on], labels=rim[on], index=np.arange(1, n + 1)), np.float64)
    low = np.nan_to_num(low, nan=0.0)
    out = values.copy()
    out[holes] = low[lab[holes] - 1]
    return out


def wall_level(jd: np.ndarray, known: np.ndarray, pixel_m: float, settings: DepthRecognitionSettings
               ) -> np.ndarray:
    """The local level of the plain wall in J_D (metres), 0 where the wall lies on the plane.

    Two stations registered a few mm apart see one wall at two depths: where only one of
    them sees it, J_D has a step that the relief thresholds take for an object, merging the
    objects on it into one RoI and failing their isolation. The level is the mean of the
    plain-wall pixels (known, within ``level_plain_m`` of the plane, not beside relief above
    it) per ``level_cell_m`` cell, then the median of the cells in ``level_window_m`` (an
    object smaller than half the window does not move it), shrunk towards 0 by
    ``level_dead_m`` (a clean wall gets exactly 0: its results do not change) and clamped
    to ``level_max_m``. A region of non-zero level shorter than ``level_min_extent_m`` is a
    large flat object (a sign covering most of a window), not a step: it is set to 0.
    """
    h, w = jd.shape
    g = max(1, int(round(settings.level_cell_m / pixel_m)))
    k = max(0, int(round(settings.level_window_m / settings.level_cell_m)) // 2)
    hb, wb = -(-h // g), -(-w // g)
    if settings.level_max_m <= 0 or min(hb, wb) < 1:
        return np.zeros_like(jd)
    high = (np.abs(jd) >= settings.level_plain_m).astype(np.uint8)
    edge = np.ones((2 * _LEVEL_EDGE_PX + 1,) * 2, np.uint8)
    plain = known & (cv2.dilate(high, edge) == 0)
    vals = np.zeros((hb * g, wb * g), np.float64)
    use = np.zeros((hb * g, wb * g), np.float64)
    vals[:h, :w] = np.where(plain, jd, 0.0)
    use[:h, :w] = plain
    count = use.reshape(hb, g, wb, g).sum(axis=(1, 3))
    cell = np.full((hb, wb), np.nan, np.float32)
    enough = count >= settings.level_min_share * g * g
    if not enough.any():
        return np.zeros_like(jd)
    cell[enough] = (vals.reshape(hb, g, wb, g).sum(axis=(1, 3)) / np.maximum(count, 1))[enough]
    if not np.any(np.abs(cell[enough]) > settings.level_dead_m):  # a clean wall (the usual case)
        return np.zeros_like(jd)
    pad = np.pad(cell, k, constant_values=np.nan)
    stack = np.stack([pad[i:i + hb, j:j + wb] for i in range(2 * k + 1) for j in range(2 * k + 1)])
    has = np.isfinite(stack).any(axis=0)
    level = np.zeros((hb, wb), np.float32)
    if has.any():
        level[has] = np.nanmedian(stack[:, has], axis=0)
    level = np.sign(level) * np.clip(np.abs(level) - settings.level_dead_m, 0.0, settings.level_max_m)
    level = _long_only(level, max(1, int(round(settings.level_min_extent_m / settings.level_cell_m))))
    lab, _ = ndimage.label(level != 0, structure=np.ones((3, 3), bool))
    for i, sl in enumerate(ndimage.find_objects(lab), start=1):
        if max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start) * g * pixel_m < settings.level_min_extent_m:
            level[sl][lab[sl] == i] = 0.0  # a compact flat object (a sign), no step of the wall
    if not level.any():
        return np.zeros_like(jd)
    full = cv2.resize(level.astype(np.float32), (wb * g, hb * g), interpolation=cv2.INTER_LINEAR)
    return np.ascontiguousarray(full[:h, :w])


def _long_only(level: np.ndarray, n: int) -> np.ndarray:
    """The level where it is part of a raised (or sunk) stretch at least ``n`` cells long
    across or down: the grey opening with an ``n``-cell line, the larger of the two
    directions, of the level above and below the plane. A flat sign of a few mm, larger than
    half the median window, raises the level in its middle; the steps of a misregistered
    station are long. Without it, a sign on a wall with such a step loses half its relief."""
    out = np.zeros_like(level, dtype=np.float32)
    for sign in (1.0, -1.0):
        part = np.ascontiguousarray(np.clip(sign * level, 0.0, None), np.float32)
        if not part.any():
            continue
        across = cv2.morphologyEx(part, cv2.MORPH_OPEN, np.ones((1, n), np.uint8), borderType=cv2.BORDER_REPLICATE)
        down = cv2.morphologyEx(part, cv2.MORPH_OPEN, np.ones((n, 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
        out += sign * np.maximum(across, down)
    return out


def _residual_plane(d: np.ndarray, use: np.ndarray, max_samples: int = 20000) -> np.ndarray | None:
    """Robust least-squares plane d = a r + b c + e over ``use`` pixels (None if too few)."""
    rr, cc = np.nonzero(use)
    if rr.size < 100:
        return None
    if rr.size > max_samples:
        pick = np.random.default_rng(0).choice(rr.size, max_samples, replace=False)
        rr, cc = rr[pick], cc[pick]
    z = d[rr, cc].astype(np.float64)
    a = np.column_stack([rr, cc, np.ones_like(rr)]).astype(np.float64)
    keep = np.ones(z.size, bool)
    coef = np.zeros(3)
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(a[keep], z[keep], rcond=None)
        res = z - a @ coef
        mad = np.median(np.abs(res[keep] - np.median(res[keep]))) * 1.4826 + 1e-6
        keep = np.abs(res) < 3.0 * mad
        if keep.sum() < 50:
            return None
    h, w = d.shape
    r = np.arange(h, dtype=np.float32)[:, None]
    c = np.arange(w, dtype=np.float32)[None, :]
    return (coef[0] * r + coef[1] * c + coef[2]).astype(np.float32)


# --------------------------------------------------------------------------- RoIs


def _robust_sigma(x: np.ndarray) -> float:
    if x.size < 50:
        return 0.0
    return float(1.4826 * median(np.abs(x - median(x))))  # medians.median: np.median's value, faster


def _smooth(jd: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(jd, (0, 0), sigma) if sigma > 0 else jd


def relief_thresholds(jd: np.ndarray, wall: np.ndarray, settings: DepthRecognitionSettings
                      ) -> tuple[float, float]:
    """(relief threshold in m, Canny high threshold in m per pixel) for J_D.

    Each is the physical minimum from the settings, raised to ``noise_k`` robust sigmas of
    the smoothed depth / its gradient measured on the plain wall (``wall`` pixels), so a
    noisy scan does not turn into edges everywhere.
    """
    sm = _smooth(jd, settings.canny_sigma_px)
    gx = cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    relief = max(settings.min_relief_m, settings.noise_k * _robust_sigma(sm[wall]))
    grad = max(settings.canny_high_fraction * settings.min_relief_m, settings.noise_k * _robust_sigma(gx[wall]))
    return relief, grad


def relief_edges(jd: np.ndarray, settings: DepthRecognitionSettings, high_m_per_px: float | None = None
                 ) -> np.ndarray:
    """J_D,Canny: Canny edges of J_D with thresholds in metres of relief per pixel (bool)."""
    sm = _smooth(jd, settings.canny_sigma_px)
    gx = cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3) / 8.0  # metres per pixel
    gy = cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    dx = np.clip(np.round(gx / _DEPTH_UNIT_M), -32767, 32767).astype(np.int16)
    dy = np.clip(np.round(gy / _DEPTH_UNIT_M), -32767, 32767).astype(np.int16)
    if high_m_per_px is None:
        high_m_per_px = settings.canny_high_fraction * settings.min_relief_m
    high = high_m_per_px / _DEPTH_UNIT_M
    return cv2.Canny(dx, dy, settings.canny_low_ratio * high, high, L2gradient=True) > 0


@dataclass
class DepthImages:
    """What both depth stages read of one wall, computed once (:func:`depth_images`)."""

    jd: np.ndarray  # J_D (depth_image_known)
    known: np.ndarray  # its pixels with data, enclosed holes or openings
    levelled: np.ndarray  # J_D minus the local wall level (levelled)
    # (settings, their relief_thresholds of ``levelled``): the RoIs' and the matches' noise, computed once
    thresholds: tuple[DepthRecognitionSettings, tuple[float, float]] | None = field(
        default=None, repr=False, compare=False)


def depth_images(ortho: Orthoimage, area: WallArea, settings: DepthRecognitionSettings) -> DepthImages:
    """J_D, its known mask and J_D above the local wall level of one wall."""
    jd, known = depth_image_known(ortho, area, settings)
    return DepthImages(jd, known, levelled(jd, known, ortho, area, settings))


def depth_rois(ortho: Orthoimage, area: WallArea, settings: DepthRecognitionSettings,
               templates: dict[str, ModelTemplate] | None = None,
               images: DepthImages | None = None) -> list[Box]:
    """RoIs of J_D: closed regions of depth discontinuities, clustered (section 4.2).

    Relief within ``border_margin_m`` of the image's sides (where the wall meets the floor,
    the ceiling and the next walls) is no object. With the ``templates`` searched, a
    region longer than ``max_roi_factor`` times the largest model and thinner than half the
    smallest is dropped too (a pipe, a cable, a step in the plaster): such regions would
    otherwise merge the objects near them into one wall-sized RoI. A region longer than
    that which is not thin (a door frame joined to the skirting along the floor, whose box
    spans the wall) stays a RoI of its own but gathers no other region into its box: every
    object inside it keeps its own RoI instead of sharing one that holds at most
    ``max_peaks_per_roi`` instances of a class. ``images`` (of this wall) saves computing
    them again.
    """
    jd = (images or depth_images(ortho, area, settings)).levelled
    limits = None
    if templates:
        sides = [(t.height_px, t.width_px) for t in templates.values()]
        limits = (settings.max_roi_factor * max(max(s) for s in sides), 0.5 * min(min(s) for s in sides))
    margin = int(round(settings.border_margin_m / ortho.pixel_m))
    if images is not None:
        return _rois_from_jd(jd, None, settings, margin, limits,
                             thresholds=_levelled_thresholds(ortho, area, images, settings))
    return _rois_from_jd(jd, _plain_wall(ortho, area, jd, settings), settings, margin, limits)


def levelled(jd: np.ndarray, known: np.ndarray, ortho: Orthoimage, area: WallArea,
             settings: DepthRecognitionSettings) -> np.ndarray:
    """J_D minus the local wall level (:func:`wall_level`); openings stay at 0."""
    level = wall_level(jd, known, ortho.pixel_m, settings)
    if area.opening_mask is not None and area.opening_mask.shape == jd.shape:
        level[area.opening_mask] = 0.0
    return (jd - level).astype(np.float32)


def _plain_wall(ortho: Orthoimage, area: WallArea, jd: np.ndarray, settings: DepthRecognitionSettings
                ) -> np.ndarray:
    """Pixels for the noise estimate: scanned, near the plane and (if it is usable) visible wall."""
    wall = np.isfinite(ortho.depth) & (np.abs(jd) < settings.noise_window_m)
    if area.visible.shape == jd.shape and (wall & area.visible).sum() >= 100:
        wall &= area.visible
    return wall


def noise_relief(ortho: Orthoimage, area: WallArea, images: DepthImages,
                 settings: DepthRecognitionSettings) -> float:
    """The wall's noise relief (metres): the smallest relief told from its plain wall,
    ``min_relief_m`` raised to ``noise_k`` robust sigmas of the depth noise measured there
    (:func:`relief_thresholds` on the levelled J_D, as :func:`match_depth` uses it)."""
    return _levelled_thresholds(ortho, area, images, settings)[0]


def _levelled_thresholds(ortho: Orthoimage, area: WallArea, images: DepthImages,
                         settings: DepthRecognitionSettings) -> tuple[float, float]:
    """:func:`relief_thresholds` of the levelled J_D on its plain wall, kept on ``images``
    (the RoIs, the matches and the taught amplitudes of one wall read the same)."""
    if images.thresholds is None or images.thresholds[0] is not settings:
        wall = _plain_wall(ortho, area, images.levelled, settings)
        images.thresholds = (settings, relief_thresholds(images.levelled, wall, settings))
    return images.thresholds[1]


def _rois_from_jd(jd: np.ndarray, wall: np.ndarray | None, settings: DepthRecognitionSettings, margin_px: int = 0,
                  limits: tuple[float, float] | None = None, *,
                  thresholds: tuple[float, float] | None = None) -> list[Box]:
    """RoIs of ``jd``; ``thresholds``: :func:`relief_thresholds` of it on ``wall``, when known."""
    relief_m, grad_m = relief_thresholds(jd, wall, settings) if thresholds is None else thresholds
    edges = relief_edges(jd, settings, grad_m)
    relief = np.abs(_smooth(jd, settings.canny_sigma_px)) >= relief_m
    relief = cv2.morphologyEx(relief.astype(np.uint8), cv2.MORPH_OPEN, np.ones((2, 2), np.uint8)) > 0
    closed = cv2.morphologyEx((edges | relief).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    if margin_px > 0:
        inner = np.zeros_like(closed)
        inner[margin_px:-margin_px, margin_px:-margin_px] = 1
        closed &= inner
    boxes = boxes_from_mask(closed > 0, settings.roi_min_px)
    longest = None
    if limits is not None:
        longest, thinnest = limits
        boxes = [b for b in boxes if max(b.height, b.width) <= longest or min(b.height, b.width) >= thinnest]
    return cluster_boxes(boxes, settings.roi_merge_gap_px, settings.roi_merge_overlap, longest_px=longest)


# --------------------------------------------------------------------------- matching


def isolation(jd: np.ndarray, box: Box, threshold_m: float, gap_px: int, width_px: int,
              *, known: np.ndarray | None = None, min_known: float = 0.5, trails: bool = False) -> float:
    """The largest share, over the four sides of ``box``, of a strip of relief above ``threshold_m``.

    Each strip runs along one side at ``gap_px`` .. ``gap_px + width_px`` pixels outside the
    footprint (the gap leaves the object's own blurred edge out). An object standing alone
    on the wall has flat strips (share ~0); a model matched on a part of something larger
    (a door casing, one half of a double socket) has relief continuing into a strip. With
    ``known``, the share is over a strip's known pixels, and a strip with less than
    ``min_known`` of them known is unknown (it counts as 0, like an unseen strip).

    With ``trails``, a side whose relief falls away from the footprint at every pixel until
    it is below ``threshold_m``, within the footprint's own extent across that side, is a
    trail, not something larger (it counts as 0; :func:`is_trail`): a scanner seeing a deep
    object obliquely returns mixed ranges between its front and the wall behind, a ramp down
    to the wall beside one edge, while a larger object's relief levels off or rises again.
    """
    out = 0.0
    g, wd = gap_px, width_px
    sides = (Box(box.r0 - g - wd, box.c0, box.r0 - g, box.c1), Box(box.r1 + g, box.c0, box.r1 + g + wd, box.c1),
             Box(box.r0, box.c0 - g - wd, box.r1, box.c0 - g), Box(box.r0, box.c1 + g, box.r1, box.c1 + g + wd))
    for k, sb in enumerate(sides):
        strip = crop_padded(jd, sb.r0, sb.r1, sb.c0, sb.c1)
        if not strip.size:
            continue
        stands = np.abs(strip) > threshold_m
        if known is None:
            share = float(np.mean(stands))
        else:
            kn = crop_padded(known, sb.r0, sb.r1, sb.c0, sb.c1)
            nk = int(np.count_nonzero(kn))
            share = float(np.count_nonzero(stands & kn)) / nk if nk and nk >= min_known * kn.size else 0.0
        if share <= out:
            continue
        reach = box.height if k < 2 else box.width
        if trails and is_trail(_outward_profile(jd, box, k, g, g + reach), threshold_m):
            continue
        out = share
    return out


def _outward_profile(jd: np.ndarray, box: Box, side: int, start_px: int, stop_px: int) -> np.ndarray:
    """The mean relief of each line parallel to side ``side`` of ``box`` (0 top, 1 bottom, 2 left,
    3 right), from ``start_px`` to ``stop_px`` (excluded) pixels outside it, nearest first."""
    if side == 0:
        return crop_padded(jd, box.r0 - stop_px, box.r0 - start_px, box.c0, box.c1).mean(axis=1)[::-1]
    if side == 1:
        return crop_padded(jd, box.r1 + start_px, box.r1 + stop_px, box.c0, box.c1).mean(axis=1)
    if side == 2:
        return crop_padded(jd, box.r0, box.r1, box.c0 - stop_px, box.c0 - start_px).mean(axis=0)[::-1]
    return crop_padded(jd, box.r0, box.r1, box.c1 + start_px, box.c1 + stop_px).mean(axis=0)


def is_trail(profile: np.ndarray, threshold_m: float) -> bool:
    """Whether a relief ``profile`` (nearest line first, as :func:`_outward_profile`) is a ramp
    down to the wall: its magnitude falls at every step until it is below ``threshold_m``
    (a larger object's relief levels off or rises again before that)."""
    p = np.abs(np.asarray(profile, float))
    if p.size < 2 or p[0] <= threshold_m:
        return False
    for k in range(1, p.size):
        if not np.isfinite(p[k]) or p[k] >= p[k - 1]:
            return False
        if p[k] <= threshold_m:
            return True
    return False


def relief_overlap(jd: np.ndarray, model: np.ndarray, box: Box, pad_px: int, threshold_m: float,
                   *, gain: float, known: np.ndarray | None = None) -> float:
    """Intersection over union of where the model and the scene stand out by ``threshold_m``.

    ``model`` is the padded (and smoothed) depth model over ``box`` grown by ``pad_px``; the
    scene's threshold is scaled by the match's ``gain``. The correlation alone tolerates a
    footprint of the wrong size (a 12 cm plate on an 8 cm socket); this does not. With
    ``known``, only the known pixels are compared (an unseen part is neither relief nor wall).
    """
    patch = crop_padded(jd, box.r0 - pad_px, box.r1 + pad_px, box.c0 - pad_px, box.c1 + pad_px)
    if patch.shape != model.shape:
        return 0.0
    sign = 1.0 if float(np.sum(model)) >= 0 else -1.0
    m = sign * model > threshold_m
    s = sign * patch > threshold_m * max(gain, 1e-6)
    if known is not None:
        k = crop_padded(known, box.r0 - pad_px, box.r1 + pad_px, box.c0 - pad_px, box.c1 + pad_px)
        m &= k
        s &= k
    union = int(np.count_nonzero(m | s))
    return float(np.count_nonzero(m & s)) / union if union else 0.0


def face_region(model: np.ndarray, edge_px: int) -> np.ndarray:
    """Where ``model`` stands out (over a tenth of its peak), ``edge_px`` off its outline.

    At least that much of an object's outline is blurred in a scan (the smoothing, mixed
    pixels); a model too small to erode keeps its whole footprint. See :func:`face_gain`.
    """
    m = np.abs(np.nan_to_num(model))  # unknown parts of a model: not its face
    peak = float(m.max()) if m.size else 0.0
    if peak <= 0:
        return np.zeros(model.shape, bool)
    stands = m > 0.1 * peak
    inner = ndimage.binary_erosion(stands, iterations=edge_px) if edge_px > 0 else stands
    return inner if np.count_nonzero(inner) >= 4 else stands


def face_gain(relief: np.ndarray, model: np.ndarray, box: Box, *, region: np.ndarray,
              known: np.ndarray | None = None) -> float | None:
    """The scene's relief over the model's on the model's face (``region``, :func:`face_region`).

    The match's ``gain`` (least squares over the padded window, :func:`least_squares_gain`)
    weighs the wall ring around the footprint most, because a deep model's window mean
    lies near its face: there a scan's mixed pixels and their trails, which stand out by a
    share of the object's depth, widen its relief by a few pixels, and a right 12 cm panel
    whose face stands out exactly as far as its model's comes out at half its depth. Here
    only the model's face counts, away from its outline: the least-squares amplitude,
    without an offset, of ``relief`` (metres out of the local wall, so the wall is 0) over
    ``model`` on ``region``'s ``known`` pixels. It tells how far the object's face stands
    out against its model's, whatever its outline does. None when nothing is left.

    Parameters
    ----------
    relief : (H, W) relief out of the local wall (J_D levelled and smoothed), metres.
    model : (h, w) the matched (turned) depth model, metres.
    box : the footprint, ``h`` x ``w`` pixels of ``relief``.
    region : (h, w) bool, the model's face (:func:`face_region`).
    known : (H, W) bool, the pixels with data (None: all).
    """
    patch = crop_padded(relief, box.r0, box.r1, box.c0, box.c1)
    if patch.shape != model.shape or region.shape != model.shape:
        return None
    inner = region if known is None else region & crop_padded(known, box.r0, box.r1, box.c0, box.c1).astype(bool)
    m = np.nan_to_num(model[inner]).astype(np.float64)
    mm = float(m @ m)
    return float(m @ patch[inner].astype(np.float64)) / mm if m.size >= 2 and mm > 0 else None


@dataclass
class ModelView:
    """What one depth model is matched on: the correlated image and the known mask."""

    image: np.ndarray  # J_D smoothed (correlated), other objects in front at the wall plane
    known: np.ndarray  # pixels with data that are not another object in front
    front: np.ndarray | None = None  # the other objects in front with their edges (None: none)
    # what the correlation around each RoI needs of this image alone, by RoI and window
    # size: shared by the templates matched on it (match_in_rois's ``windows``)
    windows: dict = field(default_factory=dict, repr=False, compare=False)

    def front_share(self, box: Box) -> float:
        """The share of ``box`` covered by objects in front (0 without any)."""
        if self.front is None:
            return 0.0
        part = crop_padded(self.front, box.r0, box.r1, box.c0, box.c1)
        return float(np.mean(part)) if part.size else 0.0


def foreground_source(relief: np.ndarray, edge_m_per_px: float, max_edge_px: int, floor_m: float = 0.0
                      ) -> np.ndarray:
    """For each pixel, the highest relief (absolute, metres) from which it is reached down an
    edge: the pixel itself, or a pixel at most ``max_edge_px`` 4-connected steps away from
    which every step falls by at least ``edge_m_per_px`` (a depth discontinuity; :func:`match_depth`
    takes ``min_relief_m`` per pixel, so the soft tail of the blur that runs on into an object
    the foreground touches is not taken).

    ``foreground_source(...) > limit`` is the foreground above ``limit`` together with its
    edges (:func:`model_view`): the ramp of mixed pixels and blur of a desk panel or a bin
    down towards the wall belongs to it, up to where the relief levels off (the wall, or
    an object the panel stands against). Computed once per wall for every limit at least
    ``floor_m`` (only the pixels within ``max_edge_px`` of relief above it are worked on).
    """
    mag = np.abs(relief).astype(np.float32)
    src = mag.copy()
    if max_edge_px <= 0 or mag.size == 0:
        return src
    seeds = mag > floor_m
    if not seeds.any():
        return src
    near = cv2.dilate(seeds.astype(np.uint8), np.ones((2 * max_edge_px + 1,) * 2, np.uint8))
    lab, _ = ndimage.label(near)
    for sl in ndimage.find_objects(lab):
        np.maximum(src[sl], _propagate_down(mag[sl], edge_m_per_px, max_edge_px), out=src[sl])
    return src


def _propagate_down(mag: np.ndarray, edge_m_per_px: float, steps: int) -> np.ndarray:
    """:func:`foreground_source` on one window (dense, ``steps`` 4-neighbour iterations)."""
    src = mag.copy()
    down = mag[:-1] - mag[1:] >= edge_m_per_px  # pixel r + 1 lies an edge below pixel r
    up = mag[1:] - mag[:-1] >= edge_m_per_px
    right = mag[:, :-1] - mag[:, 1:] >= edge_m_per_px
    left = mag[:, 1:] - mag[:, :-1] >= edge_m_per_px
    for _ in range(steps):
        new = src.copy()
        np.maximum(new[1:], np.where(down, src[:-1], 0.0), out=new[1:])
        np.maximum(new[:-1], np.where(up, src[1:], 0.0), out=new[:-1])
        np.maximum(new[:, 1:], np.where(right, src[:, :-1], 0.0), out=new[:, 1:])
        np.maximum(new[:, :-1], np.where(left, src[:, 1:], 0.0), out=new[:, :-1])
        if np.array_equal(new, src):
            break
        src = new
    return src


@dataclass
class ForegroundRegions:
    """The connected foreground regions above one limit (:func:`foreground_regions`)."""

    labels: np.ndarray  # (H, W) int32: region number, 0 outside
    beyond: np.ndarray  # per region number: its pixels beyond the limit (index 0: none)


def foreground_regions(source: np.ndarray, relief: np.ndarray, limit_m: float) -> ForegroundRegions | None:
    """The 4-connected regions of ``source > limit_m`` (foreground with its edges,
    :func:`foreground_source`) and how many of their pixels stand out beyond ``limit_m``
    in ``relief``; None when there is none."""
    deep = source > limit_m
    if not deep.any():
        return None
    lab, n = ndimage.label(deep)
    return ForegroundRegions(lab, np.bincount(lab[np.abs(relief) > limit_m], minlength=n + 1))


def model_view(jm: np.ndarray, known: np.ndarray, regions: ForegroundRegions | None, min_area_px: int = 0
               ) -> ModelView:
    """The image and known mask one depth model is matched on (:func:`match_depth`), by depth layers.

    An object's relief is bounded by its model's depth (times the largest gain a match may
    have): a surface standing out much further than that (the limit of ``regions``,
    ``foreground_factor`` x the model's peak) is another object in front of the wall, a
    different depth layer: a desk's modesty panel or legs, a bin, a chair. With its edges
    (:func:`foreground_source`) it is unknown to this model, like an unseen pixel (the NCC
    is then taken over the known pixels, an extension of the paper's correlation in a RoI
    window, and the plausibility checks ignore it), and at the wall plane in the correlated
    image. Beside a desk panel or a bin, a fully visible socket then stands alone on its
    wall: the panel's relief no longer dominates the correlation window nor fills the side
    strips of the isolation check. An object mostly behind the foreground still needs
    ``min_known_share`` of its footprint seen.

    Only furniture counts: a region with fewer than ``min_area_px`` pixels beyond the limit
    (the model's footprint) is small, a hook on a rail, a knob, perhaps a part of something
    the model would match: it stays known.
    """
    if regions is None:
        return ModelView(jm, known)
    large = regions.beyond >= max(min_area_px, 1)
    large[0] = False
    if not large.any():
        return ModelView(jm, known)
    deep = large[regions.labels]
    return ModelView(np.where(deep, np.float32(0.0), jm), known & ~deep, deep)


@dataclass
class SeenShare:
    """Where one wall's orthoimage is seen (:func:`seen_share`), to measure windows."""

    table: np.ndarray  # (H + 1, W + 1) integral image of the seen pixels
    wall_share: float  # the share of the visible wall's pixels that are seen

    def of(self, box: Box) -> float:
        """The share of ``box``'s pixels inside the image that are seen, relative to the
        wall's own share (1: seen as densely as the wall; 1 for a box outside the image)."""
        h, w = self.table.shape[0] - 1, self.table.shape[1] - 1
        r0, r1, c0, c1 = max(box.r0, 0), min(box.r1, h), max(box.c0, 0), min(box.c1, w)
        if r1 <= r0 or c1 <= c0 or self.wall_share <= 0:
            return 1.0
        n = (r1 - r0) * (c1 - c0)
        t = self.table
        seen = float(t[r1, c1] - t[r0, c1] - t[r1, c0] + t[r0, c0])
        return seen / n / self.wall_share


def seen_share(ortho: Orthoimage, area: WallArea) -> SeenShare:
    """Where ``ortho`` is seen (:class:`SeenShare`) and the share of it on the visible wall.

    A pixel is seen when it holds scan points (before any gap is filled), or when it lies
    inside a solid hole enclosed by data (all of its 3 x 3 neighbours empty too): an object's
    own occlusion shadow or an unseen recess, which the data around explains. The lattice of
    sampling gaps of a patch seen only through gaps (furniture's shadow), unseen wall reaching
    the image's border and openings (no wall there to verify) are not seen. The wall's share
    is taken over its visible area with the sampling gaps in it (``_GAP_PX``), so a scan
    sampled sparsely everywhere is no shadow.
    """
    opening = area.opening_mask if area.opening_mask is not None and area.opening_mask.shape == ortho.depth.shape \
        else np.zeros(ortho.depth.shape, bool)
    points = np.isfinite(np.asarray(ortho.depth))
    holes = ~points & ~opening
    solid = cv2.erode(holes.astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                      borderValue=0) > 0
    seen = (points & ~opening) | (solid & _enclosed(holes))
    on = np.ones_like(seen)
    if area.visible.shape == seen.shape and area.visible.any():  # with its sampling gaps (visible wall has data)
        on = cv2.dilate(area.visible.astype(np.uint8), np.ones((2 * _GAP_PX + 1,) * 2, np.uint8)) > 0
    table = cv2.integral(seen.astype(np.uint8), sdepth=cv2.CV_32S)
    return SeenShare(table, float(np.count_nonzero(seen & on)) / max(1, int(np.count_nonzero(on))))


def match_depth(
    ortho: Orthoimage,
    area: WallArea,
    rois: list[Box],
    templates: dict[str, ModelTemplate],
    settings: DepthRecognitionSettings,
    *, images: DepthImages | None = None,
) -> list[Candidate]:
    """Candidates {D} of every class with a depth model: rho_D >= mu_D around the RoIs (Algorithm I).

    ``score`` is rho_D, ``box`` the (possibly rotated) footprint at the best match and
    ``centre`` its sub-pixel centre; several instances per class and wall are possible.
    Every model is tried at ``settings.rotations``; with ``free_rotation``, a RoI whose
    relief is turned (:func:`roi_turns`) is also searched with the model turned by that
    angle plus multiples of 90 degrees, then refined by ``turn_refine_deg`` around the
    best of those (coarse to fine). ``images`` (of this wall, as given to
    :func:`depth_rois`) saves computing them again. A match in a sparsely seen window
    (``min_seen_share``, :class:`SeenShare`) must correlate at least ``foreground_mu_d``.
    """
    if not rois:
        return []
    images = images or depth_images(ortho, area, settings)
    jd, known, jl = images.jd, images.known, images.levelled
    noise_m = noise_relief(ortho, area, images, settings)
    jm = _smooth(jd, settings.match_sigma_px)  # correlated: the scene's own relief
    jml = _smooth(jl, settings.match_sigma_px)  # checked: relief above the local wall
    edges = EdgeSettings() if settings.sharp_edge_position else None
    matched_model: dict[int, np.ndarray] = {}  # id of a candidate -> the (turned) model it matched
    turns = roi_turns(jml, rois, max(noise_m, settings.min_relief_m), settings) if settings.free_rotation else []

    peaks = [float(np.abs(t.depth).max()) for t in templates.values() if t.depth is not None and t.depth.size]
    source = foreground_source(jml, settings.min_relief_m, settings.foreground_edge_px,
                               settings.foreground_factor * min(peaks)) \
        if settings.foreground_factor > 0 and peaks else None
    seen = seen_share(ortho, area) if settings.min_seen_share > 0 else None
    regions: dict[float, ForegroundRegions | None] = {}  # by limit (mm): models of one depth share them
    views: dict[tuple[float, bytes], ModelView] = {}  # by limit and the regions kept: a model's turns share one

    def view_of(peak_m: float, area_px: int) -> ModelView:
        limit = round(settings.foreground_factor * peak_m, 3)
        if limit not in regions:
            regions[limit] = foreground_regions(source, jml, limit) if source is not None else None
        found = regions[limit]
        key = (limit, b"" if found is None else np.packbits(found.beyond >= area_px).tobytes())
        if key not in views:
            views[key] = model_view(jm, known, found, area_px)
        return views[key]

    def search(cid: str, deg: float, rot: np.ndarray, where: list[Box], *, peak_m: float, area_px: int
               ) -> list[Candidate]:
        h, w = rot.shape
        v = view_of(peak_m, area_px)
        flat_m = 1e-5  # a window whose relief varies by less than this is flat (exactly 0 in openings)
        min_energy = (h + 2 * settings.template_pad_px) * (w + 2 * settings.template_pad_px) * flat_m ** 2
        relief = float(np.median(np.abs(rot[np.abs(rot) > 0.1 * np.abs(rot).max()])))
        smooth_model = padded_template(rot, settings.template_pad_px, settings.match_sigma_px)
        face = face_region(rot, settings.face_edge_px)

        def overlap(r: float, c: float, gain: float) -> float:
            return relief_overlap(jml, smooth_model, box_at((r, c), h, w), settings.template_pad_px,
                                  settings.isolation_relief_fraction * relief, gain=gain, known=v.known)

        def plausible(r: float, c: float, gain: float) -> bool:
            box = box_at((r, c), h, w)
            g = settings.isolation_gap_px  # the footprint's own blurred edge may meet a ramp of the other object
            if v.front_share(Box(box.r0 + g, box.c0 + g, box.r1 - g, box.c1 - g)) > 1.0 - settings.full_known_share:
                return False  # partly behind another object: not told apart from a smaller class
            thr = max(settings.isolation_relief_fraction * relief * gain, noise_m)
            if isolation(jml, box, thr, settings.isolation_gap_px, settings.isolation_width_px,
                         known=v.known, min_known=settings.min_known_share,
                         trails=settings.isolation_trails) > settings.isolation_max_occupancy:
                return False
            return overlap(r, c, gain) >= settings.min_relief_iou

        peaks = match_in_rois(v.image, rot, where, threshold=settings.mu_d, pad_px=settings.template_pad_px,
                              margin_px=settings.search_margin_px, max_peaks=settings.max_peaks_per_roi,
                              sigma_px=settings.match_sigma_px, gain_range=settings.gain_range,
                              min_energy=min_energy, accept=plausible, known=v.known,
                              min_known=settings.min_known_share, full_known=settings.full_known_share,
                              masked_pre=settings.masked_pre_threshold, windows=v.windows)
        reach = settings.template_pad_px + settings.isolation_gap_px + settings.isolation_width_px

        def verified(m) -> bool:
            """Whether a match's window (with its side strips) reaches no object in front (that
            side's isolation is unverified) and is seen as densely as its wall (in a shadow,
            relief and isolation are read on interpolated data)."""
            window = box_at((m.row, m.col), h + 2 * reach, w + 2 * reach)
            return ((v.front is None or v.front_share(window) == 0.0)
                    and (seen is None or seen.of(window) >= settings.min_seen_share))

        peaks = [m for m in peaks if m.score >= settings.foreground_mu_d or verified(m)]
        found = [Candidate(cid, ortho.wall_id, "depth", box_at((m.row, m.col), h, w), (m.row, m.col), m.score,
                           m.roi, deg, gain=m.gain, relief_iou=overlap(m.row, m.col, m.gain),
                           face_gain=face_gain(jml, rot, box_at((m.row, m.col), h, w), region=face, known=v.known))
                 for m in peaks]
        matched_model.update((id(c), rot) for c in found)
        return found

    out: list[Candidate] = []
    for cid in sorted(templates):
        t = templates[cid]
        if t.depth is None or t.relief_m() < settings.min_template_relief_m:
            continue
        for v in views.values():  # RoI windows are shared by one class's models and turns, then let go (memory)
            v.windows.clear()
        # the reference model and any further ones (exemplars): each is searched, NMS keeps the best
        models = [m for i, m in enumerate(t.depth_models())
                  if i == 0 or float(np.abs(m).max()) >= settings.min_template_relief_m]
        found: list[Candidate] = []
        turners = []
        for model in models:
            peak, area = float(np.abs(model).max()), int(model.size)
            closed = close_see_through(model, settings.see_through_fraction) if settings.see_through_fraction > 0 else None
            for deg, rot in rotated_variants(model, settings.rotations) + (
                    rotated_variants(closed, settings.rotations) if closed is not None else []):
                parts = group_boxes(rois, height=rot.shape[0], width=rot.shape[1],
                                    gap_px=int(round(settings.part_gap_fraction * min(rot.shape))),
                                    slack_px=settings.template_pad_px) \
                    if settings.part_gap_fraction > 0 else []
                found.extend(search(cid, deg, rot, rois + [b for b in parts if b not in rois],
                                    peak_m=peak, area_px=area))

            def turned(a: float, where: list[Box], *, cid: str = cid, model: np.ndarray = model,
                       peak: float = peak, area: int = area) -> list[Candidate]:
                return search(cid, a, rotate_template(model, a), where, peak_m=peak, area_px=area)

            turners.append(turned)
            for roi, turn in turns:
                found.extend(search_turned(turned, roi, turn, settings.turn_refine_deg))
        kept = nms(found, settings.nms_overlap, upright_bonus=settings.rotation_margin)
        if settings.free_rotation:
            # refined with the reference model (exemplars are measured turned as they hang)
            kept = [refine_turn(turners[0], c, settings.turn_steps_deg, settings.min_turn_gain) for c in kept]
        if edges is not None:  # placed by the relief's sharp edges (only the kept ones: speed)
            for c in kept:
                c.position = sharp_edge_centre(jl, matched_model[id(c)], c.centre, known, settings=edges)
        out.extend(kept)
    return out


def close_see_through(model: np.ndarray, relief_fraction: float) -> np.ndarray | None:
    """``model`` with its see-through gaps closed, or None when it has none.

    A gap enclosed by an object's relief (between a tube radiator's tubes, inside a
    bracket) shows the wall in the model's straight front view, but a scanner looking from
    above, below or the side sees the tubes' own sides there, so the scan shows relief
    where the model has none. Each 8-connected region below ``relief_fraction`` of the
    model's relief (the wall, not a recess of the object) that the rest encloses takes
    the mean relief of its 1-pixel rim;
    :func:`match_depth` tries this variant as well as the model itself.
    """
    peak = float(np.max(np.abs(model))) if model.size else 0.0
    if peak <= 0:
        return None
    rel = np.abs(model) >= relief_fraction * peak
    holes = ndimage.binary_fill_holes(rel) & ~rel
    if not holes.any():
        return None
    lab, n = ndimage.label(holes, structure=np.ones((3, 3), bool))
    rim = ndimage.grey_dilation(lab, size=(3, 3)) * rel
    on = rim > 0
    level = np.nan_to_num(np.asarray(ndimage.mean(model[on], labels=rim[on], index=np.arange(1, n + 1)), float))
    out = model.copy()
    out[holes] = level[lab[holes] - 1]
    return out.astype(model.dtype)


def refine_turn(search: Callable[[float, list[Box]], list[Candidate]], cand: Candidate,
                steps: tuple[float, ...], min_gain: float) -> Candidate:
    """``cand`` with its model's turn refined by a local coarse-to-fine search.

    At each step size of ``steps`` (e.g. 10, 5, 2, 1 degrees) the model turned one step
    either way is correlated around the candidate's centre (``search(angle, [place])``,
    with every plausibility check); the search moves while that raises rho_D. The turn
    found is kept if it raises rho_D, by more than ``min_gain`` for a candidate upright or
    at a quarter turn (objects are usually mounted so). A small object turned by a few degrees still correlates well upright,
    and its blurred relief tells no turn: this finds it.
    """
    best = cand
    place = [box_at(cand.centre, 1, 1)]
    tried: dict[float, Candidate | None] = {}  # by angle: a step back to an angle tried is not searched again

    def at(a: float) -> Candidate | None:
        a = round(a % 360.0, 3)
        if a not in tried:
            found = search(a, place)
            tried[a] = max(found, key=lambda c: c.score) if found else None
        return tried[a]

    for step in steps:
        for _ in range(6):
            tries = [c for c in (at(float(best.rotation_deg) + step), at(float(best.rotation_deg) - step))
                     if c is not None and c.score > best.score]
            if not tries:
                break
            best = max(tries, key=lambda c: c.score)
    quarter = abs(float(cand.rotation_deg) / 90.0 - round(float(cand.rotation_deg) / 90.0)) < 1e-9
    if best.score <= cand.score + (min_gain if quarter else 0.0):  # mounted upright unless clearly not
        return cand
    best.roi = cand.roi
    return best


def roi_turns(relief: np.ndarray, rois: list[Box], threshold_m: float, settings: DepthRecognitionSettings
              ) -> list[tuple[Box, float]]:
    """(RoI, turn) of the RoIs whose relief above ``threshold_m`` is turned by at least
    ``min_turn_deg`` from the image axes (:func:`~sbsc_core.recognition.matching.estimate_turn`)."""
    out = []
    for roi in rois:
        turn = estimate_turn(np.abs(relief[roi.r0:roi.r1, roi.c0:roi.c1]) >= threshold_m)
        if turn is not None and abs(turn) >= settings.min_turn_deg:
            out.append((roi, turn))
    return out


def search_turned(search: Callable[[float, list[Box]], list[Candidate]], roi: Box, turn: float,
                  refine: tuple[float, ...]) -> list[Candidate]:
    """Coarse to fine: ``search(angle, [roi])`` at ``turn`` + k x 90, then at the best angle
    found plus each of ``refine`` degrees. Returns every candidate found."""
    coarse = [c for a in turn_angles(turn) for c in search(a, [roi])]
    if not coarse or not refine:
        return coarse
    best = float(max(coarse, key=lambda c: c.score).rotation_deg)
    return coarse + [c for d in refine for c in search(round((best + d) % 360.0, 3), [roi])]
