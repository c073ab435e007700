"""Model library resampled to the orthoimage resolution (templates.py)."""

import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.recognition.templates import make_templates, resample_depth, resample_rgba
from sbsc_core.types import ModelLibrary, ObjectModel


def _model(cid: str, w_m: float, h_m: float, view: np.ndarray, depth: np.ndarray | None) -> ObjectModel:
    return ObjectModel(cid, cid, "IfcOutlet", None, w_m, h_m, [view], depth)


def test_footprint_decides_pixel_size() -> None:
    view = np.zeros((97, 211, 4), np.uint8)
    view[..., 3] = 255
    lib = ModelLibrary({"a": _model("a", 0.21, 0.097, view, None), "b": _model("b", 0.08, 0.08, view, np.ones((5, 5), np.float32))})
    t = make_templates(lib, 0.005)
    assert (t["a"].height_px, t["a"].width_px) == (19, 42)  # round(0.097/0.005)=19, round(0.21/0.005)=42
    assert t["a"].colour_views[0].shape == (19, 42, 4)
    assert t["a"].depth is None
    assert t["b"].depth.shape == (16, 16) and t["b"].depth.dtype == np.float32
    assert sorted(make_templates(lib, 0.005, ["b"])) == ["b"]


def test_unknown_class_and_bad_size_are_refused() -> None:
    view = np.full((4, 4, 4), 255, np.uint8)
    lib = ModelLibrary({"a": _model("a", 0.02, 0.02, view, None)})
    with pytest.raises(InputError, match="nope"):
        make_templates(lib, 0.005, ["nope"])
    lib = ModelLibrary({"a": _model("a", 0.0, 0.02, view, None)})
    with pytest.raises(InputError, match="width_m"):
        make_templates(lib, 0.005)


def test_alpha_background_does_not_bleed_into_object_colour() -> None:
    view = np.zeros((40, 40, 4), np.uint8)
    view[..., 1] = 255  # green background...
    view[10:30, 10:30] = (255, 0, 0, 255)  # ...around an opaque red square
    small = resample_rgba(view, (4, 4))
    border = small[small[..., 3] > 0]
    assert len(border) > 0
    assert border[:, 1].max() == 0 and border[:, 0].min() == 255  # pure red, no green bleeding
    assert small[0, 0, 3] == 0 and small[1, 1, 3] == 255


def test_depth_resampling_ignores_unknown_samples() -> None:
    d = np.full((20, 20), 0.01, np.float32)
    d[:, :7] = np.nan
    out = resample_depth(d, (4, 4))
    assert np.isnan(out[:, 0]).all()
    assert np.allclose(out[:, 1:], 0.01)  # partly unknown cells keep the known value


def test_further_depth_models_are_resampled_with_the_reference() -> None:
    from sbsc_core.recognition.templates import make_template
    from sbsc_core.types import ObjectModel

    view = np.full((40, 40, 4), 255, np.uint8)
    m = ObjectModel("s", "s", "IfcOutlet", None, 0.08, 0.08, [view], np.full((40, 40), 0.01, np.float32),
                    extra_depths=[np.full((32, 32), 0.02, np.float32), np.full((8, 8), np.nan, np.float32)])
    t = make_template(m, 0.005)
    assert [d.shape for d in t.extra_depths] == [(16, 16)]  # an all-unknown model is dropped
    models = t.depth_models()
    assert len(models) == 2 and float(models[1][0, 0]) == pytest.approx(0.02)
