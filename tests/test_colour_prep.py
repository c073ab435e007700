"""Colour preparation (paper, section 3.2): station illumination steps and highlights."""

from __future__ import annotations

import numpy as np

from sbsc_core.imaging.colour_prep import prepare_colour
from sbsc_core.settings import ColourPrepSettings
from tests.synthetic_rooms import Block, Hole, Patch, make_ortho

PX = 0.005
WALL = (205, 200, 190)
STEP_U = 2.33  # the second station lit the wall right of this 20 % darker


def _px(u: float, v: float, height: float = 2.7) -> tuple[int, int]:
    return int((height - v) / PX), int(u / PX)


def _luma(img: np.ndarray) -> np.ndarray:
    return img.astype(np.float64).mean(axis=-1)


def _scene(**kw):
    feats = [Hole("door", 0.5, 1.4, 0.0, 2.1),
             Block(2.6, 3.4, 0.15, 0.75, 0.10, (245, 245, 245)),  # white radiator, in the dark part
             Patch(3.5, 3.71, 1.5, 1.8, (200, 30, 30)),  # red sign, in the dark part
             Block(2.9, 2.98, 1.0, 1.08, 0.012, (240, 240, 235))]  # socket
    return make_ortho(4.0, 2.7, features=feats, gains=[(STEP_U, 4.0, 0.0, 2.7, 0.8)], seed=3, **kw)


def _step(img: np.ndarray) -> float:
    """Mean brightness of plain wall left of the station boundary minus right of it."""
    (ra, ca), (rb, cb) = _px(1.6, 2.5), _px(2.2, 1.0)
    left = _luma(img[ra:rb, ca:cb]).mean()
    (ra, ca), (rb, cb) = _px(2.45, 2.5), _px(3.4, 1.0)
    right = _luma(img[ra:rb, ca:cb]).mean()
    return float(left - right)


def test_station_gain_step_is_removed() -> None:
    o = _scene()
    p = prepare_colour(o, ColourPrepSettings())
    before, after = _step(o.colour), _step(p.colour)
    assert before > 35.0
    assert abs(after) < 2.0
    # right at the boundary too: no wall pixel within 2 cm of it is off by more than 12 levels
    r0, _ = _px(0, 2.5)
    r1, _ = _px(0, 1.0)
    c0, c1 = int((STEP_U - 0.02) / PX), int((STEP_U + 0.02) / PX)
    band = _luma(p.colour[r0:r1, c0:c1])
    ref = _luma(p.colour[r0:r1, int(1.7 / PX):int(2.1 / PX)]).mean()
    assert np.abs(band - ref).max() < 12.0
    # depth and mask are untouched
    assert p.depth is o.depth and p.mask is o.mask
    assert (p.colour[~o.mask] == 0).all()


def test_objects_keep_their_colour_relative_to_the_wall() -> None:
    o = _scene()
    p = prepare_colour(o)
    (r0, c0), (r1, c1) = _px(1.7, 2.0), _px(2.2, 1.5)
    wall = _luma(p.colour[r0:r1, c0:c1]).mean()
    r, c = _px(3.0, 0.45)
    radiator = _luma(p.colour[r - 10:r + 10, c - 10:c + 10]).mean()
    assert radiator - wall > 30.0  # restored from 0.8 x 245 = 196 (darker than the lit wall) to ~ white
    r, c = _px(3.6, 1.65)
    sign = p.colour[r - 5:r + 5, c - 5:c + 5].reshape(-1, 3).mean(axis=0)
    assert sign[0] > 170 and sign[1] < 60 and sign[2] < 60
    r, c = _px(2.94, 1.04)
    assert _luma(p.colour[r - 3:r + 3, c - 3:c + 3]).mean() - wall > 25.0


def test_specular_highlight_is_restored() -> None:
    o = make_ortho(3.0, 2.7, specular=[(1.5, 1.4, 0.15, 90.0)], seed=4)
    p = prepare_colour(o)
    r, c = _px(1.5, 1.4)
    win = (slice(r - 40, r + 40), slice(c - 40, c + 40))
    ref = np.array(WALL, float)
    before = np.abs(o.colour[win].astype(float) - ref).max(axis=-1)
    after = np.abs(p.colour[win].astype(float) - ref).max(axis=-1)
    assert before.max() > 45.0  # clipped at 255 in the middle
    assert np.percentile(after, 99) < 12.0  # thresholding at the wall colour + 25 now works


def test_no_wall_data_leaves_the_colour_alone() -> None:
    o = make_ortho(1.0, 1.0, features=[Hole("window", -1, 2, -1, 2)])
    p = prepare_colour(o)
    assert not p.mask.any() and (p.colour == 0).all()


def test_a_thin_sign_with_a_near_wall_coloured_band_is_not_taken_as_wall() -> None:
    """A flat sign's light text band has nearly the wall's chromaticity, but cells of it hold
    red print: they are not samples of the illumination, and the band keeps its colour."""
    band_rgb = (240, 238, 205)  # rg-chromaticity 0.016 from the wall's: within chroma_tolerance
    v0, v1 = 1.215, 1.335  # band, below a red upper part; red strokes in its upper half
    feats = [Patch(1.0, 1.21, v1, v1 + 0.21, (200, 30, 30)), Patch(1.0, 1.21, v0, v1, band_rgb)]
    feats += [Patch(1.02 + 0.04 * k, 1.035 + 0.04 * k, v0 + 0.05, v0 + 0.09, (200, 30, 30)) for k in range(5)]
    o = make_ortho(2.5, 2.7, features=feats, seed=5)
    p = prepare_colour(o)
    (ra, ca), (rb, cb) = _px(0.3, 2.0), _px(0.7, 1.8)
    wall = p.colour[ra:rb, ca:cb].reshape(-1, 3).mean(axis=0)
    (ra, ca), (rb, cb) = _px(1.02, v0 + 0.035), _px(1.19, v0 + 0.01)  # the band's unprinted lower part
    band = p.colour[ra:rb, ca:cb].reshape(-1, 3).mean(axis=0)
    assert np.abs(band - np.array(band_rgb)).max() < 8.0  # the band keeps its colour ...
    assert np.abs(band - wall).max() > 25.0  # ... and stays apart from the wall
    assert np.abs(wall - np.array(WALL)).max() < 4.0  # the plain wall is still the wall's colour


def test_median_blur_is_scipys_median_filter_per_channel():
    """:func:`_median_blur` gives ``ndimage.median_filter(..., mode="nearest")`` of each
    channel, value for value: on float32 fields with ties and steps (OpenCV, windows 3 and
    5), with NaNs and with a wider window (scipy)."""
    from scipy import ndimage

    from sbsc_core.imaging.colour_prep import _median_blur

    rng = np.random.default_rng(2)
    field = (rng.integers(0, 40, (37, 53, 3)) * 3.7).astype(np.float32)
    field[10:20, 5:30] += np.float32(60.25)  # a station step
    noisy = rng.normal(150, 20, (41, 29, 3)).astype(np.float32)
    with_nan = noisy.copy()
    with_nan[3, 4, 1] = np.nan
    for cells in (field, noisy, with_nan):
        for k in (3, 5, 7):
            want = np.stack([ndimage.median_filter(cells[..., ch], size=k, mode="nearest") for ch in range(3)], axis=-1)
            np.testing.assert_array_equal(_median_blur(cells, k), want)
