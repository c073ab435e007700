"""Place an object a reviewer added where its depth model matches the wall's relief nearby.

A reviewer clicks roughly on the object in a wall's orthoimage; the object's depth model
(contract 2, ``depth.npy``, resampled to the orthoimage's pixels as recognition does it:
:func:`sbsc_core.recognition.templates.make_template`) is correlated with the wall's depth orthoimage in
a small window around the click with the recognizer's masked normalised cross-correlation
(:func:`sbsc_core.recognition.matching.masked_ncc`, unseen pixels neither add nor remove
evidence). The click moves to the best match when that match is good enough; otherwise the
object stays where it was clicked (a flat object, or no relief there).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import SbscError
from ...io.models import load_object_model
from ..matching import masked_ncc
from ..templates import make_template

SEARCH_RADIUS_M = 0.12  # how far from the click the object's centre may move
MIN_NCC = 0.5  # a weaker match leaves the object where it was clicked
MIN_RELIEF_M = 0.002  # a depth model flatter than this cannot be matched


@dataclass(frozen=True)
class Snap:
    """Where the object goes: ``u``, ``v`` (metres on the wall), the match ``rho`` (None: not moved)."""

    u: float
    v: float
    rho: float | None = None

    @property
    def snapped(self) -> bool:
        return self.rho is not None


def depth_template(class_dir: Path, pixel_m: float) -> np.ndarray | None:
    """The class's depth model at ``pixel_m`` (NaN = wall plane), or None without one."""
    try:
        tpl = make_template(load_object_model(class_dir), pixel_m)
    except (SbscError, OSError, ValueError):
        return None
    if tpl.depth is None or tpl.relief_m() < MIN_RELIEF_M:
        return None
    return tpl.depth_filled()


def snap_to_relief(depth: np.ndarray, pixel_m: float, wall_height_m: float, template: np.ndarray,
                   *, u: float, v: float, radius_m: float = SEARCH_RADIUS_M,
                   min_ncc: float = MIN_NCC) -> Snap:
    """The best place for ``template`` within ``radius_m`` of (u, v) on a depth orthoimage.

    ``depth`` has row 0 at the top of the wall (NaN: no data), ``pixel_m`` pixels.
    Returns the click itself when no window scores ``min_ncc`` or more.
    """
    th, tw = template.shape
    rows, cols = depth.shape
    r = (wall_height_m - v) / pixel_m - 0.5  # continuous pixel centre of the click
    c = u / pixel_m - 0.5
    rad = int(np.ceil(radius_m / pixel_m))
    r0, c0 = int(round(r - th / 2.0 + 0.5)) - rad, int(round(c - tw / 2.0 + 0.5)) - rad
    r1, c1 = r0 + th + 2 * rad, c0 + tw + 2 * rad
    rr0, cc0, rr1, cc1 = max(r0, 0), max(c0, 0), min(r1, rows), min(c1, cols)
    if rr1 - rr0 < th or cc1 - cc0 < tw:
        return Snap(u, v)
    region = depth[rr0:rr1, cc0:cc1].astype(np.float32)
    known = np.isfinite(region)
    if known.sum() < th * tw // 2:
        return Snap(u, v)
    score = masked_ncc(np.nan_to_num(region, nan=0.0), known, template,
                       min_pixels=max(16, th * tw * 6 // 10))
    # windows whose centre is within the radius of the click
    ys, xs = np.mgrid[0:score.shape[0], 0:score.shape[1]]
    cy = rr0 + ys + (th - 1) / 2.0
    cx = cc0 + xs + (tw - 1) / 2.0
    near = (cy - r) ** 2 + (cx - c) ** 2 <= (rad + 0.5) ** 2
    score = np.where(near, score, -1.0)
    k = int(np.argmax(score))
    best = float(score.flat[k])
    if best < min_ncc:
        return Snap(u, v)
    y, x = np.unravel_index(k, score.shape)
    su = (float(cx[y, x]) + 0.5) * pixel_m
    sv = wall_height_m - (float(cy[y, x]) + 0.5) * pixel_m
    return Snap(round(su, 5), round(sv, 5), round(best, 4))
