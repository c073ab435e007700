"""The model library, built the way the paper built its database: every class scanned on
its own, straight on (section 5.1: "the object model database has also been generated with
Blensor").

Each class is ray-cast orthographically over exactly its footprint: the depth model is how
far the hit surface stands out of the wall (0 where the ray reaches the wall), the colour
views are the hit colours with alpha 0 on the wall. Several views differ by range noise,
colour noise and illumination, like separate scans.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..io.atomic import atomic_output_dir
from .building import ObjectBuilder, builder_specs
from .catalogue import CATALOGUE, CLASS_ORDER, ObjectSpec
from .objects import build_object
from .raycast import MeshRaycaster


@dataclass
class RenderedModel:
    colour_views: list[np.ndarray]  # (h, w, 4) uint8 RGBA, alpha 0 = wall
    depth: np.ndarray  # (h, w) float32 metres out of the wall


def render_model(class_id: str, *, pixel_m: float = 0.002, seed: int = 0, n_views: int = 3,
                 supersample: int = 3, range_noise_m: float = 0.0008,
                 colour_noise: float = 3.0, object_builder: ObjectBuilder | None = None
                 ) -> RenderedModel:
    """Scan one object of ``class_id`` straight on; see the module docstring.

    ``object_builder`` is the design set the object is built with (default: the standard
    :func:`~sbsc_core.simulate.objects.build_object`; see :mod:`designs`); the footprint is
    the catalogue's, or the builder's own ``specs`` (a random family).
    """
    spec = builder_specs(object_builder)[class_id]
    mesh = (object_builder or build_object)(class_id)
    caster = MeshRaycaster(mesh)
    w_px = max(1, round(spec.width_m / pixel_m))
    h_px = max(1, round(spec.height_m / pixel_m))
    k = supersample
    xs = -spec.width_m / 2 + (np.arange(w_px * k) + 0.5) * spec.width_m / (w_px * k)
    ys = spec.height_m / 2 - (np.arange(h_px * k) + 0.5) * spec.height_m / (h_px * k)
    gx, gy = np.meshgrid(xs, ys)
    z0 = spec.depth_m + 0.5
    origins = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z0)])
    dirs = np.tile([0.0, 0.0, -1.0], (gx.size, 1))
    hits = caster.cast(origins, dirs)
    hit = hits.hit.reshape(h_px * k, w_px * k)
    z = np.where(hit, z0 - hits.t.reshape(h_px * k, w_px * k), 0.0)
    rgb = hits.rgb.reshape(h_px * k, w_px * k, 3).astype(np.float64)

    def pool(a: np.ndarray) -> np.ndarray:
        sh = (h_px, k, w_px, k) + a.shape[2:]
        return a.reshape(sh).mean(axis=(1, 3))

    cover = pool(hit.astype(np.float64))
    depth_clean = pool(z)
    with np.errstate(invalid="ignore", divide="ignore"):
        colour_clean = pool(rgb * hit[..., None]) / np.maximum(cover, 1e-9)[..., None]
    rng = np.random.default_rng(seed * 1000 + CLASS_ORDER.index(class_id) if class_id in CLASS_ORDER else seed)
    depth = (depth_clean + np.where(cover > 0, rng.normal(0, range_noise_m, depth_clean.shape), 0.0))
    views = []
    for _ in range(n_views):
        gain = rng.uniform(0.9, 1.08)
        c = colour_clean * gain + rng.normal(0, colour_noise, colour_clean.shape)
        rgba = np.zeros((h_px, w_px, 4), np.uint8)
        rgba[..., :3] = np.clip(np.nan_to_num(c), 0, 255).astype(np.uint8)
        rgba[..., 3] = np.where(cover >= 0.5, 255, 0).astype(np.uint8)
        views.append(rgba)
    return RenderedModel(views, depth.astype(np.float32))


def model_json(class_id: str, specs: Mapping[str, ObjectSpec] = CATALOGUE) -> dict:
    """``model.json`` of ``class_id`` (contract 2) with the size of its design in ``specs``."""
    spec = specs[class_id]
    doc = {"name": spec.name, "ifc_class": spec.ifc_class, "predefined_type": spec.predefined_type,
           "width_m": spec.width_m, "height_m": spec.height_m, "depth_m": spec.depth_m,
           "order": CLASS_ORDER.index(class_id) + 1,  # the library's order (contract 2): the paper's
           "mount": list(spec.mount)}
    if spec.object_type:
        doc["object_type"] = spec.object_type
    return doc


def write_model_library(out_dir: Path, classes: Sequence[str] = CLASS_ORDER, *, seed: int = 0,
                        pixel_m: float = 0.002, n_views: int = 3,
                        object_builder: ObjectBuilder | None = None) -> Path:
    """Write a contract-2 library of ``classes`` into ``out_dir`` atomically; return it.

    The models are scans of the design set ``object_builder`` (default: the standard one);
    a simulated scene's library is rendered with the scene's builder unless told otherwise.
    """
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir) as tmp:
        for cls in classes:
            model = render_model(cls, pixel_m=pixel_m, seed=seed, n_views=n_views,
                                 object_builder=object_builder)
            d = tmp / cls
            d.mkdir()
            (d / "model.json").write_text(json.dumps(model_json(cls, builder_specs(object_builder)), indent=2) + "\n")
            for i, view in enumerate(model.colour_views):
                name = "colour.png" if i == 0 else f"colour_{i}.png"
                cv2.imwrite(str(d / name), cv2.cvtColor(view, cv2.COLOR_RGBA2BGRA))
            np.save(d / "depth.npy", model.depth)
    return out_dir
