"""The model library resampled to the orthoimage resolution (paper, section 4.2, "Matching").

The paper notes that the orthoimage and the depth models share one scale (pixels per
centimetre), so the cross-correlation runs at a single scale. Every model of the library
(contract 2) is therefore resampled once, with ``cv2.INTER_AREA``, to the pixel size of
the orthoimages: its footprint ``width_m`` x ``height_m`` becomes
``round(width_m / pixel_m)`` x ``round(height_m / pixel_m)`` pixels.

Colour views are resampled with premultiplied alpha, so that background pixels (alpha 0)
do not bleed into the object's border colours. Depth models are resampled as a
NaN-aware weighted mean (unknown samples do not pull the relief towards zero).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import InputError
from ..types import ModelLibrary, ObjectModel


@dataclass
class ModelTemplate:
    """One class of the library at orthoimage resolution.

    ``colour_views`` are RGBA ``(height_px, width_px, 4)`` uint8 (alpha 0 = background);
    ``depth`` is ``(height_px, width_px)`` float32 metres out of the wall plane (NaN
    unknown) or None when the library has no depth model for the class. ``extra_depths``
    are the class's further depth models (``depth_<k>.npy``, e.g. exemplars measured on a
    reviewed scan) at the same resolution; recognition tries them too (:meth:`depth_models`).
    """

    class_id: str
    width_px: int
    height_px: int
    width_m: float
    height_m: float
    pixel_m: float
    colour_views: list[np.ndarray]
    depth: np.ndarray | None
    name: str = ""
    extra: dict = field(default_factory=dict)
    extra_depths: list[np.ndarray] = field(default_factory=list)

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height_px, self.width_px)

    def depth_models(self) -> list[np.ndarray]:
        """Every depth model of the class, unknown samples set to the wall plane: the
        reference model first, then the further ones (none when the class has no depth)."""
        if self.depth is None:
            return []
        return [self.depth_filled()] + [np.nan_to_num(d, nan=0.0).astype(np.float32) for d in self.extra_depths]

    def depth_filled(self) -> np.ndarray | None:
        """The depth model with unknown samples set to the wall plane (0 m)."""
        if self.depth is None:
            return None
        return np.nan_to_num(self.depth, nan=0.0).astype(np.float32)

    def relief_m(self) -> float:
        """The largest absolute relief of the depth model (0 when there is none)."""
        if self.depth is None or not np.isfinite(self.depth).any():
            return 0.0
        return float(np.nanmax(np.abs(self.depth)))


def footprint_px(width_m: float, height_m: float, pixel_m: float) -> tuple[int, int]:
    """(height_px, width_px) of a footprint at ``pixel_m``: ``round(size / pixel_m)``, at least 1."""
    return max(1, round(height_m / pixel_m)), max(1, round(width_m / pixel_m))


def resample_rgba(view: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Resample an RGBA (or RGB) uint8 view to ``shape`` = (h, w) with premultiplied alpha."""
    view = np.asarray(view)
    if view.ndim != 3 or view.shape[2] not in (3, 4):
        raise ValueError(f"colour view must be (h, w, 3|4), got {view.shape}")
    h, w = shape
    if view.shape[2] == 3:
        alpha = np.full(view.shape[:2], 1.0, np.float32)
    else:
        alpha = view[..., 3].astype(np.float32) / 255.0
    rgb = view[..., :3].astype(np.float32)
    pre = np.dstack([rgb * alpha[..., None], alpha])
    small = cv2.resize(pre, (w, h), interpolation=cv2.INTER_AREA)
    if small.ndim == 2:  # 1x1 results keep their channels, but be safe
        small = small.reshape(h, w, 4)
    a = small[..., 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        col = np.where(a[..., None] > 1e-6, small[..., :3] / np.maximum(a[..., None], 1e-6), 0.0)
    out = np.empty((h, w, 4), np.uint8)
    out[..., :3] = np.clip(np.round(col), 0, 255).astype(np.uint8)
    out[..., 3] = np.clip(np.round(a * 255.0), 0, 255).astype(np.uint8)
    return out


def resample_depth(depth: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Resample a float depth map (NaN unknown) to ``shape`` = (h, w) as a NaN-aware mean."""
    depth = np.asarray(depth, np.float32)
    if depth.ndim != 2:
        raise ValueError(f"depth model must be 2-D, got {depth.shape}")
    h, w = shape
    ok = np.isfinite(depth).astype(np.float32)
    vals = np.where(ok > 0, depth, 0.0).astype(np.float32)
    num = cv2.resize(vals, (w, h), interpolation=cv2.INTER_AREA).reshape(h, w)
    den = cv2.resize(ok, (w, h), interpolation=cv2.INTER_AREA).reshape(h, w)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(den > 1e-3, num / np.maximum(den, 1e-6), np.nan)
    return out.astype(np.float32)


def make_template(model: ObjectModel, pixel_m: float) -> ModelTemplate:
    """Resample one library model to ``pixel_m`` pixels."""
    if not (model.width_m > 0 and model.height_m > 0):
        raise InputError(f"models/{model.class_id}/model.json", "width_m and height_m must be > 0")
    if not model.colour_views and model.depth is None:
        raise InputError(f"models/{model.class_id}", "no colour view and no depth model")
    shape = footprint_px(model.width_m, model.height_m, pixel_m)
    views = [resample_rgba(v, shape) for v in model.colour_views]
    depth = None if model.depth is None else resample_depth(model.depth, shape)
    if depth is not None and not np.isfinite(depth).any():
        depth = None
    extra_depths = [resample_depth(d, shape) for d in getattr(model, "extra_depths", ())] if depth is not None else []
    return ModelTemplate(
        class_id=model.class_id, width_px=shape[1], height_px=shape[0],
        width_m=float(model.width_m), height_m=float(model.height_m), pixel_m=float(pixel_m),
        colour_views=views, depth=depth, name=model.name, extra=dict(model.extra),
        extra_depths=[d for d in extra_depths if np.isfinite(d).any()],
    )


def make_templates(
    library: ModelLibrary, pixel_m: float, classes: Sequence[str] | None = None
) -> dict[str, ModelTemplate]:
    """Resample the library's models (all, or only ``classes``) to ``pixel_m`` pixels."""
    if not pixel_m > 0:
        raise InputError("settings.orthoimage.pixel_m", "must be > 0")
    ids = library.class_ids if classes is None else list(classes)
    out: dict[str, ModelTemplate] = {}
    for cid in ids:
        if cid not in library:
            raise InputError("expected", f"class '{cid}' is not in the model library")
        out[cid] = make_template(library[cid], pixel_m)
    return out
