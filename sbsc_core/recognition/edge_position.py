"""A depth match's centre from the sharp edges of its relief (position refinement).

The normalised cross-correlation of section 4.2 places a model where it best fits the whole
relief, which is right when both outlines of the object are seen alike. A scanner looking
at an object obliquely does not see them alike: on the side facing the scanner the
object's own side face projects onto one column of the orthoimage (a sharp edge), while
on the far side the object hides the wall (an occlusion shadow) and the beams grazing its
front edge return blended ranges (mixed pixels) that float into that shadow. That side of
the relief becomes a ramp several pixels wide, and the correlation, fitting both sides,
moves the centre into the ramp: by 2-5 mm for an object 5-10 cm deep seen at 20-40 degrees
(the far side of an electrical panel, the bottom of a radiator below the scanner, the top
of an exit light above it).

For each image axis this module compares the scene's relief profile across the object
(the mean over the model's footprint along the other axis) with the model's, edge by edge:
each outer edge, where the profile crosses half its height, gives the centre's shift, and
its rise (the distance between the quarter and three-quarter crossings) beyond the
model's own tells how much the edge is blurred. The two edges' shifts are averaged with
weights ``1 / (edge_blur_px + excess rise)^4``: a frontal view, both edges sharp, keeps
their mean (what the correlation measures), an oblique one is placed by its sharp edge.
Models shallower than ``min_relief_m`` (2 cm: sockets, switches, signs) keep the
correlation's centre: grazing beams blend ranges over at most half the shadow, relief x
tan(incidence) / 2, under a pixel for them, while their few edge pixels are noisier than
the correlation over the whole relief. Nothing is changed along an axis where the model's outline is no clean step on both sides
(an extinguisher's valve above its body), where an edge is not found in the scene (unseen,
a neighbour within reach) or where the refined centre would move more than ``max_shift_px``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EdgeSettings:
    """Options of :func:`sharp_edge_centre` (pixels unless stated)."""

    margin_px: int = 10  # the scene is read this far beyond the model's footprint on each side
    level: float = 0.5  # an edge is where the profile crosses this share of its height
    rise_levels: tuple[float, float] = (0.25, 0.75)  # its rise: between these crossings
    edge_blur_px: float = 0.5  # weight of an edge: 1 / (this + rise beyond the model's)^4
    max_shift_px: float = 3.0  # a refinement moving the centre further is not trusted
    min_relief_m: float = 0.02  # models shallower than this are not refined (their shadow is under a pixel)
    clean_edge_px: float = 3.0  # a model's edge is a clean step: from half to 0.9 of its height within this
    min_known_share: float = 0.8  # profile samples need data on this share of their pixels


def _crossing(p: np.ndarray, level: float, start: float, step: int) -> float | None:
    """Sub-pixel index where ``p`` first rises to ``level`` walking from index ``start``
    towards the object (``step`` +1: rightwards, -1: leftwards); None if it never does."""
    n = len(p)
    i = int(np.clip(np.floor(start) if step > 0 else np.ceil(start), 0, n - 1))
    if p[i] >= level:  # already above: walk outwards to the last sample below
        while 0 <= i < n and p[i] >= level:
            i -= step
        if not 0 <= i < n:
            return None
        i += step
    else:
        while 0 <= i < n and p[i] < level:
            i += step
        if not 0 <= i < n:
            return None
    j = i - step  # p[j] < level <= p[i]
    if not 0 <= j < n or not np.isfinite(p[j]) or not np.isfinite(p[i]):
        return None
    t = (level - p[j]) / (p[i] - p[j]) if p[i] != p[j] else 0.0
    return float(j + t * (i - j))


def _edges(p: np.ndarray, guess: tuple[float, float], s: EdgeSettings
           ) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """((left, right) crossings at ``s.level``, (left, right) rises) of a normalised
    profile ``p`` (0 = wall, 1 = full relief): each edge is the crossing nearest to its
    ``guess`` (at most ``s.margin_px`` away), its rise read from there outwards and
    inwards, so a neighbour beyond the edge does not count. None when one is missing."""
    out, rises = [], []
    for k, step in ((0, 1), (1, -1)):
        x = _crossing(p, s.level, guess[k], step)
        if x is None or abs(x - guess[k]) > s.margin_px:
            return None
        lo = _crossing(p, s.rise_levels[0], x, step)
        hi = _crossing(p, s.rise_levels[1], x, step)
        if lo is None or hi is None:
            return None
        out.append(x)
        rises.append(abs(hi - lo))
    if out[1] - out[0] < 1.0:
        return None
    return (out[0], out[1]), (rises[0], rises[1])


def _profile(a: np.ndarray, known: np.ndarray | None, axis: int, min_share: float) -> np.ndarray:
    """Mean of ``a`` along ``axis`` over its known pixels; NaN where too few are known."""
    if known is None:
        return a.mean(axis=axis)
    k = known.astype(np.float64)
    cnt = k.sum(axis=axis)
    tot = (a * k).sum(axis=axis)
    out = np.where(cnt >= min_share * a.shape[axis], tot / np.maximum(cnt, 1e-9), np.nan)
    return out


def edge_shift(scene: np.ndarray, model: np.ndarray, margin: int, s: EdgeSettings,
               known: np.ndarray | None = None) -> float | None:
    """The shift (pixels) along the last axis that puts ``model`` on ``scene``'s sharp edges.

    ``scene`` is (H, W + 2 margin) (known mask alike), ``model`` (H, W), both signed so
    the object stands out positively; the model sits at ``margin`` in the scene's columns.
    None when an edge is missing or the profile has no height.
    """
    pm = np.pad(model.mean(axis=0), margin)
    ps = _profile(scene, known, 0, s.min_known_share)
    peak = float(pm.max())
    inner = pm >= s.level * peak
    if peak <= 0 or not inner.any() or not np.isfinite(ps[inner]).all():
        return None
    # both profiles in units of their own typical height over the object (a step of the
    # model's outline, a rail at half height, is then read alike in both)
    top_m, top_s = (float(np.percentile(x[inner], 90)) for x in (pm, ps))
    if not top_s > 0:
        return None
    pm, ps = pm / top_m, np.nan_to_num(ps / top_s, nan=-1.0)
    idx = np.nonzero(inner)[0]
    em = _edges(pm, (float(idx[0]), float(idx[-1])), s)
    if em is None:
        return None
    for x, step in ((em[0][0], 1), (em[0][1], -1)):  # an outline that steps up (a valve on top) tells no edge
        top = _crossing(pm, 0.9, x, step)
        if top is None or abs(top - x) > s.clean_edge_px:
            return None
    es = _edges(ps, em[0], s)
    if es is None:
        return None
    shifts = np.array([es[0][0] - em[0][0], es[0][1] - em[0][1]])
    excess = np.maximum(0.0, np.array(es[1]) - np.array(em[1]))
    w = 1.0 / (s.edge_blur_px + excess) ** 4
    return float((w * shifts).sum() / w.sum())


def sharp_edge_centre(relief: np.ndarray, model: np.ndarray, centre: tuple[float, float],
                      known: np.ndarray | None = None, *, settings: EdgeSettings | None = None
                      ) -> tuple[float, float]:
    """The sub-pixel (row, col) centre of ``model`` on ``relief`` refined from its sharp edges.

    Parameters
    ----------
    relief : (H, W) relief of the wall in metres (J_D above the wall plane).
    model : (h, w) depth model as matched (turned), metres, the object's relief.
    centre : the correlation's (row, col) centre of the model on ``relief``.
    known : optional bool mask of ``relief``'s pixels with data.
    settings : :class:`EdgeSettings`.

    Returns
    -------
    The refined (row, col); an axis whose edges are not both found, or whose refinement
    moves more than ``max_shift_px``, keeps the correlation's coordinate.
    """
    s = settings or EdgeSettings()
    if float(np.max(np.abs(model))) < s.min_relief_m:
        return float(centre[0]), float(centre[1])
    h, w = model.shape
    sign = 1.0 if float(model.max()) >= -float(model.min()) else -1.0
    m = sign * np.asarray(model, np.float64)
    out = [float(centre[0]), float(centre[1])]
    r0 = int(round(centre[0] - (h - 1) / 2.0))
    c0 = int(round(centre[1] - (w - 1) / 2.0))
    frac = (centre[0] - (h - 1) / 2.0 - r0, centre[1] - (w - 1) / 2.0 - c0)
    g = s.margin_px
    H, W = relief.shape
    for axis in (0, 1):  # 0: rows (vertical position), 1: columns
        if axis == 1:
            rs, cs = slice(r0, r0 + h), slice(c0 - g, c0 + w + g)
            mm = m
        else:
            rs, cs = slice(r0 - g, r0 + h + g), slice(c0, c0 + w)
            mm = m.T
        if rs.start < 0 or cs.start < 0 or rs.stop > H or cs.stop > W:
            continue
        sc = sign * np.asarray(relief[rs, cs], np.float64)
        kn = None if known is None else np.asarray(known[rs, cs], bool)
        if axis == 0:
            sc = sc.T
            kn = None if kn is None else kn.T
        d = edge_shift(sc, mm, g, s, kn)
        if d is None:
            continue
        d -= frac[axis]  # the model was read at the whole pixel, the centre is sub-pixel
        if abs(d) <= s.max_shift_px:
            out[axis] += d
    return out[0], out[1]
