"""The third design set: catalogue footprints, and different from both other sets (testing only)."""

from __future__ import annotations

import numpy as np
import pytest

from sbsc_core.simulate.catalogue import CATALOGUE, CLASS_ORDER
from sbsc_core.simulate.designs import design_builder
from sbsc_core.simulate.library import render_model
from sbsc_core.simulate.objects import build_object
from sbsc_core.simulate.objects_alt import build_object_alt
from sbsc_core.simulate.objects_third import SIGN_SIDE_M, build_object_third


def _clean(class_id: str, builder) -> tuple[np.ndarray, np.ndarray]:
    m = render_model(class_id, pixel_m=0.004, n_views=1, supersample=1, range_noise_m=0.0,
                     colour_noise=0.0, object_builder=builder)
    return m.depth, m.colour_views[0]


def test_registered() -> None:
    assert design_builder("third") is build_object_third


@pytest.mark.parametrize("class_id", CLASS_ORDER)
def test_third_design_fits_the_footprint_and_differs_from_both(class_id: str) -> None:
    spec = CATALOGUE[class_id]
    v = build_object_third(class_id).vertices
    assert v[:, 0].min() >= -spec.width_m / 2 - 1e-6 and v[:, 0].max() <= spec.width_m / 2 + 1e-6
    assert v[:, 1].min() >= -spec.height_m / 2 - 1e-6 and v[:, 1].max() <= spec.height_m / 2 + 1e-6
    assert v[:, 2].min() >= -1e-9 and v[:, 2].max() <= spec.depth_m + 0.001
    d3, c3 = _clean(class_id, build_object_third)
    for other in (build_object, build_object_alt):
        d, c = _clean(class_id, other)
        colour_diff = float(np.abs(c[..., :3].astype(float) - c3[..., :3]).mean())
        changed = np.abs(c[..., :3].astype(int) - c3[..., :3]).max(axis=2) > 20
        depth_diff_mm = float(np.nanmean(np.abs(d - d3))) * 1000
        assert colour_diff > 3.0 and (changed.mean() > 0.05 or depth_diff_mm > 2.0), (colour_diff, depth_diff_mm)


def test_the_two_signs_are_same_size_square_red_plates_with_different_pictograms() -> None:
    a = build_object_third("extinguisher_sign").vertices
    b = build_object_third("fire_alarm_switch_sign").vertices
    for v in (a, b):
        assert np.ptp(v[:, 0]) == pytest.approx(SIGN_SIDE_M) and np.ptp(v[:, 1]) == pytest.approx(SIGN_SIDE_M)
    _, ca = _clean("extinguisher_sign", build_object_third)
    _, cb = _clean("fire_alarm_switch_sign", build_object_third)
    h = min(ca.shape[0], cb.shape[0])
    ya, yb = (ca.shape[0] - h) // 2, (cb.shape[0] - h) // 2
    pa, pb = ca[ya:ya + h, :, :3].astype(int), cb[yb:yb + h, :, :3].astype(int)
    red = lambda p: (p[..., 0] > 150) & (p[..., 1] < 80)  # noqa: E731
    assert red(pa).mean() > 0.5 and red(pb).mean() > 0.5
    assert (np.abs(pa - pb).max(axis=2) > 60).mean() > 0.05  # the pictograms differ
