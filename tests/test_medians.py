"""medians.median: np.median's bits, by a faster route."""

import numpy as np

from sbsc_core.recognition.medians import median


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_median_has_the_bits_of_np_median() -> None:
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 7, 8, 100, 1001, 4096, 100_001):
        for dtype in (np.float32, np.float64):
            x = rng.normal(0.0, 0.01, n).astype(dtype)
            assert _same(median(x), np.median(x))
            assert _same(median(np.abs(x - median(x))), np.median(np.abs(x - np.median(x))))
            q = np.round(x * 300).astype(dtype)  # many ties
            assert _same(median(q), np.median(q))
            y = rng.normal(5.0, 3.0, (n, 3)).astype(dtype)
            assert _same(median(y, axis=0), np.median(y, axis=0))


def test_median_falls_back_to_np_median() -> None:
    x = np.array([1.0, np.nan, 3.0, 2.0], np.float32)
    assert np.isnan(median(x)) and np.isnan(np.median(x))
    ints = np.array([1, 2, 3, 4])
    assert _same(median(ints), np.median(ints))
    m = np.arange(12.0).reshape(3, 4)
    assert _same(median(m, axis=1), np.median(m, axis=1))
    assert _same(median(np.zeros((2, 2, 2)), axis=0), np.median(np.zeros((2, 2, 2)), axis=0))
