"""The orthoimages of ``sbsc detect`` as the scene uses them: wall textures and object crops.

Orthoimages are stored with row 0 at the top of the wall and square pixels of ``pixel_m``:
pixel (r, c) has its centre at u = (c + .5) * pixel_m, v = height - (r + .5) * pixel_m
(``sbsc_core.types.Orthoimage``).
"""

from __future__ import annotations

import threading
from pathlib import Path

import cv2
import numpy as np

KINDS: tuple[str, ...] = ("colour", "depth")


def read_rgb(path: Path) -> np.ndarray | None:
    """An image file as (H, W, 3) uint8 RGB, or ``None`` when it is missing or unreadable."""
    if not Path(path).is_file():
        return None
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        return None
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def texture(img: np.ndarray, pixel_m: float, min_pixel_m: float, max_px: int) -> np.ndarray:
    """Shrink an orthoimage for the browser: pixels of at least ``min_pixel_m``, sides <= ``max_px``."""
    h, w = img.shape[:2]
    f = min(1.0, pixel_m / min_pixel_m, max_px / max(h, w))
    if f >= 1.0:
        return img
    size = (max(1, round(w * f)), max(1, round(h * f)))
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def thumbnail(img: np.ndarray, px: int) -> np.ndarray:
    """An image scaled so that its larger side is ``px`` pixels."""
    k = px / max(img.shape[:2])
    size = (max(1, round(img.shape[1] * k)), max(1, round(img.shape[0] * k)))
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA if k < 1 else cv2.INTER_LINEAR)


class WallImages:
    """Lazily read, thread-safe cache of the orthoimages in one ``orthoimages/`` directory."""

    def __init__(self, ortho_dir: Path | None, pixel_m: float) -> None:
        self.dir = None if ortho_dir is None else Path(ortho_dir)
        self.pixel_m = float(pixel_m)
        self._cache: dict[tuple[str, str], np.ndarray | None] = {}
        self._lock = threading.Lock()

    def image(self, wall: str, kind: str) -> np.ndarray | None:
        """The full-resolution orthoimage of a wall (RGB), ``None`` if there is none."""
        key = (wall, kind)
        with self._lock:
            if key not in self._cache:
                self._cache[key] = None if self.dir is None else read_rgb(self.dir / f"{wall}_{kind}.png")
            return self._cache[key]

    def crop(self, wall: str, kind: str, height_m: float, u: float, v: float, width_m: float,
             obj_height_m: float, context: float, min_side_m: float, out_px: int) -> np.ndarray | None:
        """A square view of the object (footprint outlined in red), ``out_px`` pixels wide.

        The side is ``context`` times the object's larger side, at least ``min_side_m``.
        Parts outside the orthoimage are black.
        """
        img = self.image(wall, kind)
        if img is None:
            return None
        px = self.pixel_m
        side = max(min_side_m, context * max(width_m, obj_height_m))
        half = side / 2.0 / px
        cr = (height_m - v) / px - 0.5  # continuous row / col of the object's centre
        cc = u / px - 0.5
        r0, c0 = int(np.floor(cr - half)), int(np.floor(cc - half))
        n = max(1, int(np.ceil(2 * half)))
        out = np.zeros((n, n, 3), np.uint8)
        rs, cs = max(r0, 0), max(c0, 0)
        re, ce = min(r0 + n, img.shape[0]), min(c0 + n, img.shape[1])
        if re > rs and ce > cs:
            out[rs - r0:re - r0, cs - c0:ce - c0] = img[rs:re, cs:ce]
        scale = out_px / n
        out = cv2.resize(out, (out_px, out_px),
                         interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_NEAREST)
        fw, fh = width_m / px * scale, obj_height_m / px * scale
        cx, cy = (cc - c0 + 0.5) * scale, (cr - r0 + 0.5) * scale
        p0 = (int(round(cx - fw / 2)), int(round(cy - fh / 2)))
        p1 = (int(round(cx + fw / 2)), int(round(cy + fh / 2)))
        cv2.rectangle(out, p0, p1, (255, 0, 0), 1)  # RGB red
        return out
