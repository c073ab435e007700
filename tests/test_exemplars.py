"""Exemplar libraries: which crops are cut, and the learnt depth model."""

from __future__ import annotations

import numpy as np
import pytest

from app.exemplars import learnt_depth, upright


@pytest.mark.parametrize(("deg", "ok"), [(0.0, True), (-2.0, True), (180.0, True), (178.0, True),
                                         (359.0, True), (90.0, False), (-90.0, False), (30.0, False)])
def test_only_objects_about_upright_or_upside_down_give_a_crop(deg: float, ok: bool) -> None:
    assert upright(deg) is ok


def test_learnt_depth_is_the_median_of_the_crops_of_the_common_size() -> None:
    rng = np.random.default_rng(0)
    relief = np.zeros((16, 16), np.float32)
    relief[4:12, 4:12] = 0.012
    crops = [relief + rng.normal(0, 0.002, relief.shape).astype(np.float32) for _ in range(7)]
    crops[0][:, :3] = np.nan  # a partly seen one
    crops.append(np.ones((20, 20), np.float32))  # another pixel size: left out
    model = learnt_depth(crops)
    assert model.shape == (16, 16) and np.isfinite(model).all()
    assert np.abs(model - relief).max() < np.abs(crops[1] - relief).max()  # less noisy than one crop
    assert learnt_depth([]) is None


def test_learnt_view_is_the_median_colour_crop() -> None:
    from app.exemplars import learnt_view

    crops = [np.full((16, 16, 3), v, np.uint8) for v in (10, 30, 200)]
    crops.append(np.zeros((8, 8, 3), np.uint8))  # another size: left out
    view = learnt_view(crops)
    assert view.dtype == np.uint8 and view.shape == (16, 16, 3) and int(view[0, 0, 0]) == 30
    assert learnt_view([]) is None
