"""A depth match placed by its relief's sharp edges (edge_position.py)."""

import numpy as np
import pytest

from sbsc_core.recognition.consensus import weighted_centre
from sbsc_core.recognition.edge_position import EdgeSettings, sharp_edge_centre
from sbsc_core.recognition.matching import match_in_rois
from sbsc_core.types import Box, Candidate

RELIEF_M = 0.06  # a box 6 cm deep (an electrical panel, an exit light)
H, W = 24, 40  # its model, pixels


def _cover(n: int, lo: float, hi: float) -> np.ndarray:
    """Share of each pixel (centres 0..n-1) inside [lo, hi]."""
    x = np.arange(n, dtype=float)
    return np.clip(np.minimum(x + 0.5, hi) - np.maximum(x - 0.5, lo), 0.0, 1.0)


def _box(shape: tuple[int, int], centre: tuple[float, float]) -> np.ndarray:
    rows = _cover(shape[0], centre[0] - H / 2, centre[0] + H / 2)
    cols = _cover(shape[1], centre[1] - W / 2, centre[1] + W / 2)
    return RELIEF_M * np.outer(rows, cols)


def _scene(centre: tuple[float, float], ramp_px: int = 0, seed: int = 0) -> np.ndarray:
    """A box at ``centre`` on a noisy wall; with ``ramp_px`` its left and top sides trail
    off into an occlusion shadow full of mixed pixels (a scanner below, to the right)."""
    img = _box((120, 160), centre)
    if ramp_px:
        top, left = centre[0] - H / 2, centre[1] - W / 2
        rows = _cover(img.shape[0], top, centre[0] + H / 2) > 0
        cols = _cover(img.shape[1], left, centre[1] + W / 2) > 0
        fall = lambda t: RELIEF_M * np.clip(1.0 - t / (ramp_px + 1), 0.0, 1.0) * (t > -0.5)  # noqa: E731
        x = np.arange(160, dtype=float)
        y = np.arange(120, dtype=float)
        img[rows] = np.maximum(img[rows], fall(left - x)[None, :])
        img[:, cols] = np.maximum(img[:, cols], fall(top - y)[:, None])
    return (img + np.random.default_rng(seed).normal(0.0, 0.0005, img.shape)).astype(np.float32)


MODEL = _box((H, W), ((H - 1) / 2, (W - 1) / 2)).astype(np.float32)


def _ncc_centre(scene: np.ndarray) -> tuple[float, float]:
    m = match_in_rois(scene, MODEL, [Box(40, 50, 90, 110)], threshold=0.5, pad_px=4, margin_px=6, max_peaks=1)
    assert len(m) == 1
    return m[0].row, m[0].col


def test_a_shadowed_side_pulls_the_correlation_but_not_the_sharp_edges() -> None:
    truth = (60.3, 80.6)
    scene = _scene(truth, ramp_px=6)
    ncc = _ncc_centre(scene)
    # the correlation fits the ramps too: more than half a pixel (2.5 mm) towards them
    assert truth[0] - ncc[0] > 0.4 and truth[1] - ncc[1] > 0.4
    r, c = sharp_edge_centre(scene, MODEL, ncc)
    assert abs(r - truth[0]) < 0.25 and abs(c - truth[1]) < 0.25


def test_a_frontal_view_keeps_the_correlation_centre() -> None:
    truth = (59.7, 80.2)
    scene = _scene(truth, seed=1)
    ncc = _ncc_centre(scene)
    r, c = sharp_edge_centre(scene, MODEL, ncc)
    assert abs(r - truth[0]) < 0.15 and abs(c - truth[1]) < 0.15
    assert abs(r - ncc[0]) < 0.2 and abs(c - ncc[1]) < 0.2


def test_a_neighbour_beyond_the_edge_does_not_count() -> None:
    truth = (60.0, 80.0)
    scene = _scene(truth, ramp_px=5, seed=2)
    scene[48:72, 103:112] += 0.02  # a 2 cm deep object 3 px right of the box
    r, c = sharp_edge_centre(scene, MODEL, (59.2, 79.2))
    assert abs(r - truth[0]) < 0.25 and abs(c - truth[1]) < 0.25


def test_an_unseen_edge_keeps_the_correlation_coordinate() -> None:
    scene = _scene((60.0, 80.0), seed=3)
    known = np.ones(scene.shape, bool)
    known[:, 95:] = False  # the right side not scanned
    scene[~known] = 0.0
    r, c = sharp_edge_centre(scene, MODEL, (60.4, 79.3), known)
    assert c == 79.3  # no right edge: the columns are not refined
    assert abs(r - 60.0) < 0.15
    # near the image's border nothing is read
    assert sharp_edge_centre(scene, MODEL, (8.0, 12.0)) == (8.0, 12.0)


def test_a_far_jump_is_not_trusted() -> None:
    scene = _scene((60.0, 80.0), seed=4)
    s = EdgeSettings(max_shift_px=0.5)
    r, c = sharp_edge_centre(scene, MODEL, (60.0, 81.5), settings=s)
    assert c == 81.5 and r == pytest.approx(60.0, abs=0.15)


def test_a_recessed_model_is_read_with_its_sign() -> None:
    truth = (61.5, 79.5)
    scene = -_scene(truth, ramp_px=4, seed=5)
    r, c = sharp_edge_centre(scene, -MODEL, (60.8, 78.7))
    assert abs(r - truth[0]) < 0.25 and abs(c - truth[1]) < 0.25


def test_a_shallow_model_keeps_the_correlation_centre() -> None:
    shallow = MODEL * (0.015 / RELIEF_M)  # a socket 15 mm deep: its shadow is under a pixel
    scene = _scene((60.3, 80.6), ramp_px=6) * (0.015 / RELIEF_M)
    assert sharp_edge_centre(scene, shallow, (59.8, 80.1)) == (59.8, 80.1)


def test_placement_uses_the_depth_matchs_edge_position() -> None:
    box = Box(0, 10, 0, 10)
    d = Candidate("x", "W01", "depth", box, (10.0, 10.0), 0.9, position=(10.5, 9.5))
    c = Candidate("x", "W01", "colour", box, (10.5, 9.5), 0.1)
    assert weighted_centre(d, None) == (10.5, 9.5)
    assert weighted_centre(d, c, 3.0) == pytest.approx((10.5, 9.5))
    assert weighted_centre(None, c) == (10.5, 9.5)
