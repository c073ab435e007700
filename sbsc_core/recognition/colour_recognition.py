"""Recognition with colour (paper, section 4.3, Algorithm II).

1. **RoIs.** The colour image J_C is thresholded against the wall: a pixel is foreground
   (black in the paper's J_BW) when its colour is far from the wall's. The paper takes
   the threshold from the wall area's mean intensity; here the distance is the CIE76
   delta E in Lab (so coloured objects of the wall's lightness are seen too) from a local
   estimate of the wall colour (the visible wall area averaged over
   ``background_window_m``, which follows slow illumination changes), and the threshold is
   ``max(threshold_offset, noise_k x the wall's own median deviation)``, so a noisy scan
   does not flood the image with foreground. The frames (casings) hugging the openings
   are taken out of J_BW (``opening_frames``), so an object touching one keeps a RoI of
   its own. Compact foreground regions give RoIs (bounding rectangles), clustered when
   they overlap or touch.
2. **Patterns.** Each RoI's 15 global descriptors (``colour_descriptors``) are compared
   with the prototype of each expected class by a minimum-distance classifier on the
   normalised descriptors; a RoI joins the list {C} of every class whose distance rho_C
   is at most mu_C = 0.2 (as in the paper; ``nearest_only`` keeps the nearest class
   only). The consensus decides between classes that share a place.

Prototypes are learnt from the library's front views. The paper learns them once; here
they are also re-learnt for each wall colour (``ColourPrototypes.for_wall``): every view
is composited on the wall's colour, blurred like a scan and passed through the very
foreground test used on the scene, so the prototype describes what the recognizer can
see of the object on that wall (a white socket on a white wall shows only its dark
holes; a sign's white border vanishes on a white wall). This keeps the classifier
consistent on low-contrast walls, and an object that is invisible on a wall's colour has
no colour prototype there (it is left to depth, as in the paper's Scenario II).

The scale is known (the orthoimage and the library share ``pixel_m``), so a RoI is only
compared with classes whose visible extent has a similar size (``size_tolerance``,
either orientation), and the footprint is placed by colour cross-correlation of the
composited view around the RoI (``refine_position``) rather than at the RoI centroid.
Finally the colour may not contradict the geometry: a class whose model stands out of
the wall is refused where the scan shows a flat wall or no data (``depth_agrees``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from ..settings import ColourRecognitionSettings
from ..types import Box, Candidate, Orthoimage, WallArea
from .colour_descriptors import (
    descriptor_distance,
    descriptors_of,
    global_descriptors,
    normalise_descriptors,
    rgb_to_hsv,
)
from .depth_recognition import fill_gaps
from .matching import (
    box_at,
    boxes_from_mask,
    cluster_boxes,
    crop_padded,
    estimate_turn,
    match_in_rois,
    rotate_template,
    rotated_variants,
    turn_angles,
)
from .medians import median
from .templates import ModelTemplate

# --------------------------------------------------------------------------- foreground


@dataclass
class ColourImage:
    """J_C of one wall prepared for recognition."""

    rgb: np.ndarray  # (H, W, 3) uint8, median filtered
    lab: np.ndarray  # (H, W, 3) float32 Lab of ``rgb``
    background: np.ndarray  # (H, W, 3) float32 Lab of the local wall colour
    delta: np.ndarray  # (H, W) float32 delta E to the local wall colour (0 where unusable)
    threshold: float  # delta E above which a pixel is foreground
    foreground: np.ndarray  # (H, W) bool, J_BW
    wall_rgb: np.ndarray  # (3,) float mean RGB of the wall
    noise_rgb: np.ndarray  # (3,) float robust per-channel noise sigma of the raw wall colour


def _to_lab(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(np.ascontiguousarray(rgb, dtype=np.float32) / 255.0, cv2.COLOR_RGB2Lab)


def _median(rgb: np.ndarray, k: int) -> np.ndarray:
    if k <= 1:
        return np.ascontiguousarray(rgb, dtype=np.uint8)
    return cv2.medianBlur(np.ascontiguousarray(rgb, dtype=np.uint8), k | 1)


def _close(mask: np.ndarray) -> np.ndarray:
    return cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)) > 0


def colour_image(ortho: Orthoimage, area: WallArea, settings: ColourRecognitionSettings) -> ColourImage:
    """Median-filtered J_C, its local wall colour, the deviation from it and J_BW."""
    opening = np.zeros(ortho.mask.shape, bool)
    if area.opening_mask is not None and area.opening_mask.shape == opening.shape:
        opening = area.opening_mask
    raw, usable = fill_gaps(ortho.colour, ortho.mask & ~opening, settings.gap_fill_sigma_px,
                            settings.gap_fill_min_weight)
    usable &= ~opening
    if raw is ortho.colour:  # (float colours without gaps: not a copy)
        raw = raw.copy()
    np.copyto(raw, 0, where=~usable[..., None])  # in place
    np.round(raw, out=raw)
    raw = np.clip(raw, 0, 255, out=raw).astype(np.uint8)
    vis = area.visible & usable if area.visible.shape == usable.shape else np.zeros_like(usable)
    if np.count_nonzero(vis) < 0.01 * max(1, np.count_nonzero(usable)):  # no usable wall area: the flat part of the wall
        d = np.asarray(ortho.depth, np.float32)
        vis = usable & (np.abs(np.nan_to_num(d, nan=1.0)) < settings.flat_wall_m)
    rgb = _median(raw, settings.median_px)
    noise_rgb = colour_noise(raw, vis & ortho.mask)
    lab = _to_lab(rgb)
    wall_rgb = np.asarray(area.wall_colour, float).reshape(3)
    if not np.all(np.isfinite(wall_rgb)) or not wall_rgb.any():
        wall_rgb = np.median(rgb[vis if vis.any() else usable], axis=0).astype(float) if usable.any() else np.zeros(3)
    wall_lab = _to_lab(wall_rgb.reshape(1, 1, 3)).reshape(3)
    win = max(3, int(round(settings.background_window_m / ortho.pixel_m)) | 1)
    w = vis.astype(np.float32)
    den = cv2.boxFilter(w, -1, (win, win), normalize=True, borderType=cv2.BORDER_CONSTANT)
    num = cv2.boxFilter(lab * w[..., None], -1, (win, win), normalize=True, borderType=cv2.BORDER_CONSTANT)
    ok = den > 0.05
    bg = np.divide(num, np.maximum(den, 1e-6)[..., None], out=num)  # in place, then the wall colour where too few
    np.copyto(bg, wall_lab[None, None, :], where=~ok[..., None])
    dl = lab - bg  # its norm, summed as .sum(axis=2) sums the squares
    delta = np.sqrt(dl[..., 0] * dl[..., 0] + dl[..., 1] * dl[..., 1] + dl[..., 2] * dl[..., 2]).astype(np.float32)
    del dl
    delta[~usable] = 0.0
    noise = float(median(_sample_at(delta, vis))) if vis.any() else 0.0
    thr = max(settings.threshold_offset, settings.noise_k * noise)
    fg = _close((delta > thr) & usable) & usable
    fg &= ~opening_frames(fg, area, ortho, settings)
    return ColourImage(rgb, lab, bg, delta, thr, fg, wall_rgb, noise_rgb)


def opening_frames(fg: np.ndarray, area: WallArea, ortho: Orthoimage,
                   settings: ColourRecognitionSettings) -> np.ndarray:
    """Foreground pixels of the frames (casings) that hug the openings of the wall.

    A door or window casing is a band of another colour around the opening (section 3.3
    finds the opening, not its frame). In J_BW it is one large region, and an object
    mounted next to it (an exit light just above a door) touches it and disappears into
    an oversized RoI. Along each side of an opening rectangle, lines parallel to the side
    are walked outwards: a line belongs to the frame while at least ``casing_fill`` of it
    is foreground (an object beside the opening covers only a small part of the side's
    length); the frame may start up to ``casing_gap_px`` lines off the rectangle (its edge
    is only known to a few pixels) and is at most ``casing_max_m`` wide.
    """
    out = np.zeros(fg.shape, bool)
    if not area.openings or settings.casing_max_m <= 0:
        return out
    h, w = fg.shape
    reach = max(1, int(round(settings.casing_max_m / ortho.pixel_m)))
    for op in area.openings:
        (ra, ca), (rb, cb) = ortho.uv_to_pixel(op.u_min, op.v_max), ortho.uv_to_pixel(op.u_max, op.v_min)
        # pixel edges of the rectangle (a pixel's centre is at integer + 0.5 of its edges)
        r0, c0 = max(0, int(round(ra + 0.5))), max(0, int(round(ca + 0.5)))
        r1, c1 = min(h, int(round(rb + 0.5))), min(w, int(round(cb + 0.5)))
        if r1 <= r0 or c1 <= c0:
            continue
        # width of the frame band on each side (0: none), from the rectangle outwards
        wt = _frame_width(fg[max(0, r0 - reach):r0, c0:c1][::-1], settings)
        wb = _frame_width(fg[r1:r1 + reach, c0:c1], settings)
        wl = _frame_width(fg[r0:r1, max(0, c0 - reach):c0].T[::-1], settings)
        wr = _frame_width(fg[r0:r1, c1:c1 + reach].T, settings)
        rt, cl = max(0, r0 - wt), max(0, c0 - wl)
        out[rt:r0, cl:c1 + wr] = wt > 0
        out[r1:r1 + wb, cl:c1 + wr] |= wb > 0
        out[rt:r1 + wb, cl:c0] |= wl > 0
        out[rt:r1 + wb, c1:c1 + wr] |= wr > 0
    return out & fg


def _frame_width(strip: np.ndarray, settings: ColourRecognitionSettings) -> int:
    """Lines of ``strip`` (row k = k-th line outwards from an opening) up to the frame's outer edge; 0: no frame."""
    if strip.size == 0:
        return 0
    full = strip.mean(axis=1) >= settings.casing_fill
    start = next((k for k in range(min(len(full), settings.casing_gap_px + 1)) if full[k]), None)
    if start is None:
        return 0
    end = start
    while end < len(full) and full[end]:
        end += 1
    return end


def _sample(values: np.ndarray, n: int = 100_000) -> np.ndarray:
    """At most about ``n`` of ``values`` (a regular stride: deterministic), for robust statistics."""
    step = max(1, len(values) // n)
    return values[::step]


def _sample_at(image: np.ndarray, where: np.ndarray, n: int = 100_000) -> np.ndarray:
    """``_sample(image[where], n)`` without gathering every selected pixel first."""
    idx = np.flatnonzero(where)
    return image.reshape(where.size, *image.shape[where.ndim:])[_sample(idx, n)]


def colour_noise(rgb: np.ndarray, where: np.ndarray) -> np.ndarray:
    """Robust per-channel sigma of pixel noise: MAD of the residual to the 3x3 mean, on ``where``."""
    if np.count_nonzero(where) < 50:
        return np.zeros(3)
    f = np.asarray(rgb, np.float32)
    inner = cv2.erode(where.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    if np.count_nonzero(inner) < 50:
        return np.zeros(3)
    vals = _sample_at(f, inner) - _sample_at(cv2.blur(f, (3, 3)), inner)  # the residual where it is sampled
    mad = median(np.abs(vals - median(vals, axis=0)), axis=0)  # medians.median: np.median's values, faster
    return (1.4826 * mad * np.sqrt(9.0 / 8.0)).astype(float)


def colour_rois(ortho: Orthoimage, area: WallArea, settings: ColourRecognitionSettings,
                image: ColourImage | None = None, *, largest_px: int | None = None) -> list[Box]:
    """RoIs of J_BW: bounding rectangles of compact foreground regions, clustered (section 4.3).

    ``image`` is ``colour_image(ortho, area, settings)`` when the caller already has it.
    With ``largest_px`` (the library's largest footprint side,
    :attr:`ColourPrototypes.largest_footprint_px`), a region longer than ``max_roi_factor``
    times that is no object (:func:`match_colour` skips it) and gathers no other region into
    its box (:func:`~sbsc_core.recognition.matching.cluster_boxes`): a sign beside a dark
    door frame keeps a RoI of its own.
    """
    img = image if image is not None else colour_image(ortho, area, settings)
    return _rois(img.foreground, settings, settings.max_roi_factor * largest_px if largest_px else None)


def _rois(fg: np.ndarray, settings: ColourRecognitionSettings, longest_px: float | None = None) -> list[Box]:
    boxes = boxes_from_mask(fg, settings.roi_min_px, settings.roi_min_area_px)
    return cluster_boxes(boxes, settings.roi_merge_gap_px, longest_px=longest_px)


# --------------------------------------------------------------------------- prototypes


@dataclass
class WallPrototype:
    """What the colour recognizer can see of one class on one wall colour."""

    class_id: str
    descriptor: np.ndarray  # (15,) normalised mean pattern
    samples: np.ndarray  # (n, 15) normalised patterns of the views
    size_px: tuple[float, float]  # (h, w) of the visible part's bounding box
    offset_px: tuple[float, float]  # visible bounding-box centre minus footprint centre (row, col)
    views: list[tuple[int, np.ndarray]]  # (rotation, Lab difference to the wall (h, w, 3) float32)
    footprint: tuple[int, int]  # (h, w) of the unrotated footprint


@dataclass
class ColourPrototypes:
    """Pattern prototypes of the library (paper: learnt from front views).

    ``base`` holds the paper's prototypes (each view's alpha mask as foreground);
    ``for_wall`` re-learns them for one wall colour and detection threshold.
    """

    templates: dict[str, ModelTemplate]
    settings: ColourRecognitionSettings
    base: dict[str, np.ndarray]  # class -> (15,) normalised
    _cache: dict[tuple, dict[str, WallPrototype]] = field(default_factory=dict, repr=False)

    @property
    def largest_footprint_px(self) -> int:
        return max((max(t.height_px, t.width_px) for t in self.templates.values()), default=0)

    def for_wall(self, wall_rgb: np.ndarray, threshold: float,
                 noise_rgb: np.ndarray | None = None) -> dict[str, WallPrototype]:
        """Prototypes as seen on a wall of colour ``wall_rgb`` with ``noise_rgb`` pixel noise."""
        q = max(1e-6, self.settings.prototype_colour_step)
        wall = np.round(np.asarray(wall_rgb, float).reshape(3) / q) * q
        noise = np.zeros(3) if noise_rgb is None else np.round(np.asarray(noise_rgb, float).reshape(3) * 2) / 2
        key = (tuple(wall), round(float(threshold) * 2) / 2, tuple(noise))
        threshold = key[1]
        if key not in self._cache:
            out = {}
            for cid in sorted(self.templates):
                p = wall_prototype(self.templates[cid], wall, threshold, self.settings, noise)
                if p is not None:
                    out[cid] = p
            self._cache[key] = out
        return self._cache[key]


def composite(view: np.ndarray, wall_rgb: np.ndarray, pad: int, blur_px: float) -> np.ndarray:
    """A view (RGBA) on the wall colour, padded by ``pad`` pixels of wall, blurred like a scan."""
    rgb = view[..., :3].astype(np.float32)
    a = view[..., 3:].astype(np.float32) / 255.0
    comp = rgb * a + np.asarray(wall_rgb, np.float32)[None, None, :] * (1.0 - a)
    comp = cv2.copyMakeBorder(comp, pad, pad, pad, pad, cv2.BORDER_CONSTANT,
                              value=[float(x) for x in wall_rgb])
    if blur_px > 0:
        comp = cv2.GaussianBlur(comp, (0, 0), blur_px)
    return np.clip(np.round(comp), 0, 255).astype(np.uint8)


@lru_cache(maxsize=512)
def _unit_noise(view: int, blur: int, sample: int, shape: tuple[int, ...]) -> np.ndarray:
    """The standard normal noise of one training sample (seeded by its numbers: the same on
    every wall, so a worker draws it once; read-only)."""
    out = np.random.default_rng([view, blur, sample]).normal(0.0, 1.0, shape)
    out.flags.writeable = False
    return out


def wall_prototype(t: ModelTemplate, wall_rgb: np.ndarray, threshold: float,
                   settings: ColourRecognitionSettings,
                   noise_rgb: np.ndarray | None = None) -> WallPrototype | None:
    """Learn a class's prototype as it appears on a wall of colour ``wall_rgb`` (None if invisible).

    Every view is composited on the wall, blurred by each of ``train_blurs_px`` and, when the
    wall is noisy, given ``train_noise_samples`` copies of its measured noise; each sample
    goes through the scene's own foreground test and gives one training pattern.
    """
    if not t.colour_views:
        return None
    blurs = tuple(settings.train_blurs_px) or (0.0,)
    pad = max(3, settings.median_px + int(np.ceil(3 * max(blurs))))
    wall_lab = _to_lab(np.asarray(wall_rgb, np.float32).reshape(1, 1, 3)).reshape(3)
    noise = np.zeros(3) if noise_rgb is None else np.asarray(noise_rgb, float).reshape(3)
    n_noisy = max(1, settings.train_noise_samples) if noise.max() > 0 else 1
    cy, cx = pad + (t.height_px - 1) / 2.0, pad + (t.width_px - 1) / 2.0
    samples, sizes, offsets, views = [], [], [], []
    jitter = tuple(settings.train_threshold_factors) or (1.0,)
    for vi, view in enumerate(t.colour_views):
        for bi, blur in enumerate(blurs):
            clean = composite(view, wall_rgb, pad, blur)
            for k in range(n_noisy):
                img = clean
                if noise.max() > 0:
                    img = np.clip(clean + _unit_noise(vi, bi, k, clean.shape) * noise, 0, 255)
                comp = _median(np.round(img).astype(np.uint8), settings.median_px)
                lab = _to_lab(comp)
                dl = lab - wall_lab[None, None, :]  # its norm, as np.linalg.norm sums the squares
                delta = np.sqrt(dl[..., 0] * dl[..., 0] + dl[..., 1] * dl[..., 1] + dl[..., 2] * dl[..., 2])
                described: dict[bytes, np.ndarray] = {}  # jittered thresholds often give the same foreground
                hsv = None  # converted once for all the foregrounds of this image (lab is its Lab image)
                for factor in jitter:
                    if factor != 1.0 and k > 0:
                        continue
                    fg = _close(delta > threshold * factor)
                    if np.count_nonzero(fg) < settings.roi_min_area_px:
                        continue
                    rr, cc = np.flatnonzero(fg.any(axis=1)), np.flatnonzero(fg.any(axis=0))  # the bounding box
                    r0, r1, c0, c1 = rr[0], rr[-1] + 1, cc[0], cc[-1] + 1
                    if max(r1 - r0, c1 - c0) < settings.roi_min_px:
                        continue
                    key = np.packbits(fg).tobytes()
                    if key not in described:
                        hsv = rgb_to_hsv(comp) if hsv is None else hsv
                        described[key] = normalise_descriptors(descriptors_of(hsv, lab, fg, settings), settings)
                    samples.append(described[key])
                    if factor == 1.0:
                        sizes.append((r1 - r0, c1 - c0))
                        offsets.append(((r0 + r1 - 1) / 2.0 - cy, (c0 + c1 - 1) / 2.0 - cx))
                    if not views and k == 0 and factor == 1.0:
                        diff = np.where(fg[..., None], lab - wall_lab[None, None, :], 0.0).astype(np.float32)
                        views.append(np.ascontiguousarray(diff[pad:pad + t.height_px, pad:pad + t.width_px]))
    if not samples or not sizes:
        return None
    arr = np.asarray(samples)
    placed = rotated_variants(views[0], settings.rotations) if settings.refine_position and views else []
    return WallPrototype(
        class_id=t.class_id, descriptor=arr.mean(axis=0), samples=arr,
        size_px=tuple(np.median(np.asarray(sizes, float), axis=0)),
        offset_px=tuple(np.mean(np.asarray(offsets, float), axis=0)),
        views=placed, footprint=(t.height_px, t.width_px),
    )


def learn_prototypes(templates: dict[str, ModelTemplate], settings: ColourRecognitionSettings) -> ColourPrototypes:
    """Pattern prototypes of every class with colour views (paper: learnt from front views)."""
    base = {}
    for cid in sorted(templates):
        t = templates[cid]
        pats = []
        for view in t.colour_views:
            fg = view[..., 3] > 127
            if fg.sum() >= 1:
                pats.append(normalise_descriptors(global_descriptors(view[..., :3], fg, settings), settings))
        if pats:
            base[cid] = np.mean(pats, axis=0)
    return ColourPrototypes(templates=templates, settings=settings, base=base)


# --------------------------------------------------------------------------- matching


def size_mismatch(roi: Box, size_px: tuple[float, float], rotations: bool) -> float:
    """How much the RoI's sides differ from the prototype's: the larger ratio of the two
    sides, minus 1 (0.3 = one side 30 % longer or shorter), in the better orientation."""
    h, w = max(size_px[0], 1.0), max(size_px[1], 1.0)
    rh, rw = max(roi.height, 1), max(roi.width, 1)

    def ratio(a: float, b: float) -> float:
        return max(a / b, b / a) - 1.0

    straight = max(ratio(rh, h), ratio(rw, w))
    if not rotations:
        return straight
    return min(straight, max(ratio(rh, w), ratio(rw, h)))


def rotate_offset(offset: tuple[float, float], deg: float) -> tuple[float, float]:
    """A (row, col) offset from a footprint's centre after turning it by ``deg`` (counter-clockwise)."""
    dr, dc = offset
    a = np.deg2rad(float(deg))
    if abs(float(deg) / 90.0 - round(float(deg) / 90.0)) < 1e-9:  # exact for quarter turns
        for _ in range(int(round(float(deg) / 90.0)) % 4):
            dr, dc = -dc, dr
        return dr, dc
    return dr * np.cos(a) - dc * np.sin(a), dr * np.sin(a) + dc * np.cos(a)


def turned_extent(mask: np.ndarray, settings: ColourRecognitionSettings) -> tuple[float, tuple[int, int]] | None:
    """(turn, (h, w)) of a RoI's foreground turned by at least ``min_turn_deg``: its turn
    (:func:`~sbsc_core.recognition.matching.estimate_turn`) and the size of its bounding box turned back."""
    if not settings.free_rotation:
        return None
    turn = estimate_turn(mask)
    if turn is None or abs(turn) < settings.min_turn_deg:
        return None
    ys, xs = np.nonzero(mask)
    a = np.deg2rad(turn)
    best = None
    for sgn in (1.0, -1.0):  # the turn back is the one that gives the smaller box
        u = xs * np.cos(a) + sgn * ys * np.sin(a)
        v = -sgn * xs * np.sin(a) + ys * np.cos(a)
        size = (int(round(np.ptp(v))) + 1, int(round(np.ptp(u))) + 1)
        if best is None or size[0] * size[1] < best[0] * best[1]:
            best = size
    return turn, best


def _best_placement(roi: Box, proto: WallPrototype, settings: ColourRecognitionSettings, diff: np.ndarray,
                    variants: list[tuple[float, np.ndarray]]) -> tuple[float, tuple[float, float], float,
                                                                       tuple[int, int]] | None:
    """(rank, centre, rotation, view shape) of the best-correlating view of ``variants`` in a RoI."""
    rc = roi.centre
    best = None
    for deg, view in variants:
        quarter = int(round(float(deg) / 90.0)) % 2
        sh, sw = proto.size_px[::-1] if quarter else proto.size_px
        off = rotate_offset(proto.offset_px, deg)
        gr, gc = rc[0] - off[0], rc[1] - off[1]
        slack_r = settings.search_margin_px + abs(roi.height - sh) / 2.0
        slack_c = settings.search_margin_px + abs(roi.width - sw) / 2.0
        area = Box(int(np.floor(gr - slack_r)), int(np.floor(gc - slack_c)),
                   int(np.ceil(gr + slack_r)) + 1, int(np.ceil(gc + slack_c)) + 1)
        peaks = match_in_rois(diff, view, [area], threshold=-1.0, pad_px=settings.search_margin_px // 2,
                              margin_px=0, max_peaks=1, min_energy=1e-6 * view.size)
        if not peaks:
            continue
        rank = peaks[0].score + (settings.rotation_margin if deg == 0 else 0.0)
        if best is None or rank > best[0]:
            best = (rank, (peaks[0].row, peaks[0].col), deg, view.shape[:2])
    return best


def _place(img: ColourImage, roi: Box, proto: WallPrototype, settings: ColourRecognitionSettings,
           diff: np.ndarray, *, turn: float | None = None) -> tuple[tuple[float, float], float, Box]:
    """Footprint centre, rotation and box of a class in a RoI (cross-correlation, else centroid).

    The footprint centre is searched around the RoI centre minus the prototype's offset of
    its visible part, within ``search_margin_px`` plus half the size difference. A RoI
    turned by ``turn`` is also tried with the view turned by it plus multiples of 90
    degrees, then refined by ``turn_refine_deg`` around the best of those.
    """
    fh, fw = proto.footprint
    rc = roi.centre
    guess = (rc[0] - proto.offset_px[0], rc[1] - proto.offset_px[1])
    if settings.refine_position and proto.views:
        best = _best_placement(roi, proto, settings, diff, proto.views)
        if turn is not None:
            base = proto.views[0][1]
            coarse = _best_placement(roi, proto, settings, diff,
                                     [(a, rotate_template(base, a)) for a in turn_angles(turn)])
            if coarse is not None:
                fine = _best_placement(roi, proto, settings, diff, [
                    (a, rotate_template(base, a)) for a in
                    (round((coarse[2] + d) % 360.0, 3) for d in settings.turn_refine_deg)])
                for b in (coarse, fine):
                    if b is not None and (best is None or b[0] > best[0]):
                        best = b
        if best is not None:
            _, centre, deg, (h, w) = best
            return centre, deg, box_at(centre, h, w)
    return guess, 0, box_at(guess, fh, fw)


def depth_agrees(depth: np.ndarray, t: ModelTemplate, box: Box, rotation_deg: float,
                 settings: ColourRecognitionSettings) -> bool:
    """False when a class that stands out of the wall is placed where the scan shows a flat wall.

    Only for models with at least ``depth_check_min_relief_m`` of relief: the footprint must
    have depth data in ``depth_check_coverage`` of its pixels (a protruding object is always
    scanned where its colour was; a footprint over a hole or an opening is not an object)
    and the least-squares amplitude of the scene's relief against the model's there must
    reach ``depth_check_gain`` (0 disables the check).
    """
    if settings.depth_check_gain <= 0 or t.depth is None or t.relief_m() < settings.depth_check_min_relief_m:
        return True
    model = rotate_template(t.depth_filled(), rotation_deg)
    if model.shape != (box.height, box.width):
        return True
    patch = crop_padded(depth, box.r0, box.r1, box.c0, box.c1)
    ok = np.isfinite(patch)
    if ok.mean() < settings.depth_check_coverage:
        return False  # a protruding object would have been scanned: this is mostly a hole
    m = model[ok] - model[ok].mean()
    den = float((m * m).sum())
    if den <= 0:
        return True
    gain = float((m * (patch[ok] - patch[ok].mean())).sum() / den)
    return gain >= settings.depth_check_gain


def prototype_distance(pattern: np.ndarray, proto: WallPrototype, nearest_sample: bool = True) -> float:
    """rho_C of a normalised pattern to a class: to its mean pattern or, if nearer, to a sample."""
    d = float(descriptor_distance(pattern, proto.descriptor))
    if nearest_sample and len(proto.samples):
        d = min(d, float(np.min(descriptor_distance(pattern[None, :], proto.samples))))
    return d


def match_colour(
    ortho: Orthoimage,
    area: WallArea,
    rois: list[Box],
    prototypes: ColourPrototypes,
    settings: ColourRecognitionSettings,
    *, image: ColourImage | None = None,
) -> list[Candidate]:
    """Candidates {C}: RoIs whose pattern lies within mu_C of a class prototype.

    ``score`` is rho_C (lower is better); ``box`` is the class footprint placed on the RoI.
    ``image`` is ``colour_image(ortho, area, settings)`` when the caller already has it.
    """
    if not rois or not prototypes.templates:
        return []
    img = image if image is not None else colour_image(ortho, area, settings)
    protos = prototypes.for_wall(img.wall_rgb, img.threshold, img.noise_rgb)
    if not protos:
        return []
    diff = np.ascontiguousarray(img.lab - img.background, dtype=np.float32)
    # the wall (and what cannot be seen) is the zero background (in place, not gathered: the most of the image)
    np.multiply(diff, 0.0, out=diff, where=~img.foreground[..., None])
    relief = np.asarray(ortho.depth, np.float32)
    max_side = settings.max_roi_factor * prototypes.largest_footprint_px
    any_rot = any(r % 180 for r in settings.rotations)
    out: list[Candidate] = []
    for roi in rois:
        if max(roi.height, roi.width) > max_side:
            continue
        fg = img.foreground[roi.r0:roi.r1, roi.c0:roi.c1]
        if fg.sum() < settings.roi_min_area_px:
            continue
        crop = img.rgb[roi.r0:roi.r1, roi.c0:roi.c1]
        pattern = normalise_descriptors(global_descriptors(crop, fg, settings), settings)
        turned = turned_extent(fg, settings)
        extent = roi if turned is None else Box(0, 0, *turned[1])
        scored = []
        for cid, p in protos.items():
            if size_mismatch(extent, p.size_px, any_rot) > settings.size_tolerance:
                continue
            scored.append((prototype_distance(pattern, p, settings.nearest_sample), cid))
        scored.sort()
        for rho, cid in scored:
            if rho > settings.mu_c:
                break
            centre, deg, box = _place(img, roi, protos[cid], settings, diff, turn=None if turned is None else turned[0])
            if not depth_agrees(relief, prototypes.templates[cid], box, deg, settings):
                continue  # a protruding class where the wall is flat: not this class
            out.append(Candidate(cid, ortho.wall_id, "colour", box, centre, rho, roi, deg))
            if settings.nearest_only:
                break
    return out
