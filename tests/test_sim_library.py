"""The model library built by scanning each class on its own (contract 2)."""

import json

import numpy as np
import pytest

from sbsc_core.io.models import load_model_library
from sbsc_core.paths import bundled_models_dir
from sbsc_core.simulate.catalogue import CATALOGUE, CLASS_ORDER
from sbsc_core.simulate.library import render_model, write_model_library


def test_render_sizes_coverage_and_depth() -> None:
    m = render_model("smoke_detector", pixel_m=0.002, seed=0, n_views=2)
    spec = CATALOGUE["smoke_detector"]
    h, w = m.depth.shape
    assert (h, w) == (round(spec.height_m / 0.002), round(spec.width_m / 0.002))
    alpha = m.colour_views[0][..., 3] > 0
    assert abs(alpha.mean() - np.pi / 4) < 0.05  # a round object covers pi/4 of its square
    assert abs(float(np.nanmax(m.depth)) - spec.depth_m) < 0.004
    assert abs(float(np.median(m.depth[~alpha]))) < 0.002  # the wall around it is at 0
    a, b = (v[..., :3].astype(float) for v in m.colour_views)
    diff = np.abs(a - b)[alpha].mean()
    assert 0.5 < diff < 30  # two views differ by noise, but not by much


def test_written_library_is_valid_and_deterministic(tmp_path) -> None:
    classes = ["socket_x1", "extinguisher_sign"]
    write_model_library(tmp_path / "a", classes=classes, seed=3)
    write_model_library(tmp_path / "b", classes=classes, seed=3)
    lib = load_model_library(tmp_path / "a")
    assert lib.class_ids == sorted(classes)
    for cls in classes:
        model = lib[cls]
        assert len(model.colour_views) == 3 and model.depth is not None
        assert model.depth.dtype == np.float32
        meta = json.loads((tmp_path / "a" / cls / "model.json").read_text())
        assert meta["ifc_class"] == CATALOGUE[cls].ifc_class
        for name in ("colour.png", "colour_1.png", "depth.npy"):
            assert (tmp_path / "a" / cls / name).read_bytes() == (tmp_path / "b" / cls / name).read_bytes()


@pytest.mark.parametrize("class_id", CLASS_ORDER)
def test_bundled_library_has_every_class(class_id: str) -> None:
    lib = load_model_library(bundled_models_dir())
    model = lib[class_id]
    spec = CATALOGUE[class_id]
    assert model.width_m == spec.width_m and model.height_m == spec.height_m
    h, w = model.depth.shape
    assert abs(h / w - spec.height_m / spec.width_m) < 0.05
