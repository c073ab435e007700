"""The 15 global colour and shape descriptors of a region (paper, section 4.3, equations 1-14).

Given an RGB image and a foreground mask:

* the saturation S (HSV) and the a and b components (CIE Lab) of the foreground are each
  clustered into three classes ("drastic clustering", 1-D k-means); classes closer than
  ``cluster_merge_s`` / ``cluster_merge_ab`` are merged (noise is not a colour); the
  classes are ranked by their number of pixels, so the first and second class
  prototypes {s1, s2} are the two principal values of the component;
* v1 = s1, v2 = s2 (eq. 1, 2); v3 = <s1> / <I3S>, the share of foreground pixels in class
  s1 (eq. 3); v4 = <s2(s1)> / <s1>, the pixels of class s2 contained in the regions of
  class s1 (a region being the convex hull of a connected part of s1), relative to the
  pixels of s1 (eq. 4);
  v5 = the number of connected segments of s2 contained in the regions of s1;
* v6..v9 and v10..v13 are v1..v4 for the a and b components (eq. 5-12);
* v14 = 4 pi A / P^2, the roundness of the foreground (eq. 13), measured on its outer
  contours (polygon through the boundary pixel centres, so that a square gives pi/4 at
  any scale);
* v15 = sum p(i, j)^2, the energy of the grey-level co-occurrence matrix (eq. 14) of the
  foreground's lightness quantised to ``glcm_levels`` levels, over the four directions
  0, 45, 90 and 135 degrees at distance 1, symmetric, counting only pairs of foreground
  pixels (so a rotation by 90 degrees leaves it unchanged).

Every descriptor is invariant to rotations by 90 degrees and nearly so to scale.

``normalise_descriptors`` maps a pattern onto comparable unit ranges (S, ratios, roundness
and energy are already in [0, 1]; a and b are divided by ``ab_scale``; the segment count
by ``segment_cap``), and ``descriptor_distance`` is the Euclidean distance of two
normalised patterns divided by sqrt(15), i.e. their root-mean-square difference, the
rho_C compared with mu_C = 0.2.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy import ndimage

from ..settings import ColourRecognitionSettings

N_DESCRIPTORS = 15
NAMES = ("s1", "s2", "s1_share", "s2_in_s1", "s2_segments",
         "a1", "a2", "a1_share", "a2_in_a1",
         "b1", "b2", "b1_share", "b2_in_b1",
         "roundness", "glcm_energy")
_EIGHT = np.ones((3, 3), bool)


def rgb_to_hsv_lab(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(HSV with S, V in [0, 1] and H in degrees, Lab with L in [0, 100]) as float32."""
    f = np.ascontiguousarray(np.asarray(rgb)[..., :3], dtype=np.float32) / 255.0
    return cv2.cvtColor(f, cv2.COLOR_RGB2HSV), cv2.cvtColor(f, cv2.COLOR_RGB2Lab)


def rgb_to_hsv(rgb: np.ndarray) -> np.ndarray:
    """The HSV image of :func:`rgb_to_hsv_lab` alone."""
    f = np.ascontiguousarray(np.asarray(rgb)[..., :3], dtype=np.float32) / 255.0
    return cv2.cvtColor(f, cv2.COLOR_RGB2HSV)


def _nearest(x: np.ndarray, sorted_centres: np.ndarray) -> np.ndarray:
    """Index of the nearest of ascending ``sorted_centres`` for each value of ``x``."""
    bounds = 0.5 * (sorted_centres[1:] + sorted_centres[:-1])
    return np.searchsorted(bounds, x)


def kmeans_1d(values: np.ndarray, k: int = 3, merge_tol: float = 0.0, bins: int = 256,
              iterations: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic 1-D k-means: (centres (m,), labels (n,)), m <= k classes.

    Lloyd's algorithm on a ``bins``-bin histogram of the values (quantile start), then
    classes whose centres are closer than ``merge_tol`` are merged: a nearly uniform
    component is one class, not three classes of noise, so the ranking of the classes
    (and with it the descriptors) does not flip on noise.
    """
    centres, labels, _ = _kmeans_1d(values, k, merge_tol, bins, iterations)
    return centres, labels


def _kmeans_1d(values: np.ndarray, k: int, merge_tol: float, bins: int = 256,
               iterations: int = 50) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`kmeans_1d` and the number of values in each class (it runs tens of
    thousands of times a run on small components: few numpy calls, plain floats)."""
    x = np.asarray(values, np.float64).ravel()
    if x.size == 0:
        return np.zeros(1), np.zeros(0, int), np.zeros(1, np.int64)
    lo, hi = float(np.minimum.reduce(x)), float(np.maximum.reduce(x))  # x.min(), x.max() without their wrappers
    if hi - lo <= max(merge_tol, 1e-9):
        return np.array([x.mean()]), np.zeros(x.size, int), np.array([x.size], np.int64)
    hist, mids = _histogram(x, lo, hi, bins)
    cw = np.cumsum(hist)  # whole counts: exact, its last value is the total
    centres = np.interp(_QUANTILES3 if k == 3 else (np.arange(k) + 0.5) / k, cw / cw[-1], mids)
    # Lloyd on the histogram: a class takes the bins whose centres lie between the midpoints
    # to its neighbours' centres, so its weight and weighted sum are differences of
    # cumulative sums (plain floats: k is tiny and this loop runs thousands of times a wall)
    cum_w = [0.0] + cw.tolist()
    cum_s = [0.0] + np.cumsum(hist * mids).tolist()
    width, tol = (hi - lo) / bins, 1e-9 * (hi - lo)
    c = _lloyd3(centres.tolist(), cum_w, cum_s, lo=lo, width=width, tol=tol, bins=bins,
                iterations=iterations) if k == 3 else \
        _lloyd(centres.tolist(), cum_w, cum_s, lo=lo, width=width, tol=tol, bins=bins, iterations=iterations)
    # the classes that hold any bin (a bin goes to the nearest centre, ties to the lower)
    bounds = [0.5 * (q + p) for p, q in zip(c, c[1:], strict=False)]
    ends = [0] + np.searchsorted(mids, bounds, side="right").tolist() + [bins]
    centres = np.asarray([v for v, i, j in zip(c, ends, ends[1:], strict=False) if cum_w[j] > cum_w[i]])
    if merge_tol > 0 and centres.size > 1:
        groups = [[centres[0]]]
        for v in centres[1:]:
            if v - groups[-1][-1] < merge_tol:
                groups[-1].append(v)
            else:
                groups.append([v])
        if len(groups) < centres.size:
            # np.mean(g)'s value: the sum as np.add.reduce adds, over the count
            centres = np.array([float(np.add.reduce(np.asarray(g))) / len(g) for g in groups])
    # labels: the nearest centre (ties to the lower), as _nearest gives them, by comparisons
    labels = np.zeros(x.size, np.intp)
    above = [x.size]
    for v in (0.5 * (centres[1:] + centres[:-1])).tolist():
        gt = x > v
        labels += gt
        above.append(int(np.count_nonzero(gt)))
    counts = np.asarray([p - q for p, q in zip(above, above[1:] + [0], strict=True)], np.int64)
    sums = np.bincount(labels, weights=x, minlength=centres.size)
    centres = np.where(counts > 0, sums / np.maximum(counts, 1), centres)
    return centres, labels, counts


def _lloyd(c: list[float], cum_w: list[float], cum_s: list[float], *, lo: float, width: float, tol: float,
           bins: int, iterations: int) -> list[float]:
    """Lloyd's iterations on a histogram given by its cumulative weights and weighted sums."""
    for _ in range(iterations):
        cut = [0] + [min(bins, max(0, math.floor((0.5 * (p + q) - lo) / width - 0.5) + 1))
                     for p, q in zip(c, c[1:], strict=False)] + [bins]
        new = sorted((cum_s[j] - cum_s[i]) / (cum_w[j] - cum_w[i]) if cum_w[j] > cum_w[i] else old
                     for i, j, old in zip(cut, cut[1:], c, strict=False))
        done = max(abs(p - q) for p, q in zip(new, c, strict=True)) <= tol
        c = new
        if done:
            break
    return c


def _lloyd3(c: list[float], cum_w: list[float], cum_s: list[float], *, lo: float, width: float, tol: float,
            bins: int, iterations: int) -> list[float]:
    """:func:`_lloyd` for three classes, written out (the same arithmetic, the same result)."""
    a, b, d = c
    w0, s0, wn, sn = cum_w[0], cum_s[0], cum_w[bins], cum_s[bins]
    floor = math.floor
    for _ in range(iterations):
        i = min(bins, max(0, floor((0.5 * (a + b) - lo) / width - 0.5) + 1))
        j = min(bins, max(0, floor((0.5 * (b + d) - lo) / width - 0.5) + 1))
        wi, wj = cum_w[i], cum_w[j]
        na = (cum_s[i] - s0) / (wi - w0) if wi > w0 else a
        nb = (cum_s[j] - cum_s[i]) / (wj - wi) if wj > wi else b
        nd = (sn - cum_s[j]) / (wn - wj) if wn > wj else d
        na, nb, nd = sorted((na, nb, nd))
        done = max(abs(na - a), abs(nb - b), abs(nd - d)) <= tol
        a, b, d = na, nb, nd
        if done:
            break
    return [a, b, d]


def _histogram(x: np.ndarray, lo: float, hi: float, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """(counts, bin centres) of ``bins`` equal bins over [lo, hi] (the last bin closed)."""
    idx = ((x - lo) * (bins / (hi - lo))).astype(np.int64)  # >= 0 (x >= lo); bins at most (x = hi)
    if not math.isfinite(hi - lo):
        np.clip(idx, 0, bins - 1, out=idx)
    counts = np.bincount(idx, minlength=bins + 1)
    counts[bins - 1] += counts[bins]  # the last bin closed
    hist = counts[:bins].astype(np.float64)
    mids = lo + (_HALVES256 if bins == 256 else np.arange(bins) + 0.5) * ((hi - lo) / bins)
    return hist, mids


_HALVES256 = np.arange(256) + 0.5  # bin centres of the usual histogram, in bin widths
_HALVES256.flags.writeable = False
_QUANTILES3 = (np.arange(3) + 0.5) / 3
_QUANTILES3.flags.writeable = False


def hull_regions(mask: np.ndarray) -> np.ndarray:
    """The regions of ``mask``: each outer contour's convex hull, filled.

    "Contained in the regions of s1" then survives a ring broken by a gap of missing data or
    noise, which filling holes alone does not.
    """
    m = np.ascontiguousarray(mask, dtype=np.uint8)
    contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    out = np.zeros_like(m)
    if contours:
        cv2.fillPoly(out, [cv2.convexHull(c) for c in contours], 1)
    return (out > 0) | mask


def prototype_descriptors(channel: np.ndarray, mask: np.ndarray, with_segments: bool,
                          merge_tol: float = 0.0) -> list[float]:
    """v1..v4 (and v5 when ``with_segments``) of one component (equations 1-4).

    With a single class (a uniform component) the second prototype is the first, and
    no pixel of it lies inside the first's regions.
    """
    vals = channel[mask]
    n = vals.size
    if n == 0:
        return [0.0] * (5 if with_segments else 4)
    centres, labels, counts = _kmeans_1d(vals, 3, merge_tol)
    cs, ns = centres.tolist(), counts.tolist()
    if len(cs) < 2:
        return [cs[0], cs[0], 1.0, 0.0] + ([0.0] if with_segments else [])
    first, second = sorted(range(len(cs)), key=lambda i: (-ns[i], cs[i]))[:2]  # most populous first, ties by value
    lab_img = np.full(mask.shape, -1, np.int8)
    lab_img[mask] = labels
    m1 = lab_img == first
    n1 = ns[first]
    m2 = lab_img == second
    regions1 = hull_regions(m1)
    inside = m2 & regions1
    v1 = cs[first]
    v2 = cs[second] if ns[second] > 0 else v1
    v3 = n1 / n
    v4 = float(np.count_nonzero(inside)) / n1 if n1 else 0.0
    out = [v1, v2, v3, v4]
    if with_segments:
        _, nseg = ndimage.label(inside, structure=_EIGHT)
        out.append(float(nseg))
    return out


def roundness(mask: np.ndarray) -> float:
    """4 pi A / P^2 of the outer contours of ``mask`` (equation 13); 0 for degenerate shapes."""
    m = np.ascontiguousarray(mask, dtype=np.uint8)
    contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    area = sum(cv2.contourArea(c) for c in contours)
    perim = sum(cv2.arcLength(c, True) for c in contours)
    if perim <= 0 or area <= 0:
        return 0.0
    return float(min(1.0, 4.0 * np.pi * area / perim ** 2))


def glcm_energy(lightness: np.ndarray, mask: np.ndarray, levels: int) -> float:
    """Energy of the symmetric 4-direction grey-level co-occurrence matrix (equation 14).

    ``lightness`` is Lab L in [0, 100]; only pairs of two foreground pixels count.
    """
    q = (lightness / 100.0 * levels).astype(np.int32)
    np.minimum(q, levels - 1, out=q)  # np.clip, without its Python wrapper
    np.maximum(q, 0, out=q)
    code = q * np.int32(levels)
    h, w = q.shape
    pairs = []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        r0, r1 = 0, h - dr
        c0, c1 = max(0, -dc), w - max(0, dc)
        ok = mask[r0:r1, c0:c1] & mask[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
        pairs.append((code[r0:r1, c0:c1] + q[r0 + dr:r1 + dr, c0 + dc:c1 + dc])[ok])
    one_way = np.bincount(np.concatenate(pairs), minlength=levels * levels).reshape(levels, levels)
    counts = (one_way + one_way.T).ravel().astype(np.float64)  # symmetric: each pair both ways (exact counts)
    total = counts.sum()
    if total <= 0:
        return 1.0
    p = counts / total
    return float((p * p).sum())


def global_descriptors(rgb: np.ndarray, mask: np.ndarray,
                       settings: ColourRecognitionSettings | None = None) -> np.ndarray:
    """The pattern V = (v1, ..., v15) of the foreground ``mask`` of ``rgb`` (equations 1-14)."""
    mask = np.asarray(mask, bool)
    if mask.shape != rgb.shape[:2]:
        raise ValueError(f"mask {mask.shape} does not match image {rgb.shape[:2]}")
    hsv, lab = rgb_to_hsv_lab(rgb)
    return descriptors_of(hsv, lab, mask, settings)


def descriptors_of(hsv: np.ndarray, lab: np.ndarray, mask: np.ndarray,
                   settings: ColourRecognitionSettings | None = None) -> np.ndarray:
    """:func:`global_descriptors` of an image already converted by :func:`rgb_to_hsv_lab`
    (several masks of one image convert it once)."""
    s = settings or ColourRecognitionSettings()
    mask = np.asarray(mask, bool)
    v = prototype_descriptors(hsv[..., 1], mask, True, s.cluster_merge_s)
    v += prototype_descriptors(lab[..., 1], mask, False, s.cluster_merge_ab)
    v += prototype_descriptors(lab[..., 2], mask, False, s.cluster_merge_ab)
    v.append(roundness(mask))
    v.append(glcm_energy(lab[..., 0], mask, s.glcm_levels) if mask.any() else 0.0)
    return np.asarray(v, np.float64)


def normalise_descriptors(v: np.ndarray, settings: ColourRecognitionSettings | None = None) -> np.ndarray:
    """Map raw patterns (..., 15) onto unit ranges so that each descriptor weighs alike."""
    s = settings or ColourRecognitionSettings()
    out = np.array(v, np.float64, copy=True)
    out[..., 4] = np.minimum(out[..., 4], s.segment_cap) / s.segment_cap
    out[..., _AB] /= s.ab_scale  # element by element: one call for the columns, the same values
    out[..., _UNIT] = np.clip(out[..., _UNIT], 0.0, 1.0)
    return out


_AB = [5, 6, 9, 10]  # a and b: divided by ab_scale
_UNIT = [2, 3, 7, 8, 11, 12, 13, 14]  # shares, ratios, roundness and energy: within [0, 1]


def descriptor_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray | float:
    """rho_C: RMS difference of normalised patterns (Euclidean / sqrt(15)); broadcasts."""
    d = np.sqrt(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=-1) / N_DESCRIPTORS)
    return float(d) if np.ndim(d) == 0 else d
