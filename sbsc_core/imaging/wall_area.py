"""Visible wall area and openings of an orthoimage (paper, section 3.3).

**Visible area.** The orthoimage is tiled into seed windows; a window whose pixels all
have data, are flat (on the wall plane) and of one colour is a coherent seed. Seeds are
clustered by colour (CIE Lab); each cluster holding a fair share of the seeds is a wall
colour. The visible wall is then the segmentation by colour: pixels on the plane within
``colour_tolerance`` of a wall colour, in connected regions that contain a seed. Objects
(other colour, or standing out of the plane), openings and unscanned parts are not
visible wall.

**Openings.** Doors and windows are found from discontinuities of J_CD: straight vertical
and horizontal lines among the colour edges (Canny on L*), the depth steps and the
borders of the data. Every rectangle bounded by two vertical and two horizontal lines (a
door's bottom is the floor) whose size is that of a door or a window is a hypothesis. It
is an opening if its sides are supported by edges (partly occluded sides are allowed),
its interior is consistent with a hole (no data through it, or glass / a leaf recessed
behind the wall plane; a closed door may instead be of another colour) and nothing in it
stands out of the wall (an electrical panel or a radiator does), and its surroundings are
wall rather than more hole (location consistency: the rectangle is the whole opening).
Hypotheses are accepted best first without overlaps.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..settings import WallAreaSettings
from ..types import Opening, Orthoimage, WallArea

__all__ = ["find_wall_area", "visible_wall", "find_openings", "to_lab"]


def find_wall_area(ortho: Orthoimage, settings: WallAreaSettings | None = None) -> WallArea:
    """Visible wall area, openings (door / window rectangles) and the wall's mean colour."""
    s = settings or WallAreaSettings()
    lab = to_lab(ortho.colour)
    visible, centres = visible_wall(ortho, s, lab)
    openings, opening_mask = find_openings(ortho, s, lab, centres)
    visible &= ~opening_mask
    wall_colour = (np.array(cv2.mean(ortho.colour, mask=visible.astype(np.uint8))[:3]) if visible.any()
                   else np.zeros(3))
    return WallArea(visible=visible, openings=openings, opening_mask=opening_mask, wall_colour=wall_colour)


def to_lab(colour: np.ndarray) -> np.ndarray:
    """8-bit sRGB (H, W, 3) to CIE Lab float32 (L 0..100)."""
    return cv2.cvtColor(colour.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab)


def _smoothed_depth(ortho: Orthoimage, k: int) -> np.ndarray:
    d = np.where(ortho.mask, ortho.depth, 0.0).astype(np.float32)
    if k >= 3:
        d = cv2.medianBlur(d, 5 if k >= 5 else 3)
    return np.where(ortho.mask, d, np.nan)


def visible_wall(ortho: Orthoimage, settings: WallAreaSettings | None = None, lab: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(visible mask, wall colour centres (k, 3) in Lab) from coherent colour seeds."""
    s = settings or WallAreaSettings()
    lab = to_lab(ortho.colour) if lab is None else lab
    h, w = ortho.shape
    n = max(2, int(s.seed_window_px))
    hb, wb = h // n, w // n
    empty = np.zeros((h, w), bool), np.zeros((0, 3), np.float32)
    if hb == 0 or wb == 0:
        return empty
    m = ortho.mask[: hb * n, : wb * n].astype(np.float32)
    frac = _block_mean(m, hb, wb)
    dep = np.where(ortho.mask, ortho.depth, 0.0).astype(np.float32)[: hb * n, : wb * n]
    col = lab[: hb * n, : wb * n] * m[..., None]
    inv = 1.0 / np.maximum(frac, 1e-6)
    d_mean = _block_mean(dep, hb, wb) * inv
    d_var = _block_mean(dep * dep, hb, wb) * inv - d_mean**2
    c_mean = _block_mean(col, hb, wb) * inv[..., None]
    c_var = _block_mean(col * col, hb, wb) * inv[..., None] - c_mean**2
    seed = (frac >= s.seed_min_valid) & (np.abs(d_mean) <= s.wall_depth_tolerance_m)
    seed &= (d_var <= s.seed_depth_std_m**2) & (c_var.max(axis=-1) <= s.seed_colour_std**2)
    if not seed.any():
        return empty
    centres = _colour_clusters(c_mean[seed], s.colour_tolerance, s.min_cluster_fraction)
    if len(centres) == 0:
        return empty
    depth = _smoothed_depth(ortho, s.depth_median_px)
    flat = np.abs(np.nan_to_num(depth, nan=1.0)) <= s.wall_depth_tolerance_m
    cand = ortho.mask & flat & (_min_dist(lab, centres) <= s.colour_tolerance)
    nlab, labels = cv2.connectedComponents(cand.astype(np.uint8), connectivity=8)
    # seeds of a wall cluster anchor the regions they lie in
    anchor = seed & (_min_dist(c_mean, centres) <= s.colour_tolerance)
    br, bc = np.nonzero(anchor)
    keep = np.zeros(nlab, bool)
    keep[labels[br * n + n // 2, bc * n + n // 2]] = True
    keep[0] = False
    return keep[labels], centres.astype(np.float32)


def _block_mean(a: np.ndarray, hb: int, wb: int) -> np.ndarray:
    """Mean over non-overlapping blocks (the array is an exact multiple of the block size)."""
    return cv2.resize(a, (wb, hb), interpolation=cv2.INTER_AREA)


def _min_dist(lab: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Distance (CIE76) of every Lab value to the nearest of ``centres``."""
    best = None
    planes = [np.ascontiguousarray(lab[..., k]) for k in range(3)]
    for c in np.asarray(centres, np.float32):
        d = (planes[0] - c[0]) ** 2
        d += (planes[1] - c[1]) ** 2
        d += (planes[2] - c[2]) ** 2
        best = d if best is None else np.minimum(best, d)
    return np.sqrt(best)


def _colour_clusters(seeds: np.ndarray, tol: float, min_fraction: float, max_probe: int = 600) -> np.ndarray:
    """Greedy mode seeking: the densest seed colour, its members within ``tol``, repeat."""
    total = len(seeds)
    rest = seeds.astype(np.float64)
    centres = []
    while len(rest) >= max(1, min_fraction * total):
        probe = rest[:: max(1, math.ceil(len(rest) / max_probe))]
        dens = (np.linalg.norm(probe[:, None] - rest[None, ::max(1, math.ceil(len(rest) / max_probe))], axis=-1)
                <= tol / 2).sum(axis=1)
        c = probe[int(np.argmax(dens))]
        for _ in range(5):
            mem = np.linalg.norm(rest - c, axis=1) <= tol
            c = rest[mem].mean(axis=0)
        mem = np.linalg.norm(rest - c, axis=1) <= tol
        if mem.sum() < min_fraction * total:
            break
        centres.append(c)
        rest = rest[~mem]
    return np.array(centres).reshape(-1, 3)


# --------------------------------------------------------------------------- openings


def _edges(ortho: Orthoimage, lab: np.ndarray, s: WallAreaSettings) -> tuple[np.ndarray, np.ndarray]:
    """Vertical-line and horizontal-line edge pixels from colour, depth and data borders."""
    L8 = np.where(ortho.mask, np.clip(lab[..., 0] * 2.55, 0, 255), 0).astype(np.uint8)
    canny = cv2.Canny(L8, s.canny_low, s.canny_high, L2gradient=True) > 0
    gx = cv2.Sobel(L8, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(L8, cv2.CV_32F, 0, 1, ksize=3)
    ev = canny & (np.abs(gx) >= np.abs(gy))
    eh = canny & (np.abs(gy) > np.abs(gx))
    far = np.float32(-1.0)  # no data: seen through, far behind
    d = np.where(ortho.mask, ortho.depth, far).astype(np.float32)
    jump_x = np.abs(np.diff(d, axis=1)) > s.depth_step_m
    jump_y = np.abs(np.diff(d, axis=0)) > s.depth_step_m
    ev[:, :-1] |= jump_x
    ev[:, 1:] |= jump_x
    eh[:-1] |= jump_y
    eh[1:] |= jump_y
    return ev, eh


def _line_positions(e: np.ndarray, length: int, tol: int, axis: int) -> np.ndarray:
    """Columns (axis=0: vertical lines) or rows (axis=1) holding straight runs of ``length``."""
    if axis == 0:
        grown = cv2.dilate(e.astype(np.uint8), np.ones((1, 2 * tol + 1), np.uint8))
        runs = cv2.morphologyEx(grown, cv2.MORPH_OPEN, np.ones((length, 1), np.uint8))
        runs = cv2.bitwise_and(runs, e.astype(np.uint8))
        prof = runs.sum(axis=0).astype(np.float64)
    else:
        grown = cv2.dilate(e.astype(np.uint8), np.ones((2 * tol + 1, 1), np.uint8))
        runs = cv2.morphologyEx(grown, cv2.MORPH_OPEN, np.ones((1, length), np.uint8))
        runs = cv2.bitwise_and(runs, e.astype(np.uint8))
        prof = runs.sum(axis=1).astype(np.float64)
    k = 2 * tol + 1
    peak = (prof >= length * 0.5) & (prof == _max_filter_1d(prof, 2 * k + 1))
    return np.flatnonzero(peak)


def _max_filter_1d(a: np.ndarray, k: int) -> np.ndarray:
    pad = k // 2
    p = np.pad(a, pad, mode="constant", constant_values=-np.inf)
    return np.lib.stride_tricks.sliding_window_view(p, k).max(axis=1)


def _integral(a: np.ndarray) -> np.ndarray:
    return cv2.integral(a.astype(np.uint8), sdepth=cv2.CV_32S)


def _box_sum(ii: np.ndarray, r0, c0, r1, c1):
    return ii[r1, c1] - ii[r0, c1] - ii[r1, c0] + ii[r0, c0]


def find_openings(ortho: Orthoimage, settings: WallAreaSettings | None = None, lab: np.ndarray | None = None,
                  wall_centres: np.ndarray | None = None) -> tuple[list[Opening], np.ndarray]:
    """Door and window rectangles (wall u, v metres) and the mask of their pixels."""
    s = settings or WallAreaSettings()
    lab = to_lab(ortho.colour) if lab is None else lab
    h, w = ortho.shape
    px = ortho.pixel_m
    out_mask = np.zeros((h, w), bool)
    if wall_centres is None or len(wall_centres) == 0:
        wall_centres = visible_wall(ortho, s, lab)[1]
    depth = ortho.depth
    hole = ~ortho.mask
    open_ = hole | (ortho.mask & (np.nan_to_num(depth, nan=0.0) < -s.recess_m))
    protr = ortho.mask & (np.nan_to_num(depth, nan=0.0) > s.recess_m)
    if len(wall_centres):
        other = ortho.mask & ~open_ & ~protr & (_min_dist(lab, wall_centres) > s.colour_tolerance)
    else:
        other = np.zeros((h, w), bool)
    ev, eh = _edges(ortho, lab, s)
    tol = int(s.line_tolerance_px)
    length = max(3, int(round(s.min_line_m / px)))
    cols = np.unique(np.concatenate([[0, w], _line_positions(ev, length, tol, 0)]))
    rows = np.unique(np.concatenate([[0, h], _line_positions(eh, length, tol, 1)]))
    # support of sides: edges within +-tol of the line, cumulated along it
    ev_g = cv2.dilate(ev.astype(np.uint8), np.ones((1, 2 * tol + 1), np.uint8))
    eh_g = cv2.dilate(eh.astype(np.uint8), np.ones((2 * tol + 1, 1), np.uint8))
    cs_v = np.vstack([np.zeros((1, w), np.int32), np.cumsum(ev_g, axis=0, dtype=np.int32)])  # (h+1, w)
    cs_h = np.hstack([np.zeros((h, 1), np.int32), np.cumsum(eh_g, axis=1, dtype=np.int32)])  # (h, w+1)
    ii_open, ii_other, ii_protr = _integral(open_), _integral(other), _integral(protr)
    ring = max(1, int(round(s.ring_m / px)))
    floor_px = s.door_floor_tolerance_m / px
    wmin = min(s.door_width_m[0], s.window_width_m[0]) / px
    wmax = max(s.door_width_m[1], s.window_width_m[1]) / px
    hmin = min(s.door_height_m[0], s.window_height_m[0]) / px
    hmax = max(s.door_height_m[1], s.window_height_m[1]) / px
    r0s, r1s = np.meshgrid(rows, rows, indexing="ij")
    ok = (r1s - r0s >= hmin) & (r1s - r0s <= hmax)
    r0s, r1s = r0s[ok], r1s[ok]
    c0s, c1s = np.meshgrid(cols, cols, indexing="ij")
    ok = (c1s - c0s >= wmin) & (c1s - c0s <= wmax)
    c0s, c1s = c0s[ok], c1s[ok]
    cands = []
    if len(r0s) and len(c0s):
        block = max(1, 400_000 // len(r0s))
        for b in range(0, len(c0s), block):
            nb = len(c0s[b:b + block])
            hyp = (np.tile(r0s, nb), np.repeat(c0s[b:b + block], len(r0s)),
                   np.tile(r1s, nb), np.repeat(c1s[b:b + block], len(r0s)))
            cands += _score(*hyp, h=h, w=w, px=px, floor_px=floor_px, ring=ring, cs_v=cs_v, cs_h=cs_h,
                            ii_open=ii_open, ii_other=ii_other, ii_protr=ii_protr, s=s)
    cands.sort(key=lambda c: (-c[0], -(c[4] - c[2]) * (c[5] - c[3])))
    openings: list[Opening] = []
    for _, kind, r0, c0, r1, c1 in cands:
        if out_mask[r0:r1, c0:c1].any():
            continue
        r0, c0, r1, c1 = _snap(open_, r0, c0, r1, c1, reach=tol + 1)
        if out_mask[r0:r1, c0:c1].any():
            continue
        out_mask[r0:r1, c0:c1] = True
        height = ortho.frame.height_m
        v_min = max(0.0, height - r1 * px)
        if kind == "door":
            v_min = 0.0
        openings.append(Opening(ortho.wall_id, kind, c0 * px, min(c1 * px, ortho.frame.width_m), v_min,
                                height - r0 * px))
    openings.sort(key=lambda o: (o.u_min, o.v_min))
    return openings, out_mask


def _score(r0: np.ndarray, c0: np.ndarray, r1: np.ndarray, c1: np.ndarray, *, h: int, w: int, px: float,
           floor_px: float, ring: int, cs_v: np.ndarray, cs_h: np.ndarray, ii_open: np.ndarray,
           ii_other: np.ndarray, ii_protr: np.ndarray, s: WallAreaSettings) -> list[tuple]:
    """Accepted hypotheses (score, kind, r0, c0, r1, c1) among rectangles given as arrays."""
    width_m = (c1 - c0) * px
    height_m = (r1 - r0) * px
    at_floor = (h - r1) <= floor_px
    is_door = at_floor & _within(width_m, s.door_width_m) & _within(height_m, s.door_height_m)
    sill_m = (h - r1) * px
    is_window = ~at_floor & (sill_m >= s.window_min_sill_m) & _within(width_m, s.window_width_m) & \
        _within(height_m, s.window_height_m)
    keep = np.flatnonzero(is_door | is_window)
    if not len(keep):
        return []
    r0, c0, r1, c1, is_door = r0[keep], c0[keep], r1[keep], c1[keep], is_door[keep]
    area = (r1 - r0) * (c1 - c0)
    f_open = _box_sum(ii_open, r0, c0, r1, c1) / area
    f_other = _box_sum(ii_other, r0, c0, r1, c1) / area
    f_protr = _box_sum(ii_protr, r0, c0, r1, c1) / area

    def vside(c: np.ndarray) -> np.ndarray:  # share of the side's rows with vertical edges
        border = (c <= 0) | (c >= w)
        cc = np.clip(c, 0, w - 1)
        return np.where(border, 1.0, (cs_v[r1, cc] - cs_v[r0, cc]) / (r1 - r0))

    def hside(r: np.ndarray) -> np.ndarray:  # share of the side's columns with horizontal edges
        border = (r <= 0) | (r >= h)
        rr = np.clip(r, 0, h - 1)
        return np.where(border, 1.0, (cs_h[rr, c1] - cs_h[rr, c0]) / (c1 - c0))

    bottom = np.where(is_door, 1.0, hside(r1))
    support = np.minimum(np.minimum(vside(c0), vside(np.minimum(c1, w - 1) + (c1 >= w))),
                         np.minimum(hside(r0), bottom))
    # location consistency: the band around the rectangle is not more hole
    R0, R1 = np.maximum(r0 - ring, 0), np.minimum(r1 + ring, h)
    C0, C1 = np.maximum(c0 - ring, 0), np.minimum(c1 + ring, w)
    outer_area = (R1 - R0) * (C1 - C0) - area
    ring_open = np.where(outer_area > 0, (_box_sum(ii_open, R0, C0, R1, C1) - f_open * area) /
                         np.maximum(outer_area, 1), 0.0)
    hole_like = f_open >= s.min_open_fraction
    closed_door = is_door & (f_open + f_other >= s.min_door_other_fraction)
    ok = (support >= s.min_side_support) & (f_protr <= s.max_protruding_fraction) & \
        (ring_open <= s.max_ring_open_fraction) & (hole_like | closed_door)
    score = 2.0 * f_open + f_other + support - ring_open  # a hole beats a frame of another colour
    return [(float(score[k]), "door" if is_door[k] else "window", int(r0[k]), int(c0[k]), int(r1[k]), int(c1[k]))
            for k in np.flatnonzero(ok)]


def _within(x, rng: tuple[float, float]):
    return (x >= rng[0]) & (x <= rng[1])


def _snap(open_: np.ndarray, r0: int, c0: int, r1: int, c1: int, *, reach: int) -> tuple[int, int, int, int]:
    """Move each side to where the hole really starts (within ``reach`` pixels)."""
    h, w = open_.shape

    def first_open(profile: np.ndarray, start: int, lo: int, hi: int, step: int) -> int:
        for k in range(reach + 1):
            for cand in (start - k * step, start + k * step):
                if lo <= cand < hi and profile[cand] >= 0.5 and (cand - step < lo or cand - step >= hi or profile[cand - step] < 0.5):
                    return cand
        return start

    colf = open_[r0:r1].mean(axis=0) if r1 > r0 else np.zeros(w)
    rowf = open_[:, c0:c1].mean(axis=1) if c1 > c0 else np.zeros(h)
    nc0 = first_open(colf, c0, 0, w, 1)
    nc1 = first_open(colf[::-1], w - c1, 0, w, 1)
    nr0 = first_open(rowf, r0, 0, h, 1)
    nr1 = first_open(rowf[::-1], h - r1, 0, h, 1)
    return nr0, nc0, h - nr1, w - nc1
