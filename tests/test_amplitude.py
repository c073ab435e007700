"""Depth is metric (amplitude.py): a place is not taken for a class that its relief rules out."""

from __future__ import annotations

import numpy as np

from sbsc_core.recognition.amplitude import (
    as_far_as_examples,
    colour_where_relief_allows,
    example_limit,
    relief_amplitude,
    scene_amplitude,
)
from sbsc_core.types import Box, Candidate


def _wall(seed: int, sigma_m: float = 0.0005) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, sigma_m, (60, 60)).astype(np.float32)


def _cand(cls: str) -> Candidate:
    return Candidate(cls, "W1", "colour", Box(22, 22, 38, 38), (29.5, 29.5), 0.1)


def test_relief_amplitude_is_robust_and_needs_known_pixels() -> None:
    plate = np.full((16, 16), 0.0025, np.float32)
    plate[0, 0] = 0.5  # one spike says nothing
    assert abs(relief_amplitude(plate) - 0.0025) < 1e-6
    half = plate.copy()
    half[:9] = np.nan
    assert relief_amplitude(half) is None
    wall = _wall(1)
    wall[22:38, 22:38] += 0.0025
    assert abs(scene_amplitude(wall, (16, 16), (29.5, 29.5), 0.0) - 0.0025) < 0.001


def test_a_print_where_the_wall_is_flat_is_refused_and_a_flat_class_is_kept() -> None:
    """A flush 2.5 mm socket's print on a flat wall (a highlight) is refused; the same print
    where the relief stands out 2.5 mm is kept; a sign without a depth model is kept anywhere;
    a place seen too sparsely to measure is kept."""
    models = {"flush": np.full((16, 16), 0.0025, np.float32)}
    flat = _wall(2)
    kept, refused = colour_where_relief_allows([_cand("flush"), _cand("sign")], flat, models, {}, (0.5, 2.0))
    assert [c.class_id for c in kept] == ["sign"]
    assert [r.candidate.class_id for r in refused] == ["flush"] and refused[0].scene_m < 0.5 * refused[0].model_m
    raised = _wall(3)
    raised[22:38, 22:38] += 0.0025
    kept, refused = colour_where_relief_allows([_cand("flush")], raised, models, {}, (0.5, 2.0))
    assert len(kept) == 1 and not refused
    unseen = flat.copy()
    unseen[20:40, 20:40] = np.nan
    kept, _ = colour_where_relief_allows([_cand("flush")], unseen, models, {}, (0.5, 2.0))
    assert len(kept) == 1


def test_noise_never_makes_a_real_object_refused() -> None:
    """On a noisy scan the footprint's amplitude only grows: a real 3 mm sign under 2 mm of
    noise stands out at least as far as its model."""
    models = {"sign": np.full((16, 16), 0.003, np.float32)}
    for seed in range(5):
        noisy = _wall(seed, sigma_m=0.002)
        noisy[22:38, 22:38] += 0.003
        kept, refused = colour_where_relief_allows([_cand("sign")], noisy, models, {}, (0.5, 2.0))
        assert len(kept) == 1 and not refused


def test_a_taught_class_refuses_what_stands_out_beyond_its_examples_spread_and_the_noise() -> None:
    """Examples that stood out 11.0 and 11.2 mm: an instance may stand out 11.2 + 0.2 mm + the
    wall's noise relief. A 21 mm box (1.9x: inside the generic gain_range) is refused as that
    class; the class's own instance on a noisy wall is kept (its noise relief is measured there);
    a class without examples and a place seen too sparsely are kept."""
    assert abs(example_limit([0.011, 0.0112], 0.0025) - (0.0112 + 0.0002 + 0.0025)) < 1e-9
    taught = {"switch": ((16, 16), [0.011, 0.0112])}
    box = _wall(4)
    box[22:38, 22:38] += 0.021
    kept, refused = as_far_as_examples([_cand("switch"), _cand("socket")], box, taught, 0.0025)
    assert [c.class_id for c in kept] == ["socket"]
    assert len(refused) == 1 and refused[0].scene_m > refused[0].limit_m > refused[0].examples_m
    for seed in range(5):  # 2 mm of noise: the wall's noise relief is 4 sigmas of it
        noisy = _wall(seed, sigma_m=0.002)
        noisy[22:38, 22:38] += 0.011
        kept, refused = as_far_as_examples([_cand("switch")], noisy, taught, 4 * 0.002)
        assert len(kept) == 1 and not refused
    unseen = box.copy()
    unseen[20:40, 20:40] = np.nan
    assert len(as_far_as_examples([_cand("switch")], unseen, taught, 0.0025)[0]) == 1
    assert as_far_as_examples([_cand("switch")], box, {}, 0.0025) == ([_cand("switch")], [])
