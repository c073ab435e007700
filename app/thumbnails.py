"""Thumbnails for review: colour and depth crops of a wall's orthoimage around one detection.

The crop is centred on the detection's footprint (u, v) and shows some wall around it;
the footprint is outlined. Orthoimage conventions are those of ``sbsc_core.types``: row 0
is the top of the wall, pixel (r, c) has its centre at u = (c + .5) px, v = H - (r + .5) px.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from pathlib import Path

import cv2
import numpy as np

NO_DATA_BGR = (60, 60, 60)
OUTLINE_BGR = (0, 215, 255)  # amber
MIN_DEPTH_SPAN_M = 0.02  # the depth colour map spans at least this: scanner noise stays dark


class ImageCache:
    """A small thread-safe LRU of decoded orthoimages keyed by path and modification time."""

    def __init__(self, maxsize: int = 12) -> None:
        self.maxsize = maxsize
        self._items: OrderedDict[tuple[str, float], np.ndarray] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, path: Path) -> np.ndarray:
        key = (str(path), path.stat().st_mtime)
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
        img = np.load(path) if path.suffix == ".npy" else cv2.imread(str(path), cv2.IMREAD_COLOR)
        if img is None:
            raise FileNotFoundError(path)
        with self._lock:
            self._items[key] = img
            while len(self._items) > self.maxsize:
                self._items.popitem(last=False)
        return img


def crop_window(shape: tuple[int, int], wall_height_m: float, pixel_m: float, u: float, v: float,
                side_m: float) -> tuple[int, int, int, int]:
    """(r0, c0, r1, c1) of a square window of ``side_m`` centred on (u, v); may exceed the image."""
    c = u / pixel_m - 0.5
    r = (wall_height_m - v) / pixel_m - 0.5
    half = max(1, int(round(side_m / pixel_m / 2)))
    r0, c0 = int(round(r)) - half, int(round(c)) - half
    return r0, c0, r0 + 2 * half, c0 + 2 * half


def _take(img: np.ndarray, win: tuple[int, int, int, int], fill) -> np.ndarray:  # noqa: ANN001
    """The window of ``img``, padded with ``fill`` where it leaves the image."""
    r0, c0, r1, c1 = win
    h, w = img.shape[:2]
    out = np.empty((r1 - r0, c1 - c0) + img.shape[2:], img.dtype)
    out[...] = fill
    rr0, cc0, rr1, cc1 = max(r0, 0), max(c0, 0), min(r1, h), min(c1, w)
    if rr1 > rr0 and cc1 > cc0:
        out[rr0 - r0:rr1 - r0, cc0 - c0:cc1 - c0] = img[rr0:rr1, cc0:cc1]
    return out


def colourise_depth(depth: np.ndarray) -> np.ndarray:
    """Relief as a colour map (BGR): wall plane dark, standing-out parts bright; no data grey."""
    ok = np.isfinite(depth)
    out = np.empty(depth.shape + (3,), np.uint8)
    out[...] = NO_DATA_BGR
    if ok.any():
        vals = depth[ok]
        lo = float(np.percentile(vals, 2))
        hi = max(float(np.percentile(vals, 98)), lo + MIN_DEPTH_SPAN_M)
        grey = np.clip((depth - lo) / (hi - lo) * 255, 0, 255)
        grey = np.nan_to_num(grey).astype(np.uint8)
        cmap = cv2.applyColorMap(grey, cv2.COLORMAP_VIRIDIS)
        out[ok] = cmap[ok]
    return out


def thumbnail(cache: ImageCache, image_path: Path, kind: str, *, wall_height_m: float,
              pixel_m: float, u: float, v: float, width_m: float, height_m: float,
              size_px: int, context: float, min_side_m: float, depth_path: Path | None = None) -> bytes:
    """PNG bytes of the ``kind`` ("colour" or "depth") crop around a footprint.

    For a colour crop, ``depth_path`` (the wall's ``_depth.npy``) marks pixels without
    scan points, which are shown grey rather than black.
    """
    img = cache.get(image_path)
    side = max(context * max(width_m, height_m), min_side_m)
    win = crop_window(img.shape[:2], wall_height_m, pixel_m, u, v, side)
    if kind == "depth":
        crop = colourise_depth(_take(img.astype(np.float32), win, np.nan))
    else:
        crop = _take(img, win, NO_DATA_BGR)
        if depth_path is not None and depth_path.is_file():
            depth = cache.get(depth_path)
            if depth.shape == img.shape[:2]:
                crop[~np.isfinite(_take(depth.astype(np.float32), win, np.nan))] = NO_DATA_BGR
    scale = size_px / crop.shape[0]
    crop = cv2.resize(crop, (size_px, size_px),
                      interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_NEAREST)
    # outline the footprint
    cx = (u / pixel_m - 0.5 - win[1]) * scale
    cy = ((wall_height_m - v) / pixel_m - 0.5 - win[0]) * scale
    hw, hh = width_m / pixel_m / 2 * scale, height_m / pixel_m / 2 * scale
    cv2.rectangle(crop, (int(round(cx - hw)), int(round(cy - hh))),
                  (int(round(cx + hw)), int(round(cy + hh))), OUTLINE_BGR, 2)
    ok, buf = cv2.imencode(".png", crop)
    if not ok:
        raise RuntimeError("cannot encode thumbnail")
    return buf.tobytes()
