"""The matching toolkit (matching.py): correlation maps, peaks, rotation, boxes."""

import numpy as np

from sbsc_core.recognition.matching import (
    REFUSE_POINT,
    box_at,
    masked_ncc,
    match_in_rois,
    ncc_map,
    patch_ncc,
    pick_peaks,
    rotate_template,
    rotated_size,
)
from sbsc_core.types import Box


def _blob(h: int = 15, w: int = 9) -> np.ndarray:
    t = np.zeros((h, w), np.float32)
    t[2:-2, 2:-2] = 1.0
    t[3:6, 3:-3] = 2.0  # asymmetric: a mark near the top
    return t


def test_ncc_map_peaks_where_the_template_lies() -> None:
    img = np.random.default_rng(0).normal(0, 0.05, (60, 80)).astype(np.float32)
    t = _blob()
    img[20:35, 40:49] += t
    res = ncc_map(img, t)
    assert res.shape == (60 - 15 + 1, 80 - 9 + 1)
    y, x = np.unravel_index(np.argmax(res), res.shape)
    assert (y, x) == (20, 40) and res[y, x] > 0.95


def test_masked_ncc_ignores_unknown_pixels() -> None:
    t = _blob()
    img = np.zeros((30, 30), np.float32)
    img[5:20, 10:19] = t
    known = np.ones_like(img, bool)
    img[5:12, 10:19] = -5.0  # garbage where unknown
    known[5:12, 10:19] = False
    plain = ncc_map(img, t)[5, 10]
    masked = masked_ncc(img, known, t)[5, 10]
    assert masked > 0.99 > plain


def test_pick_peaks_is_greedy_judged_and_suppresses() -> None:
    corr = np.zeros((20, 20))
    corr[5, 5], corr[5, 6], corr[15, 15] = 0.9, 0.85, 0.8
    peaks = list(pick_peaks(corr, threshold=0.5, max_peaks=5, exclude=(2, 2)))
    assert [(y, x) for _, y, x in peaks] == [(5, 5), (15, 15)]
    refused = list(pick_peaks(corr, threshold=0.5, max_peaks=5, exclude=(0, 0),
                              judge=lambda y, x: REFUSE_POINT if (y, x) == (5, 5) else "accept"))
    assert [(y, x) for _, y, x in refused] == [(5, 6), (15, 15)]


def test_rotate_template_any_angle() -> None:
    t = _blob()
    assert np.array_equal(rotate_template(t, 90), np.rot90(t))
    r = rotate_template(t, 30)
    hh, ww = rotated_size(15, 9, 30)
    assert r.shape == (hh + (hh - 15) % 2, ww + (ww - 9) % 2)
    assert abs(float(r.sum()) - float(t.sum())) < 0.05 * float(t.sum())  # nothing cut off
    back = rotate_template(r, -30)
    oy, ox = (back.shape[0] - 15) // 2, (back.shape[1] - 9) // 2
    assert patch_ncc(back[oy:oy + 15, ox:ox + 9], t) > 0.85


def test_match_in_rois_finds_a_turned_object_with_its_turned_model() -> None:
    t = _blob(21, 13)
    img = np.zeros((80, 80), np.float32)
    rot = rotate_template(t, 37)
    img[20:20 + rot.shape[0], 30:30 + rot.shape[1]] = rot
    centre = (20 + (rot.shape[0] - 1) / 2, 30 + (rot.shape[1] - 1) / 2)
    roi = box_at(centre, rot.shape[0], rot.shape[1])
    upright = match_in_rois(img, t, [roi], threshold=-1.0, pad_px=3, margin_px=4, max_peaks=1)
    turned = match_in_rois(img, rot, [roi], threshold=-1.0, pad_px=3, margin_px=4, max_peaks=1)
    assert turned[0].score > 0.99 > upright[0].score + 0.1
    assert abs(turned[0].row - centre[0]) < 0.5 and abs(turned[0].col - centre[1]) < 0.5


def test_box_at_centres_the_box() -> None:
    assert box_at((10.0, 20.0), 5, 4) == Box(8, 19, 13, 23)
