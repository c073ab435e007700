"""The thirteen virtual object classes: footprints, depths, determinism."""

import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.simulate.catalogue import CATALOGUE, CLASS_ORDER, TABLE1_COUNTS
from sbsc_core.simulate.objects import build_object


@pytest.mark.parametrize("class_id", CLASS_ORDER)
def test_object_fits_its_footprint_and_depth(class_id: str) -> None:
    spec = CATALOGUE[class_id]
    mesh = build_object(class_id)
    v = mesh.vertices
    assert mesh.n_triangles > 0
    assert v[:, 0].min() >= -spec.width_m / 2 - 1e-6 and v[:, 0].max() <= spec.width_m / 2 + 1e-6
    assert v[:, 1].min() >= -spec.height_m / 2 - 1e-6 and v[:, 1].max() <= spec.height_m / 2 + 1e-6
    assert v[:, 2].min() >= -1e-9
    assert v[:, 2].max() <= spec.depth_m + 0.001
    # the object fills most of its footprint's height and width (within 2.6 cm)
    assert v[:, 0].max() - v[:, 0].min() >= spec.width_m - 0.026
    assert v[:, 1].max() - v[:, 1].min() >= spec.height_m - 0.002


def test_objects_are_deterministic() -> None:
    a, b = build_object("fire_extinguisher"), build_object("fire_extinguisher")
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.tri_colour, b.tri_colour)


def test_signs_carry_a_pictogram_texture() -> None:
    mesh = build_object("extinguisher_sign")
    assert len(mesh.textures) == 1
    tex = mesh.textures[0]
    red = (tex[..., 0] > 150) & (tex[..., 1] < 80)
    light = tex.mean(axis=2) > 200
    assert 0.3 < red.mean() < 0.9 and light.mean() > 0.1  # red sign with a light pictogram


def test_unknown_class_is_refused() -> None:
    with pytest.raises(InputError, match="unknown class 'toaster'"):
        build_object("toaster")


def test_table1_counts_cover_the_catalogue() -> None:
    assert set(TABLE1_COUNTS) == set(CATALOGUE) and sum(TABLE1_COUNTS.values()) == 116
