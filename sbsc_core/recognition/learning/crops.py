"""Crops of objects out of a surface's orthoimages, and their medians (learnt views and depth models).

An object's crop is its footprint (``width_m`` x ``height_m`` centred on its ``u``, ``v``)
cut out of the colour orthoimage (row 0 at the top of the surface, ``pixel_m`` pixels) and
out of the depth orthoimage minus the surface level around it (the median of a ring around
the footprint): its relief. The per-pixel median of several crops averages the scanner noise
of single crops out; it becomes a learnt front view (``colour_<k>.png``) and a learnt depth
model (``depth_<k>.npy``) of a library class (contract 2, docs/model-library.md).
"""

from __future__ import annotations

import warnings

import numpy as np

MIN_SEEN = 0.6  # a crop with less of its footprint scanned is left out
MAX_TURN_DEG = 5.0  # an object turned by more (from upright or upside down) gives no crop
MIN_DEPTH_SAMPLES = 1  # crops a learnt depth model needs at least
OBJECT_DELTA_E = 12.0  # a learnt view's pixel this far (CIE76) from the surface's colour is the object
OBJECT_RELIEF_M = 0.003  # ... and so is one standing out this much
OBJECT_MIN_SHARE = 0.25  # an object box smaller than this share of the footprint is not trusted

Window = tuple[int, int, int, int]


def footprint(shape: tuple[int, ...], surface_height_m: float, pixel_m: float, *, u: float, v: float,
              width_m: float, height_m: float) -> Window | None:
    """(r0, c0, r1, c1) of an object's footprint in an orthoimage; None when it leaves the image."""
    c0 = int(round((u - width_m / 2) / pixel_m))
    c1 = int(round((u + width_m / 2) / pixel_m))
    r0 = int(round((surface_height_m - v - height_m / 2) / pixel_m))
    r1 = int(round((surface_height_m - v + height_m / 2) / pixel_m))
    if r0 < 0 or c0 < 0 or r1 > shape[0] or c1 > shape[1] or r1 - r0 < 2 or c1 - c0 < 2:
        return None
    return r0, c0, r1, c1


def seen_share(depth: np.ndarray, win: Window) -> float:
    """The share of the window's pixels that the scan saw (finite depth)."""
    r0, c0, r1, c1 = win
    return float(np.isfinite(depth[r0:r1, c0:c1]).mean())


def surface_level(depth: np.ndarray, win: Window, ring_px: int) -> float:
    """The median depth of a ring of ``ring_px`` pixels around ``win`` (0 when unseen)."""
    r0, c0, r1, c1 = win
    R0, C0 = max(0, r0 - ring_px), max(0, c0 - ring_px)
    R1, C1 = min(depth.shape[0], r1 + ring_px), min(depth.shape[1], c1 + ring_px)
    ring = depth[R0:R1, C0:C1].astype(np.float32).copy()
    ring[r0 - R0:r1 - R0, c0 - C0:c1 - C0] = np.nan
    return float(np.nanmedian(ring)) if np.isfinite(ring).any() else 0.0


def surface_colour(colour: np.ndarray, depth: np.ndarray, win: Window, ring_px: int) -> np.ndarray | None:
    """The median colour of the scanned pixels of a ring of ``ring_px`` around ``win`` (None unseen)."""
    r0, c0, r1, c1 = win
    R0, C0 = max(0, r0 - ring_px), max(0, c0 - ring_px)
    R1, C1 = min(depth.shape[0], r1 + ring_px), min(depth.shape[1], c1 + ring_px)
    ring = np.isfinite(depth[R0:R1, C0:C1])
    ring[r0 - R0:r1 - R0, c0 - C0:c1 - C0] = False
    if not ring.any():
        return None
    return np.median(colour[R0:R1, C0:C1][ring], axis=0)


def object_alpha(view_bgr: np.ndarray, surface_bgr: np.ndarray | None, relief_m: np.ndarray | None, *,
                 min_delta_e: float = OBJECT_DELTA_E, min_relief_m: float = OBJECT_RELIEF_M,
                 min_share: float = OBJECT_MIN_SHARE) -> np.ndarray:
    """The alpha of a learnt front view: 255 over the bounding box of what is the object (a colour
    ``min_delta_e`` from the surface's, or relief of ``min_relief_m``), 0 around it; all 255 when
    that box covers less than ``min_share`` of the footprint (an object of the surface's colour
    without relief: nothing tells it from the surface, so the whole footprint is its view)."""
    import cv2

    h, w = view_bgr.shape[:2]
    fg = np.zeros((h, w), bool)
    if surface_bgr is not None:
        lab = cv2.cvtColor(view_bgr.astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab)
        wall = cv2.cvtColor(np.asarray(surface_bgr, np.float32).reshape(1, 1, 3) / 255.0, cv2.COLOR_BGR2Lab)
        fg |= np.linalg.norm(lab - wall, axis=2) > min_delta_e
    if relief_m is not None and relief_m.shape == (h, w):
        fg |= np.nan_to_num(np.abs(relief_m), nan=0.0) >= min_relief_m
    fg = cv2.morphologyEx(fg.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)) > 0  # noise specks
    alpha = np.full((h, w), 255, np.uint8)
    if not fg.any():
        return alpha
    rr, cc = np.flatnonzero(fg.any(axis=1)), np.flatnonzero(fg.any(axis=0))
    r0, r1, c0, c1 = rr[0], rr[-1] + 1, cc[0], cc[-1] + 1
    if (r1 - r0) * (c1 - c0) < min_share * h * w:
        return alpha
    alpha[:] = 0
    alpha[r0:r1, c0:c1] = 255
    return alpha


def relief(depth: np.ndarray, win: Window, ring_px: int) -> np.ndarray | None:
    """The depth crop over ``win`` minus the surface level around it; None when less than
    ``MIN_SEEN`` of it was scanned."""
    r0, c0, r1, c1 = win
    if seen_share(depth, win) < MIN_SEEN:
        return None
    return depth[r0:r1, c0:c1].astype(np.float32) - surface_level(depth, win, ring_px)


def upright(rotation_deg: float) -> bool:
    """Whether an object turned by ``rotation_deg`` still covers its upright footprint: within
    ``MAX_TURN_DEG`` of upright or of upside down (the crop is the object as it hangs)."""
    off = abs((rotation_deg + 90.0) % 180.0 - 90.0)
    return off <= MAX_TURN_DEG


def _common(crops: list[np.ndarray]) -> list[np.ndarray]:
    """The crops of the most common size (a wall of another pixel size gives another)."""
    shapes = [c.shape for c in crops]
    shape = max(set(shapes), key=shapes.count)
    return [c for c in crops if c.shape == shape]


def learnt_view(crops: list[np.ndarray]) -> np.ndarray | None:
    """The per-pixel median of the colour crops of one class (uint8); None without crops.

    Float crops may hold NaN where the scan saw nothing: the median is taken over the crops
    that saw each pixel, and a pixel none saw takes the median colour of the view."""
    if not crops:
        return None
    stack = np.stack(_common(crops))
    if stack.dtype.kind != "f":
        return np.median(stack, axis=0).round().astype(np.uint8)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pixels stay NaN
        view = np.nanmedian(stack, axis=0)
        fill = np.nanmedian(view.reshape(-1, view.shape[-1]), axis=0)
    view = np.where(np.isfinite(view), view, np.nan_to_num(fill, nan=0.0))
    return np.clip(view.round(), 0, 255).astype(np.uint8)


def learnt_depth(crops: list[np.ndarray]) -> np.ndarray | None:
    """The per-pixel median of the relief crops of one class (NaN where none saw it); None
    with fewer than ``MIN_DEPTH_SAMPLES`` crops. Crops of another size than the most common
    one (a wall of another pixel size) are left out."""
    if len(crops) < MIN_DEPTH_SAMPLES:
        return None
    stack = np.stack(_common(crops))
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN pixels stay NaN
        model = np.nanmedian(stack, axis=0).astype(np.float32)
    return model if np.isfinite(model).any() else None
