"""The 15 global descriptors (colour_descriptors.py, paper equations 1-14)."""

import math

import cv2
import numpy as np

from sbsc_core.recognition.colour_descriptors import (
    descriptor_distance,
    descriptors_of,
    glcm_energy,
    global_descriptors,
    kmeans_1d,
    normalise_descriptors,
    rgb_to_hsv,
    rgb_to_hsv_lab,
    roundness,
)
from tests.recognition_synth import knob_like, panel_like, sign_like, socket_like


def _pattern(rgba: np.ndarray) -> np.ndarray:
    return normalise_descriptors(global_descriptors(rgba[..., :3], rgba[..., 3] > 127))


def test_shape_and_named_values_on_a_constructed_image() -> None:
    # a red square (S = 1) holding two separate white spots (S = 0), on a mask of the square
    img = np.zeros((40, 40, 3), np.uint8)
    img[:] = (255, 0, 0)
    img[8:14, 8:14] = 255
    img[24:32, 24:32] = 255
    mask = np.ones((40, 40), bool)
    v = global_descriptors(img, mask)
    assert v.shape == (15,)
    n_white = 36 + 64
    assert abs(v[0] - 1.0) < 1e-6 and abs(v[1]) < 1e-6  # s1 = red's saturation, s2 = white's
    assert abs(v[2] - (1600 - n_white) / 1600) < 1e-6  # v3: share of s1
    assert abs(v[3] - n_white / (1600 - n_white)) < 1e-6  # v4: s2 inside s1 over s1
    assert v[4] == 2  # v5: two segments of s2 in s1
    assert abs(v[13] - np.pi / 4) < 0.01  # v14: a square's roundness
    assert 0 < v[14] < 1


def test_invariant_to_90_degree_rotation() -> None:
    for rgba in (socket_like()[0], panel_like()[0], sign_like()[0], knob_like()[0]):
        a = _pattern(rgba)
        for k in (1, 2, 3):
            b = _pattern(np.ascontiguousarray(np.rot90(rgba, k)))
            assert descriptor_distance(a, b) < 1e-6


def test_nearly_invariant_to_scale() -> None:
    for rgba in (socket_like(32, 32)[0], panel_like(40, 60)[0], sign_like(42, 42)[0], knob_like(30)[0]):
        big = cv2.resize(rgba, None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
        assert descriptor_distance(_pattern(rgba), _pattern(big)) < 0.05


def test_classes_are_far_apart() -> None:
    pats = [_pattern(x) for x in (socket_like()[0], panel_like()[0], sign_like()[0], knob_like()[0])]
    for i in range(len(pats)):
        for j in range(i + 1, len(pats)):
            assert descriptor_distance(pats[i], pats[j]) > 0.2


def test_roundness_of_disc_and_square() -> None:
    yy, xx = np.mgrid[0:81, 0:81]
    disc = (yy - 40) ** 2 + (xx - 40) ** 2 <= 35 ** 2
    assert roundness(disc) > 0.85
    sq = np.zeros((50, 50), bool)
    sq[5:45, 5:45] = True
    assert abs(roundness(sq) - np.pi / 4) < 1e-6
    line = np.zeros((20, 20), bool)
    line[10, 2:18] = True
    assert roundness(line) == 0.0


def test_glcm_energy() -> None:
    mask = np.ones((16, 16), bool)
    assert glcm_energy(np.full((16, 16), 50.0), mask, 8) == 1.0
    checker = np.where((np.indices((16, 16)).sum(0) % 2) == 0, 10.0, 90.0)
    e = glcm_energy(checker, mask, 8)
    assert 0.2 < e < 0.5  # four distinct co-occurrence cells, unequally filled
    # only foreground pairs count: masking the right half leaves a uniform left half
    half = np.hstack([np.full((16, 8), 50.0), np.full((16, 8), 90.0)])
    m = np.zeros((16, 16), bool)
    m[:, :8] = True
    assert glcm_energy(half, m, 8) == 1.0


def test_kmeans_merges_noise_into_one_class() -> None:
    rng = np.random.default_rng(0)
    centres, labels = kmeans_1d(rng.normal(10.0, 0.5, 500), 3, merge_tol=4.0)
    assert centres.size == 1 and (labels == 0).all()
    x = np.concatenate([rng.normal(0, 0.5, 300), rng.normal(40, 0.5, 200), rng.normal(80, 0.5, 100)])
    centres, labels = kmeans_1d(x, 3, merge_tol=4.0)
    assert np.allclose(np.sort(centres), [0, 40, 80], atol=0.3)
    assert np.bincount(labels).tolist() == [300, 200, 100]


def test_distance_is_rms_of_normalised_patterns() -> None:
    a = np.zeros(15)
    b = np.zeros(15)
    b[0] = 1.0
    assert abs(descriptor_distance(a, b) - 1 / np.sqrt(15)) < 1e-12
    assert descriptor_distance(a, a) == 0.0
    raw = np.zeros(15)
    raw[4], raw[5] = 30, 50  # segment count capped, a scaled by ab_scale
    n = normalise_descriptors(raw)
    assert n[4] == 1.0 and abs(n[5] - 0.5) < 1e-12


def _kmeans_reference(values, k=3, merge_tol=0.0, bins=256, iterations=50):
    """kmeans_1d as first written (numpy histogram, generic Lloyd loop, searchsorted labels)."""
    x = np.asarray(values, np.float64).ravel()
    lo, hi = float(x.min()), float(x.max())
    if hi - lo <= max(merge_tol, 1e-9):
        return np.array([x.mean()]), np.zeros(x.size, int)
    idx = np.clip(((x - lo) * (bins / (hi - lo))).astype(np.int64), 0, bins - 1)
    hist = np.bincount(idx, minlength=bins).astype(np.float64)
    mids = lo + (np.arange(bins) + 0.5) * ((hi - lo) / bins)
    cdf = np.cumsum(hist) / hist.sum()
    cum_w = np.concatenate(([0.0], np.cumsum(hist))).tolist()
    cum_s = np.concatenate(([0.0], np.cumsum(hist * mids))).tolist()
    width, tol = (hi - lo) / bins, 1e-9 * (hi - lo)
    c = np.interp((np.arange(k) + 0.5) / k, cdf, mids).tolist()
    for _ in range(iterations):
        cut = [0] + [min(bins, max(0, math.floor((0.5 * (p + q) - lo) / width - 0.5) + 1))
                     for p, q in zip(c, c[1:], strict=False)] + [bins]
        new = sorted((cum_s[j] - cum_s[i]) / (cum_w[j] - cum_w[i]) if cum_w[j] > cum_w[i] else old
                     for i, j, old in zip(cut, cut[1:], c, strict=False))
        done = max(abs(p - q) for p, q in zip(new, c, strict=True)) <= tol
        c = new
        if done:
            break

    def nearest(v, centres):
        return np.searchsorted(0.5 * (centres[1:] + centres[:-1]), v)

    centres = np.asarray(c)
    centres = centres[np.bincount(nearest(mids, centres), weights=hist, minlength=k) > 0]
    if merge_tol > 0 and centres.size > 1:
        groups = [[centres[0]]]
        for v in centres[1:]:
            if v - groups[-1][-1] < merge_tol:
                groups[-1].append(v)
            else:
                groups.append([v])
        if len(groups) < centres.size:
            centres = np.array([np.mean(g) for g in groups])
    labels = nearest(x, centres)
    counts = np.bincount(labels, minlength=centres.size)
    sums = np.bincount(labels, weights=x, minlength=centres.size)
    return np.where(counts > 0, sums / np.maximum(counts, 1), centres), labels


def test_kmeans_gives_exactly_what_the_first_version_gave() -> None:
    """The fast kmeans_1d (three classes written out, labels by comparisons) changes no bit."""
    rng = np.random.default_rng(5)
    cases = [rng.normal(0, 1, 50), rng.uniform(0, 1, 3000).astype(np.float32), np.round(rng.normal(5, 3, 999)),
             np.r_[np.zeros(100), np.ones(3)], np.r_[rng.normal(0, 0.1, 400), rng.normal(9, 0.1, 10)],
             rng.integers(0, 4, 700).astype(float), np.linspace(-2, 2, 257)]
    for k in (2, 3, 4):
        for merge in (0.0, 0.05, 4.0):
            for x in cases:
                c, lab = kmeans_1d(x, k, merge)
                rc, rlab = _kmeans_reference(x, k, merge)
                assert c.tobytes() == rc.tobytes() and np.array_equal(lab, rlab)


def test_descriptors_of_converted_images_equal_global_descriptors() -> None:
    rng = np.random.default_rng(2)
    rgb = rng.integers(0, 256, (30, 40, 3)).astype(np.uint8)
    mask = np.zeros((30, 40), bool)
    mask[5:25, 8:30] = True
    hsv, lab = rgb_to_hsv_lab(rgb)
    assert np.array_equal(rgb_to_hsv(rgb), hsv)
    assert global_descriptors(rgb, mask).tobytes() == descriptors_of(hsv, lab, mask).tobytes()
