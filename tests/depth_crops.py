"""Crops of simulated walls stored as test data: depth in 0.1 mm steps, the visible area, and
where the object (or the false match) is; shared by the tests of depth recognition beside furniture."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sbsc_core.io.models import load_model_library
from sbsc_core.recognition.templates import make_templates
from sbsc_core.types import Orthoimage, WallArea, WallFrame

PIXEL_M = 0.005


def bundled_templates() -> dict:
    """The bundled model library's templates at 5 mm pixels."""
    lib = load_model_library(Path(__file__).parents[1] / "sbsc_core" / "data" / "models")
    return make_templates(lib, PIXEL_M)


def depth_crop(data: Path, name: str, at_key: str) -> tuple[Orthoimage, WallArea, tuple[float, float]]:
    """Crop ``name`` of ``data`` as an orthoimage (flat grey where seen), its wall area (with
    ``<name>_opening`` when stored) and the pixel ``<name>_<at_key>``."""
    z = np.load(data)
    q = z[f"{name}_depth_01mm"]
    depth = np.where(q == -32768, np.nan, q * 1e-4).astype(np.float32)
    h, w = depth.shape
    mask = np.isfinite(depth)
    frame = WallFrame(origin=np.zeros(3), axis_u=np.array([1.0, 0.0, 0.0]), axis_v=np.array([0.0, 0.0, 1.0]),
                      normal=np.array([0.0, -1.0, 0.0]), width_m=w * PIXEL_M, height_m=h * PIXEL_M)
    colour = np.where(mask[..., None], 200, 0).astype(np.uint8) * np.ones((1, 1, 3), np.uint8)
    ortho = Orthoimage("W01", frame, PIXEL_M, colour, depth, mask)
    opening = z[f"{name}_opening"] if f"{name}_opening" in z.files else np.zeros((h, w), bool)
    area = WallArea(visible=z[f"{name}_visible"], openings=[], opening_mask=opening,
                    wall_colour=np.array([200.0, 200.0, 200.0]))
    r, c = z[f"{name}_{at_key}"]
    return ortho, area, (float(r), float(c))
