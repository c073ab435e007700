"""Synthetic walls, objects and libraries for the recognition tests (no simulator needed).

A wall is a uniform colour with noise and a few no-data holes; objects are pasted from
synthetic templates (colour views + depth relief) at known pixel positions, optionally
rotated by multiples of 90 degrees. Everything is deterministic for a given seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from sbsc_core.recognition.templates import ModelTemplate
from sbsc_core.types import ModelLibrary, ObjectModel, Orthoimage, WallArea, WallFrame

PIXEL_M = 0.005


def _rgba(rgb: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    a = np.full(rgb.shape[:2], 255, np.uint8) if alpha is None else alpha.astype(np.uint8)
    return np.dstack([rgb.astype(np.uint8), a])


def socket_like(w_px: int = 16, h_px: int = 16, body=(245, 245, 240), hole=(60, 60, 60),
                relief_m: float = 0.012) -> tuple[np.ndarray, np.ndarray]:
    """A square plate with a dark round recess; returns (RGBA, depth)."""
    rgb = np.empty((h_px, w_px, 3), np.uint8)
    rgb[:] = body
    depth = np.full((h_px, w_px), relief_m, np.float32)
    yy, xx = np.mgrid[0:h_px, 0:w_px]
    disc = (yy - (h_px - 1) / 2) ** 2 + (xx - (w_px - 1) / 2) ** 2 <= (0.3 * min(w_px, h_px)) ** 2
    rgb[disc] = hole
    depth[disc] = relief_m * 0.4
    return _rgba(rgb), depth


def panel_like(w_px: int = 40, h_px: int = 60, body=(200, 30, 40), stripe=(240, 240, 240),
               relief_m: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A tall box with a white stripe in its upper third and a sloped top; (RGBA, depth)."""
    rgb = np.empty((h_px, w_px, 3), np.uint8)
    rgb[:] = body
    rgb[h_px // 5: h_px // 5 + max(2, h_px // 8), 3:-3] = stripe
    depth = np.full((h_px, w_px), relief_m, np.float32)
    depth[: h_px // 4] = np.linspace(relief_m * 0.3, relief_m, h_px // 4, dtype=np.float32)[:, None]
    return _rgba(rgb), depth


def sign_like(w_px: int = 42, h_px: int = 42, back=(0, 132, 80), fig=(250, 250, 250)) -> tuple[np.ndarray, None]:
    """A flat square sign with a white cross; (RGBA, no depth)."""
    rgb = np.empty((h_px, w_px, 3), np.uint8)
    rgb[:] = back
    t = max(2, w_px // 7)
    rgb[h_px // 2 - t: h_px // 2 + t, w_px // 5: -w_px // 5] = fig
    rgb[h_px // 5: -h_px // 5, w_px // 2 - t: w_px // 2 + t] = fig
    return _rgba(rgb), None


def knob_like(d_px: int = 22, body=(250, 250, 250), ring=(220, 40, 30), relief_m: float = 0.04) -> tuple[np.ndarray, np.ndarray]:
    """A round dome (alpha 0 outside the disc) with a red ring; (RGBA, depth)."""
    yy, xx = np.mgrid[0:d_px, 0:d_px]
    rr = np.hypot(yy - (d_px - 1) / 2, xx - (d_px - 1) / 2) / (d_px / 2)
    inside = rr <= 1.0
    rgb = np.empty((d_px, d_px, 3), np.uint8)
    rgb[:] = body
    rgb[(rr > 0.55) & (rr < 0.8)] = ring
    depth = np.where(inside, relief_m * np.sqrt(np.clip(1 - rr ** 2, 0, 1)) + 0.005, 0.0).astype(np.float32)
    return _rgba(rgb, np.where(inside, 255, 0)), depth


def arrow_like(w_px: int = 30, h_px: int = 16, body=(240, 240, 235), mark=(30, 30, 30),
               relief_m: float = 0.015) -> tuple[np.ndarray, np.ndarray]:
    """An asymmetric wide plate (a ramp left to right and a dark mark at the left); (RGBA, depth)."""
    rgb = np.empty((h_px, w_px, 3), np.uint8)
    rgb[:] = body
    rgb[3:-3, 2: w_px // 4] = mark
    depth = np.tile(np.linspace(relief_m * 0.3, relief_m, w_px, dtype=np.float32), (h_px, 1))
    return _rgba(rgb), depth


def make_model(class_id: str, view: np.ndarray, depth: np.ndarray | None, pixel_m: float = PIXEL_M,
               upsample: int = 4) -> ObjectModel:
    """An ObjectModel whose views are ``upsample`` times finer than the orthoimage."""
    h, w = view.shape[:2]
    big = cv2.resize(view, (w * upsample, h * upsample), interpolation=cv2.INTER_NEAREST)
    d = None if depth is None else cv2.resize(depth, (w * upsample, h * upsample), interpolation=cv2.INTER_NEAREST)
    return ObjectModel(class_id=class_id, name=class_id, ifc_class="IfcBuildingElementProxy",
                       predefined_type=None, width_m=w * pixel_m, height_m=h * pixel_m,
                       colour_views=[big], depth=d)


def synthetic_library() -> ModelLibrary:
    """Five synthetic classes: socket, panel, sign (colour only), knob, arrow."""
    specs = {
        "socket": socket_like(),
        "panel": panel_like(),
        "sign": sign_like(),
        "knob": knob_like(),
        "arrow": arrow_like(),
    }
    return ModelLibrary({k: make_model(k, v, d) for k, (v, d) in specs.items()}, root="synthetic")


@dataclass
class Placed:
    class_id: str
    centre: tuple[float, float]  # (row, col) footprint centre
    rotation_deg: int = 0


def make_wall(h_px: int = 300, w_px: int = 500, colour=(225, 220, 205), colour_noise: float = 3.0,
              depth_noise_m: float = 0.0008, holes: int = 4, seed: int = 0,
              wall_id: str = "W01") -> tuple[Orthoimage, WallArea]:
    """A plain noisy wall with ``holes`` random no-data discs; WallArea has all data as visible."""
    rng = np.random.default_rng(seed)
    colour_img = np.clip(np.asarray(colour, float) + rng.normal(0, colour_noise, (h_px, w_px, 3)), 0, 255)
    depth = rng.normal(0, depth_noise_m, (h_px, w_px)).astype(np.float32)
    mask = np.ones((h_px, w_px), bool)
    for _ in range(holes):
        cy, cx, rad = rng.integers(0, h_px), rng.integers(0, w_px), rng.integers(3, 9)
        yy, xx = np.ogrid[0:h_px, 0:w_px]
        mask &= (yy - cy) ** 2 + (xx - cx) ** 2 > rad ** 2
    depth[~mask] = np.nan
    colour_img[~mask] = 0
    frame = WallFrame(origin=np.array([1.0, 2.0, 0.0]), axis_u=np.array([1.0, 0.0, 0.0]),
                      axis_v=np.array([0.0, 0.0, 1.0]), normal=np.array([0.0, -1.0, 0.0]),
                      width_m=w_px * PIXEL_M, height_m=h_px * PIXEL_M)
    ortho = Orthoimage(wall_id, frame, PIXEL_M, colour_img.astype(np.uint8), depth, mask)
    area = WallArea(visible=mask.copy(), openings=[], opening_mask=np.zeros((h_px, w_px), bool),
                    wall_colour=np.asarray(colour, float))
    return ortho, area


def paste(ortho: Orthoimage, area: WallArea, t: ModelTemplate, centre: tuple[float, float],
          rotation_deg: int = 0, blur_px: float = 0.6, seed: int = 0,
          depth_noise_m: float = 0.0008, colour_noise: float = 3.0) -> None:
    """Paste template ``t`` (rotated counter-clockwise) so that its footprint centre is ``centre``.

    ``centre`` may be fractional: the template is shifted sub-pixel with a bilinear warp.
    Pixels covered by the object are removed from ``area.visible``.
    """
    rng = np.random.default_rng(seed)
    k = (rotation_deg // 90) % 4
    view = np.rot90(t.colour_views[0], k).astype(np.float32)
    h, w = view.shape[:2]
    H, W = ortho.shape
    ty, tx = centre[0] - (h - 1) / 2.0, centre[1] - (w - 1) / 2.0
    m = np.float32([[1, 0, tx], [0, 1, ty]])

    def warp(img: np.ndarray) -> np.ndarray:
        out = cv2.warpAffine(img, m, (W, H), flags=cv2.INTER_LINEAR, borderValue=0)
        return cv2.GaussianBlur(out, (0, 0), blur_px) if blur_px > 0 else out

    alpha = warp(np.ascontiguousarray(view[..., 3] / 255.0))
    prem = warp(np.ascontiguousarray(view[..., :3] * (view[..., 3:] / 255.0)))
    col = ortho.colour.astype(np.float32)
    hole = ~ortho.mask
    a = alpha[..., None]
    new = col * (1 - a) + prem + rng.normal(0, colour_noise, col.shape) * a
    new = np.where(hole[..., None], prem / np.maximum(a, 1e-3), new)
    show = (alpha > 0.02) & (~hole | (alpha > 0.5))
    ortho.colour[show] = np.clip(new[show], 0, 255).astype(np.uint8)
    if t.depth is not None:
        depth = np.ascontiguousarray(np.rot90(np.nan_to_num(t.depth), k).astype(np.float32))
        dd = cv2.warpAffine(depth, m, (W, H), flags=cv2.INTER_LINEAR, borderValue=0)
        on = np.abs(dd) > 1e-4
        ortho.depth[on] = dd[on] + rng.normal(0, depth_noise_m, int(on.sum())).astype(np.float32)
        ortho.mask |= on
    ortho.mask |= alpha > 0.5
    fp = alpha > 0.5
    area.visible &= ~cv2.dilate(fp.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
