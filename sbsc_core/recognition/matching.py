"""The matching toolkit shared by depth and colour recognition.

Small functions with one job each, modelled on scikit-image: :func:`ncc_map` and
:func:`masked_ncc` return correlation maps (like ``skimage.feature.match_template``,
computed with ``cv2.matchTemplate``), :func:`pick_peaks` picks peaks from a map (like
``skimage.feature.peak_local_max``, greedily, with a judge), and the box operations
(:func:`box_at`, :func:`box_overlap`, :func:`boxes_from_mask`, :func:`cluster_boxes`,
:func:`nms`) work on :class:`~sbsc_core.types.Box`. :func:`match_in_rois` combines them
for the paper's search of a model around the regions of interest (sections 4.2, 4.3).

Templates may be turned by any in-plane angle (:func:`rotate_template`): the rotated
model is drawn on a canvas large enough to hold it, the background being 0 (the wall).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from ..types import Box, Candidate

MASKED_FLOOR = 0.5  # masked NCC also down to this x min_known (a too little seen object peaks there)

# --------------------------------------------------------------------------- boxes


def box_at(centre: tuple[float, float], h: int, w: int) -> Box:
    """The ``h`` x ``w`` box whose centre is nearest to ``centre`` (row, col)."""
    r0 = int(np.floor(centre[0] - (h - 1) / 2.0 + 0.5))
    c0 = int(np.floor(centre[1] - (w - 1) / 2.0 + 0.5))
    return Box(r0, c0, r0 + h, c0 + w)


def box_overlap(a: Box, b: Box) -> float:
    """Intersection over the smaller area (1 when one box lies inside the other)."""
    small = min(a.area, b.area)
    return a.intersection(b) / small if small > 0 else 0.0


def boxes_from_mask(mask: np.ndarray, min_side_px: int, min_area_px: int = 1) -> list[Box]:
    """Bounding rectangles of the 8-connected regions of ``mask`` that are large enough."""
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    out = []
    for i in range(1, n):
        x, y, w, h, a = (int(v) for v in stats[i])
        if max(w, h) >= min_side_px and a >= min_area_px:
            out.append(Box(y, x, y + h, x + w))
    return out


def cluster_boxes(boxes: list[Box], gap_px: int = 0, min_overlap: float = 0.0, *,
                  longest_px: float | None = None) -> list[Box]:
    """Merge boxes that overlap (or lie within ``gap_px``) until none do (paper, Figure 3 e).

    With ``min_overlap`` > 0 two boxes are merged only when their intersection exceeds
    that fraction of the smaller one. With ``longest_px`` (the library's limit: no object
    is longer), a box longer than that is no object's part: it is kept as it is and gathers
    no other box (a door frame joined to the skirting spans the wall, and would merge every
    object inside it into one RoI).
    """
    if longest_px is not None:
        large = [b for b in boxes if max(b.height, b.width) > longest_px]
        parts = [b for b in boxes if max(b.height, b.width) <= longest_px]
        return sorted(cluster_boxes(parts, gap_px, min_overlap) + large, key=lambda b: (b.r0, b.c0, b.r1, b.c1))
    work = list(boxes)
    changed = True
    while changed:
        changed = False
        out: list[Box] = []
        for b in work:
            merged = True
            while merged:
                merged = False
                for i, o in enumerate(out):
                    grown = Box(o.r0 - gap_px, o.c0 - gap_px, o.r1 + gap_px, o.c1 + gap_px)
                    inter = grown.intersection(b)
                    if inter > 0 and (min_overlap <= 0 or o.intersection(b) > min_overlap * min(o.area, b.area)):
                        b = o.union_box(b)
                        out.pop(i)
                        merged = changed = True
                        break
            out.append(b)
        work = out
    return sorted(work, key=lambda b: (b.r0, b.c0, b.r1, b.c1))


def nms(cands: list[Candidate], overlap: float, higher_is_better: bool = True,
        upright_bonus: float = 0.0) -> list[Candidate]:
    """Keep the best of candidates of one class whose boxes overlap by more than ``overlap``.

    Unrotated candidates rank ``upright_bonus`` higher (objects are usually mounted upright).
    """
    sign = 1.0 if higher_is_better else -1.0
    order = sorted(cands, key=lambda c: -(sign * c.score + (upright_bonus if c.rotation_deg == 0 else 0.0)))
    kept: list[Candidate] = []
    for c in order:
        if all(k.wall_id != c.wall_id or k.class_id != c.class_id or box_overlap(k.box, c.box) <= overlap
               for k in kept):
            kept.append(c)
    return kept


def group_boxes(boxes: list[Box], *, height: int, width: int, gap_px: int, slack_px: int = 0) -> list[Box]:
    """Boxes enclosing two or more of ``boxes`` that fit together in a ``height`` x ``width`` footprint.

    The parts of one complex object need not touch: the columns of a radiator with the wall
    showing between them are separate RoIs, and the object's centre may lie in a gap, out of
    reach of a search around any one of them. Starting from each box, the nearest others
    within ``gap_px`` are added while the enclosing box still fits the footprint (either
    way round, with ``slack_px`` to spare: a RoI's edge is blurred). Returns each distinct
    group's enclosing box once, sorted.
    """
    big, small = max(height, width) + slack_px, min(height, width) + slack_px

    def fits(b: Box) -> bool:
        return max(b.height, b.width) <= big and min(b.height, b.width) <= small

    def gap(a: Box, b: Box) -> int:
        return max(a.r0 - b.r1, b.r0 - a.r1, a.c0 - b.c1, b.c0 - a.c1, 0)

    out: set[tuple[int, int, int, int]] = set()
    for a in boxes:
        if not fits(a):
            continue
        group, n, left = a, 1, [b for b in boxes if b is not a]
        while True:  # grow by the nearest box within reach that keeps the group in the footprint
            reach = [b for b in left if gap(group, b) <= gap_px and fits(group.union_box(b))]
            if not reach:
                break
            b = min(reach, key=lambda b: gap(group, b))
            group, n = group.union_box(b), n + 1
            left = [o for o in left if o is not b and not group.intersection(o) == o.area]
        if n >= 2:
            out.add((group.r0, group.c0, group.r1, group.c1))
    return [Box(*t) for t in sorted(out)]


def crop_padded(image: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """``image[r0:r1, c0:c1]`` where the parts outside the image are zeros."""
    h, w = image.shape[:2]
    out = np.zeros((r1 - r0, c1 - c0) + image.shape[2:], image.dtype)
    a, b = max(r0, 0), min(r1, h)
    c, d = max(c0, 0), min(c1, w)
    if a < b and c < d:
        out[a - r0:b - r0, c - c0:d - c0] = image[a:b, c:d]
    return out


# --------------------------------------------------------------------------- templates


def padded_template(template: np.ndarray, pad_px: int, sigma_px: float = 0.0) -> np.ndarray:
    """``template`` with a border of ``pad_px`` zeros (the wall), Gaussian-smoothed if asked."""
    tp = cv2.copyMakeBorder(np.ascontiguousarray(template, dtype=np.float32), pad_px, pad_px, pad_px, pad_px,
                            cv2.BORDER_CONSTANT, value=0)
    if sigma_px > 0:
        tp = cv2.GaussianBlur(tp, (0, 0), sigma_px, borderType=cv2.BORDER_CONSTANT)
    return tp


def rotated_size(h: int, w: int, deg: float) -> tuple[int, int]:
    """(h, w) of the axis-aligned box holding an ``h`` x ``w`` rectangle turned by ``deg``
    (:func:`rotate_template` may add a pixel to keep the parity of ``h`` and ``w``)."""
    a = np.deg2rad(float(deg) % 180.0)
    ca, sa = abs(np.cos(a)), abs(np.sin(a))
    return max(1, int(round(h * ca + w * sa))), max(1, int(round(w * ca + h * sa)))


def rotate_template(image: np.ndarray, deg: float, *, supersample: int = 4) -> np.ndarray:
    """``image`` turned counter-clockwise by ``deg`` about its centre, on a canvas that holds it.

    Multiples of 90 degrees are exact (``np.rot90``). Other angles are rendered like a scan
    samples the turned object: each pixel is the mean over ``supersample`` x
    ``supersample`` points of the pixelated model (no extra blur, whatever the angle, so
    correlations at nearby angles compare fairly). The uncovered canvas is 0 (the wall).
    Works on (H, W) and (H, W, C).
    """
    deg = float(deg) % 360.0
    if abs(deg - round(deg / 90.0) * 90.0) < 1e-9:
        return np.ascontiguousarray(np.rot90(image, int(round(deg / 90.0)) % 4))
    h, w = image.shape[:2]
    nh, nw = rotated_size(h, w, deg)
    nh, nw = nh + (nh - h) % 2, nw + (nw - w) % 2  # same parity: the centre stays on the pixel grid
    m = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), deg, 1.0)
    m[0, 2] += (nw - w) / 2.0
    m[1, 2] += (nh - h) / 2.0
    k = max(1, int(supersample))
    m4 = m * k
    m4[:, 2] += (k - 1) / 2.0  # pixel centres of the k-times finer canvas
    src = np.ascontiguousarray(image, dtype=np.float32)
    fine = cv2.warpAffine(src, m4, (nw * k, nh * k), flags=cv2.INTER_NEAREST,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    out = cv2.resize(fine, (nw, nh), interpolation=cv2.INTER_AREA)
    return out.reshape((nh, nw) + image.shape[2:])


def rotated_variants(img: np.ndarray, rotations: tuple[float, ...]) -> list[tuple[float, np.ndarray]]:
    """(degrees, image) for each distinct in-plane rotation (counter-clockwise, any angle).

    Multiples of 90 that give the same image (a symmetric model) are listed once.
    """
    out: list[tuple[float, np.ndarray]] = []
    for deg in rotations:
        r = rotate_template(img, deg)
        if any(o.shape == r.shape and np.allclose(o, r, atol=1e-6, equal_nan=True) for _, o in out):
            continue
        d = float(deg) % 360.0
        out.append((int(d) if d == int(d) else d, r))
    return out


# --------------------------------------------------------------------------- correlation maps


def ncc_map(image: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation (``cv2.TM_CCOEFF_NORMED``) of every valid window.

    Like ``skimage.feature.match_template`` without padding: the map has shape
    ``image.shape - template.shape + 1`` and is indexed by the window's top-left pixel.
    Undefined values (flat windows) are -1.
    """
    res = cv2.matchTemplate(image, template, cv2.TM_CCOEFF_NORMED)
    bad = ~np.isfinite(res)  # what np.nan_to_num(res, nan=-1, posinf=-1, neginf=-1) sets, in place
    if bad.any():
        res[bad] = -1.0
    return res


def masked_ncc(region: np.ndarray, known: np.ndarray, template: np.ndarray, min_pixels: int = 16) -> np.ndarray:
    """Normalised cross-correlation of ``template`` over the ``known`` pixels of each window.

    Like ``cv2.TM_CCOEFF_NORMED`` (same output shape), but the means and energies of both
    image and template are taken over the window's known pixels only (Padfield, "Masked
    object registration in the Fourier domain", 2012): unseen pixels neither add nor
    remove evidence. Windows with fewer than ``min_pixels`` known pixels or no variance get -1.
    """
    th, tw = template.shape
    m = (known > 0).astype(np.float32)
    scale = 1000.0  # metres to mm: float32 sums stay well conditioned
    base = float(np.mean(region[m > 0])) if m.any() else 0.0
    f = ((region.astype(np.float64) - base) * scale * m).astype(np.float32)
    t = ((template.astype(np.float64) - template.mean()) * scale).astype(np.float32)
    oh, ow = region.shape[0] - th + 1, region.shape[1] - tw + 1

    def box(x: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(x.astype(np.float64), -1, (tw, th), anchor=(0, 0), normalize=False,
                             borderType=cv2.BORDER_CONSTANT)[:oh, :ow]

    n = box(m)
    sf, sff = box(f), box(f.astype(np.float64) ** 2)
    st = cv2.matchTemplate(m, t, cv2.TM_CCORR).astype(np.float64)
    stt = cv2.matchTemplate(m, t * t, cv2.TM_CCORR).astype(np.float64)
    sft = cv2.matchTemplate(f, t, cv2.TM_CCORR).astype(np.float64)
    nn = np.maximum(n, 1.0)
    num = sft - sf * st / nn
    vf = sff - sf * sf / nn
    vt = stt - st * st / nn
    den = np.sqrt(np.maximum(vf, 0.0) * np.maximum(vt, 0.0))
    ok = (n >= min_pixels) & (den > 1e-9 * np.maximum(nn, 1.0))
    out = np.full((oh, ow), -1.0)
    out[ok] = np.clip(num[ok] / den[ok], -1.0, 1.0)
    return out.astype(np.float32)


def patch_ncc(patch: np.ndarray, template: np.ndarray, mask: np.ndarray | None = None) -> float:
    """NCC of one patch with a template of the same shape (over ``mask`` pixels if given).

    Multi-channel patches are correlated as one vector per pixel (means per channel).
    """
    p = np.asarray(patch, np.float64)
    t = np.asarray(template, np.float64)
    if mask is not None:
        p, t = p[mask], t[mask]
    else:
        p, t = p.reshape(-1, *p.shape[2:]), t.reshape(-1, *t.shape[2:])
    if p.shape[0] < 2:
        return -1.0
    p = p - p.mean(axis=0)
    t = t - t.mean(axis=0)
    den = float(np.sqrt((p * p).sum() * (t * t).sum()))
    return float((p * t).sum() / den) if den > 1e-12 else -1.0


def least_squares_gain(patch: np.ndarray, template: np.ndarray, known: np.ndarray | None = None, *,
                       centred: tuple[np.ndarray, float] | None = None) -> float:
    """Least-squares amplitude of ``patch`` relative to ``template`` (over ``known`` pixels if given).

    ``centred``: :func:`centred_template` of ``template``, when every pixel counts (``known``
    None) and the caller measures many patches against one template.
    """
    if known is not None:
        if known.sum() < 2:
            return 0.0
        t = template[known].astype(np.float64)
        x = patch[known].astype(np.float64)
        t = t - t.mean(axis=0)
        tt = float((t * t).sum())
    else:
        t, tt = centred_template(template) if centred is None else centred
        n = template.shape[0] * template.shape[1]
        x = patch.reshape(n, -1).astype(np.float64)
    return float((t * (x - x.mean(axis=0))).sum() / tt) if tt > 1e-18 else 0.0


def centred_template(template: np.ndarray) -> tuple[np.ndarray, float]:
    """``template``'s pixels (n, channels) in float64 less their mean, and their sum of squares
    (what :func:`least_squares_gain` measures every patch against)."""
    n = template.shape[0] * template.shape[1]
    t = template.reshape(n, -1).astype(np.float64)
    t = t - t.mean(axis=0)
    return t, float((t * t).sum())


def window_energy(region: np.ndarray, ph: int, pw: int) -> np.ndarray:
    """Sum of squared deviations from the mean of every ``ph`` x ``pw`` window (top-left indexed)."""
    x = region.astype(np.float64)
    if x.ndim == 2:
        x = x[..., None]
    n = ph * pw
    oh, ow = x.shape[0] - ph + 1, x.shape[1] - pw + 1
    total = np.zeros((oh, ow))
    for ch in range(x.shape[2]):
        c = np.ascontiguousarray(x[..., ch])
        s1 = cv2.boxFilter(c, -1, (pw, ph), anchor=(0, 0), normalize=False, borderType=cv2.BORDER_CONSTANT)
        s2 = cv2.sqrBoxFilter(c, -1, (pw, ph), anchor=(0, 0), normalize=False, borderType=cv2.BORDER_CONSTANT)
        total += s2[:oh, :ow] - s1[:oh, :ow] ** 2 / n
    return total


def footprint_share(known: np.ndarray, ph: int, pw: int, *, pad_px: int, shape: tuple[int, ...]) -> np.ndarray:
    """Share of ``known`` pixels in the footprint (a ``ph`` x ``pw`` window less its pad), top-left indexed."""
    fh, fw = ph - 2 * pad_px, pw - 2 * pad_px
    s = cv2.boxFilter(known, cv2.CV_32F, (fw, fh), anchor=(0, 0), normalize=True, borderType=cv2.BORDER_CONSTANT)
    return s[pad_px:pad_px + shape[0], pad_px:pad_px + shape[1]]


# --------------------------------------------------------------------------- peaks


def subpixel_offset(corr: np.ndarray, y: int, x: int) -> tuple[float, float]:
    """Parabolic refinement of a correlation peak at (y, x): offsets in pixels, within +-0.5."""
    def fit(a: float, b: float, c: float) -> float:
        den = a - 2.0 * b + c
        if not np.isfinite(den) or den >= 0:
            return 0.0
        return float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))

    dy = fit(corr[y - 1, x], corr[y, x], corr[y + 1, x]) if 0 < y < corr.shape[0] - 1 else 0.0
    dx = fit(corr[y, x - 1], corr[y, x], corr[y, x + 1]) if 0 < x < corr.shape[1] - 1 else 0.0
    return dy, dx


ACCEPT, REFUSE_AREA, REFUSE_POINT = "accept", "refuse_area", "refuse_point"


def pick_peaks(corr: np.ndarray, *, threshold: float, max_peaks: int, exclude: tuple[int, int],
               judge: Callable[[int, int], str] | None = None) -> Iterator[tuple[float, int, int]]:
    """Peaks of ``corr`` >= ``threshold``, best first, at most ``max_peaks`` accepted.

    Like ``skimage.feature.peak_local_max`` with ``exclude_border=False``, but greedy and
    judged: each maximum is offered to ``judge(y, x)``, which accepts it (its neighbourhood
    of +-``exclude`` = (rows, cols) is then suppressed), refuses its neighbourhood
    (``REFUSE_AREA``) or only that point (``REFUSE_POINT``, the next best is tried).
    Yields (score, y, x) of the accepted peaks. ``corr`` is not modified; -inf never peaks.
    """
    work = np.array(corr, dtype=np.float64, copy=True)
    hy, hx = exclude
    found = 0
    while found < max_peaks:
        y, x = np.unravel_index(int(np.argmax(work)), work.shape)
        score = float(work[y, x])
        if not np.isfinite(score) or score < threshold:
            return
        verdict = ACCEPT if judge is None else judge(int(y), int(x))
        if verdict == REFUSE_POINT:
            work[y, x] = -np.inf
            continue
        work[max(0, y - hy): y + hy + 1, max(0, x - hx): x + hx + 1] = -np.inf
        if verdict == ACCEPT:
            found += 1
            yield score, int(y), int(x)


# --------------------------------------------------------------------------- search around RoIs


@dataclass
class Match:
    """One peak of a template's correlation around a RoI."""

    score: float  # NCC (plain or masked, whichever is higher)
    row: float  # sub-pixel centre of the (unpadded) template, image pixels
    col: float
    roi: Box
    gain: float  # least-squares amplitude of the image against the padded template


def _search_window(roi: Box, margin_px: int, centre_off: tuple[float, float]) -> tuple[int, int, int, int]:
    """Top-left range (r0, r1, c0, c1) of padded windows whose centre may lie in ``roi`` + margin."""
    cy_off, cx_off = centre_off
    cr0, cr1 = roi.r0 - margin_px, roi.r1 - 1 + margin_px
    cc0, cc1 = roi.c0 - margin_px, roi.c1 - 1 + margin_px
    return (int(np.floor(cr0 - cy_off)) - 1, int(np.ceil(cr1 - cy_off)) + 1,
            int(np.floor(cc0 - cx_off)) - 1, int(np.ceil(cc1 - cx_off)) + 1)


def match_in_rois(
    image: np.ndarray,
    template: np.ndarray,
    rois: list[Box],
    *,
    threshold: float,
    pad_px: int,
    margin_px: int,
    max_peaks: int,
    sigma_px: float = 0.0,
    gain_range: tuple[float, float] | None = None,
    min_energy: float = 0.0,
    accept: Callable[[float, float, float], bool] | None = None,
    known: np.ndarray | None = None,
    min_known: float = 0.0,
    full_known: float = 1.0,
    masked_pre: float = -1.0,
    windows: dict | None = None,
) -> list[Match]:
    """Normalised cross-correlation of ``template`` (padded by ``pad_px`` of zeros) around RoIs.

    Parameters
    ----------
    image : (H, W) or (H, W, C) float32 with the background at 0 (already smoothed by
        ``sigma_px`` if the template is to be).
    template : the model, (h, w) or (h, w, C), background 0.
    rois : the template's centre may lie anywhere in a RoI grown by ``margin_px``.
    threshold : peaks of the NCC map below this are no matches (mu_D of the paper).
    max_peaks : matches per RoI at most; each suppresses a neighbourhood of half the template.
    gain_range : the least-squares amplitude of the image patch relative to the padded
        template must lie in this range (depth is metric).
    min_energy : windows whose energy (sum of squared deviations) is at most this are never
        peaks (their correlation is undefined).
    accept : ``accept(row, col, gain)`` may refuse a peak (a plausibility check).
    known : bool mask of the pixels that have data (2-D images only). A peak whose
        footprint has data on less than ``min_known`` of it is refused with its
        neighbourhood; a footprint with less than ``full_known`` is also correlated over
        its known pixels only (:func:`masked_ncc`; the higher coefficient counts, the gain
        is then the masked one), computed only around windows reaching ``masked_pre`` in
        the plain map.
    windows : a dict the caller keeps across calls on the same ``image`` and ``known``:
        what a RoI's map needs of the image alone (its crop, the flat windows, the known
        shares), computed once per RoI and window size for every template of that size
        (a model's turns by 180 degrees, classes of one size).

    Returns
    -------
    list of Match, each with its sub-pixel centre in image pixel coordinates.
    """
    h, w = template.shape[:2]
    tp = padded_template(template, pad_px, sigma_px)
    ph, pw = tp.shape[:2]
    if float(((tp - tp.reshape(ph * pw, -1).mean(axis=0)) ** 2).sum()) < 1e-18:
        return []
    opts = _Search(pad_px, margin_px, min_energy, min_known, full_known, masked_pre)
    centred = centred_template(tp)  # the gain of every unmasked peak is measured against it
    out: list[Match] = []
    for roi in rois:
        c = _correlate_around(image, tp, (h, w), roi, known=known if image.ndim == 2 else None, o=opts,
                              windows=windows)

        def judge(y: int, x: int, c: _RoiCorrelation = c) -> str:
            if c.share is not None and c.share[y, x] < min_known:  # seen too little: no object here
                return REFUSE_AREA
            patch = c.region[y:y + ph, x:x + pw]
            if c.masked[y, x] and c.known is not None:
                gain = least_squares_gain(patch, tp, c.known[y:y + ph, x:x + pw] > 0)
            else:
                gain = least_squares_gain(patch, tp, centred=centred)
            if gain_range is not None and not gain_range[0] <= gain <= gain_range[1]:
                return REFUSE_POINT  # a wrong amplitude: not this class here, look on
            dy, dx = subpixel_offset(c.corr, y, x)
            r, col = float(c.rows[y] + dy), float(c.cols[x] + dx)
            if accept is not None and not accept(r, col, gain):
                return REFUSE_POINT  # a wrong context: look on
            c.kept[(y, x)] = (r, col, gain)
            return ACCEPT

        work = np.where(c.valid, c.corr, -np.inf)
        for score, y, x in pick_peaks(work, threshold=threshold, max_peaks=max_peaks,
                                      exclude=(max(1, h // 2), max(1, w // 2)), judge=judge):
            r, col, gain = c.kept[(y, x)]
            out.append(Match(score, r, col, roi, gain))
    return out


@dataclass(frozen=True)
class _Search:
    pad_px: int
    margin_px: int
    min_energy: float
    min_known: float
    full_known: float
    masked_pre: float


@dataclass
class _RoiCorrelation:
    """The correlation map of a padded template around one RoI."""

    region: np.ndarray  # the image crop the map was computed on
    corr: np.ndarray  # NCC by window top-left (masked where that is higher)
    rows: np.ndarray  # image row of the template centre for each map row
    cols: np.ndarray
    valid: np.ndarray  # windows whose centre lies in the RoI + margin and that are not flat
    known: np.ndarray | None  # known mask of ``region`` (float32) or None
    share: np.ndarray | None  # known share of each window's footprint
    masked: np.ndarray  # windows whose coefficient is the masked one
    kept: dict[tuple[int, int], tuple[float, float, float]]


@dataclass(frozen=True)
class _RoiWindows:
    """What the correlation maps around one RoI need of the image alone, for every padded
    template of one size (:func:`_roi_windows`; read only)."""

    region: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    valid: np.ndarray
    known: np.ndarray | None
    share: np.ndarray | None


def _roi_windows(image: np.ndarray, padded: tuple[int, int], size: tuple[int, int], roi: Box,
                 *, known: np.ndarray | None, o: _Search) -> _RoiWindows:
    """The crop of ``image`` (and ``known``) around ``roi`` for a padded template of shape
    ``padded`` (unpadded ``size``), the map's rows and columns, the windows whose centre lies
    in the RoI and that are not flat, and the known share of each window's footprint."""
    h, w = size
    ph, pw = padded
    cy_off, cx_off = o.pad_px + (h - 1) / 2.0, o.pad_px + (w - 1) / 2.0
    cr0, cr1 = roi.r0 - o.margin_px, roi.r1 - 1 + o.margin_px
    cc0, cc1 = roi.c0 - o.margin_px, roi.c1 - 1 + o.margin_px
    r_a, tl_r1, c_a, tl_c1 = _search_window(roi, o.margin_px, (cy_off, cx_off))
    region = crop_padded(image, r_a, tl_r1 + ph, c_a, tl_c1 + pw)
    shape = (region.shape[0] - ph + 1, region.shape[1] - pw + 1)  # that of the NCC map
    ys = np.arange(shape[0]) + r_a + cy_off
    xs = np.arange(shape[1]) + c_a + cx_off
    valid = ((ys >= cr0) & (ys <= cr1))[:, None] & ((xs >= cc0) & (xs <= cc1))[None, :]
    valid &= window_energy(region, ph, pw) > o.min_energy  # a flat patch has no defined correlation
    kreg = share = None
    if known is not None:
        kreg = crop_padded(known, r_a, tl_r1 + ph, c_a, tl_c1 + pw).astype(np.float32)
        share = footprint_share(kreg, ph, pw, pad_px=o.pad_px, shape=shape)
    return _RoiWindows(region, ys, xs, valid, kreg, share)


def _correlate_around(image: np.ndarray, tp: np.ndarray, size: tuple[int, int], roi: Box,
                      *, known: np.ndarray | None, o: _Search, windows: dict | None = None) -> _RoiCorrelation:
    """NCC map of the padded template ``tp`` (unpadded ``size``) whose centre lies in ``roi``;
    ``windows`` (see :func:`match_in_rois`) keeps the RoI's :class:`_RoiWindows` by size."""
    ph, pw = tp.shape[:2]
    key = (roi.r0, roi.c0, roi.r1, roi.c1, size, (ph, pw), known is None, o)
    win = None if windows is None else windows.get(key)
    if win is None:
        win = _roi_windows(image, (ph, pw), size, roi, known=known, o=o)
        if windows is not None:
            windows[key] = win
    region, valid, kreg, share = win.region, win.valid, win.known, win.share
    res = ncc_map(region, tp)
    masked = np.zeros(res.shape, bool)
    if known is not None:
        # masked also a little below min_known: an object seen too little must still peak
        # there (and be refused), not on the border of the allowed windows beside it
        partial = valid & (share < o.full_known) & (share >= MASKED_FLOOR * o.min_known)
        todo = partial & (res >= o.masked_pre)
        if todo.any():  # the masked map only over the windows that may need it
            yy, xx = np.nonzero(todo)
            y0, y1, x0, x1 = yy.min(), yy.max() + 1, xx.min(), xx.max() + 1
            mres = np.full(res.shape, -1.0, np.float32)
            mres[y0:y1, x0:x1] = masked_ncc(region[y0:y1 + ph - 1, x0:x1 + pw - 1],
                                            kreg[y0:y1 + ph - 1, x0:x1 + pw - 1], tp)
            masked = partial & (mres > res)
            res = np.where(masked, mres, res)
    return _RoiCorrelation(region, res, win.rows, win.cols, valid, kreg, share, masked, {})


# --------------------------------------------------------------------------- orientation


def estimate_turn(mask: np.ndarray, *, min_pixels: int = 30, min_fill: float = 0.8) -> float | None:
    """The in-plane turn (degrees, counter-clockwise, in (-45, 45]) of the largest region of ``mask``.

    The turn of its minimum-area rectangle (``cv2.minAreaRect``), defined modulo 90 degrees.
    None when the region has fewer than ``min_pixels`` pixels or fills less than
    ``min_fill`` of that rectangle (a round or irregular shape has no defined turn).
    """
    m = np.ascontiguousarray(mask, dtype=np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    if n < 2:
        return None
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    area = int(stats[k, cv2.CC_STAT_AREA])
    if area < min_pixels:
        return None
    ys, xs = np.nonzero(lab == k)
    (_, _), (rw, rh), angle = cv2.minAreaRect(np.column_stack([xs, ys]).astype(np.float32))
    if rw * rh <= 0 or area / ((rw + 1.0) * (rh + 1.0)) < min_fill:
        return None
    turn = (-float(angle)) % 90.0  # OpenCV's angle is clockwise in image coordinates
    return turn - 90.0 if turn > 45.0 else turn


def turn_angles(turn: float, *, refine: tuple[float, ...] = ()) -> list[float]:
    """The four model rotations (``turn`` + k x 90) that may fit a region turned by ``turn``,
    each followed by its refinements ``turn + k x 90 + d`` for d in ``refine``."""
    return [round((turn + 90.0 * k + d) % 360.0, 3) for k in range(4) for d in (0.0, *refine)]
