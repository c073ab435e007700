"""Depth is metric (amplitude.py): a place is not taken for a class that its relief rules out."""

from __future__ import annotations

import numpy as np

from sbsc_core.recognition.amplitude import (
    colour_where_relief_allows,
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
