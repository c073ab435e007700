"""Orthographic occlusion (``sbsc_core.imaging.occlusion``): the wall seen behind a stand-off object."""

from __future__ import annotations

import numpy as np
import pytest

from sbsc_core.imaging.occlusion import front_layers, hide_occluded
from sbsc_core.imaging.orthoimage import build_orthoimage
from sbsc_core.settings import OrthoimageSettings
from sbsc_core.simulate import mesh as M
from sbsc_core.simulate.objects import build_object
from sbsc_core.simulate.realism import CLASS_GLOSS, ScanEffects
from sbsc_core.simulate.scanner import ScannerSettings, scan_mesh
from sbsc_core.types import PointCloud, Wall, WallFrame

PX = 0.005
WALL_H = 2.6


@pytest.fixture(scope="module")
def extinguisher_scan() -> tuple[PointCloud, Wall]:
    """A wall with a bracket-mounted extinguisher (axis 10.5 cm off the wall, u = 1.988, v = 0.9..1.5)
    scanned by the realistic scanner from two stations, as on Scenario I's corridor wall C-S: one
    0.64 m from the wall and 1.1 m to the side (it sees the wall behind the extinguisher through the
    bracket's gap, densely), one 1.4 m off and 1.8 m to the other side."""
    turn = np.array([[-1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])  # object x, y, z -> world -x, z, y
    ext = build_object("fire_extinguisher").glossy(CLASS_GLOSS["fire_extinguisher"]).transformed(turn, (0, 0, 1.2))
    wall = M.quad((2.0, 0.0, 0.0), (-4.0, 0.0, 0.0), (0.0, 0.0, WALL_H), (214, 200, 168))
    scanner = ScannerSettings(angular_step_deg=0.1, elevation_min_deg=-26.0, elevation_max_deg=0.0)
    scan = scan_mesh(M.merge([wall, ext]), [(1.1, 0.64, 1.5), (-1.8, 1.4, 1.5)], scanner, seed=3,
                     effects=ScanEffects())
    frame = WallFrame(np.array([2.0, 0, 0]), np.array([-1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0, 1.0, 0]),
                      4.0, WALL_H)
    return PointCloud(scan.xyz, scan.rgb, np.zeros(3)), Wall("W01", frame, np.arange(len(scan.xyz)))


def _rows(v0: float, v1: float) -> slice:
    return slice(int((WALL_H - v1) / PX), int((WALL_H - v0) / PX))


def _cols(u0: float, u1: float) -> slice:
    return slice(int(u0 / PX), int(u1 / PX))


def test_extinguisher_seen_behind_keeps_its_relief(extinguisher_scan) -> None:
    """The plain per-pixel median drops many pixels of the extinguisher's body to the wall seen
    behind it (the detector then lost it); with the occlusion test the body is solid relief and
    its colour is the body's, while the plain wall, the pixels with data and the object's
    outline are those of the plain median."""
    cloud, wall = extinguisher_scan
    plain = build_orthoimage(cloud, wall, OrthoimageSettings(occlusion_gap_m=None))
    o = build_orthoimage(cloud, wall, OrthoimageSettings())
    body = (_rows(0.95, 1.33), _cols(1.94, 2.04))
    assert (np.nan_to_num(plain.depth[body]) < 0.05).mean() > 0.1  # speckled with wall
    assert (np.nan_to_num(o.depth[body]) < 0.05).mean() < 0.02
    assert np.nanmedian(o.depth[body]) == pytest.approx(0.17, abs=0.015)
    changed = (np.nan_to_num(plain.depth[body]) < 0.05) & (o.depth[body] > 0.1)
    assert changed.sum() > 0.1 * changed.size
    def red(img: np.ndarray, where: np.ndarray) -> float:
        c = img[body][where].astype(int)
        return float((c[:, 0] - c[:, 1] > 60).mean())

    # the changed pixels are as red as the rest of the body (red, a cream label), no longer beige
    body_red = red(plain.colour, ~changed & (plain.depth[body] > 0.1))
    assert red(o.colour, changed) == pytest.approx(body_red, abs=0.15) and red(plain.colour, changed) < 0.1
    away = (_rows(0.95, 1.45), _cols(2.6, 3.5))  # plain wall beside the extinguisher
    assert o.mask.sum() >= plain.mask.sum() - 10  # a few hidden wall pixels without a front: no data
    np.testing.assert_array_equal(o.depth[away], plain.depth[away])
    beside = (_rows(0.95, 1.45), _cols(2.1, 2.4))  # the stations' mixed pixels beside the body
    assert (np.nan_to_num(o.depth[beside]) > 0.01).mean() <= (np.nan_to_num(plain.depth[beside]) > 0.01).mean() + 0.005


def test_hide_occluded_needs_a_coherent_front() -> None:
    """A wall pixel inside a surface 15 cm out takes its own front layer, or has no data without
    one; a stray front point on the plain wall and the pixel just outside a straight edge keep
    their value."""
    h, w = 7, 9
    pixel, depth = [], []
    for r in range(h):
        for c in range(w):
            inside = 2 <= r <= 4 and 2 <= c <= 5
            k = r * w + c
            if inside and (r, c) == (3, 3):  # seen behind mostly: 4 wall points, 1 front point
                pixel += [k] * 5
                depth += [0.0, 0.001, -0.001, 0.0, 0.15]
            elif inside and (r, c) == (3, 4):  # the wall alone was seen here
                pixel += [k] * 3
                depth += [0.0, 0.001, -0.001]
            elif inside:
                pixel += [k] * 3
                depth += [0.15, 0.151, 0.149]
            elif (r, c) == (5, 7):  # a mixed pixel's stray point on the plain wall
                pixel += [k] * 4
                depth += [0.0, 0.001, 0.0, 0.08]
            else:
                pixel += [k] * 3
                depth += [0.0, 0.001, -0.001]
    pixel, depth = np.array(pixel), np.array(depth, np.float32)
    rgb = np.where((depth > 0.05)[:, None], [[200, 20, 20]], [[210, 200, 170]]).astype(np.uint8)
    from sbsc_core.imaging.orthoimage import rasterize_median

    d, c, m = rasterize_median(pixel, depth, rgb, (h, w), depth_range=(-0.06, 0.3), quantum=0.0001)
    assert d[3, 3] == pytest.approx(0.0, abs=1e-3)  # the plain median: the wall
    front = front_layers(pixel, depth, rgb, (h, w), gap_m=0.02, far_m=0.25)
    fd = front.depth
    assert np.isfinite(fd).sum() == 2 and fd[3, 3] == pytest.approx(0.15, abs=1e-4)
    assert front.points[3, 3] == 5 and front.front_points[3, 3] == 1 and front.front_points[2, 2] == 0
    d2, c2, m2 = hide_occluded(d, c, m, front, gap_m=0.02)
    assert d2[3, 3] == pytest.approx(0.15, abs=1e-4) and tuple(c2[3, 3]) == (200, 20, 20)
    assert not m2[3, 4] and np.isnan(d2[3, 4])  # hidden wall: no data (a sampling gap to fill)
    assert d2[5, 7] == d[5, 7] and m2.sum() == m.sum() - 1
    assert np.array_equal(d2[1], d[1]) and np.array_equal(d2[:, 6], d[:, 6])  # outside the edges
    assert fd[5, 7] == pytest.approx(0.08, abs=1e-4)  # a front, but no coherent one
    far = front_layers(pixel, depth, rgb, (h, w), gap_m=0.02, far_m=0.05)
    assert np.isnan(far.depth).all()  # beyond far_m: furniture, never a front


def test_occlusion_is_a_setting() -> None:
    """On by default (2 cm); a settings file turns it off with null, or sets another gap; the
    per-pixel layers (None by default) can be set from a file too."""
    from sbsc_core.settings import DetectionSettings

    assert DetectionSettings().orthoimage.occlusion_gap_m == 0.02
    s = DetectionSettings.from_dict({"orthoimage": {"occlusion_gap_m": None, "layer_gap_m": 0.02}})
    assert s.orthoimage.occlusion_gap_m is None and s.orthoimage.layer_gap_m == 0.02
    assert DetectionSettings.from_dict({"orthoimage": {"occlusion_gap_m": 0.03}}).orthoimage.occlusion_gap_m == 0.03
    with pytest.raises(Exception, match="occlusion_gap_m"):
        DetectionSettings.from_dict({"orthoimage": {"occlusion_gap_m": "off"}})


def test_front_layers_of_record_fields_as_of_arrays() -> None:
    """The depths and colours of a partition's records (strided fields of one structured array,
    as :func:`~sbsc_core.imaging.partition.folder_records` returns them) give exactly the front
    layers of the same values in contiguous arrays."""
    rng = np.random.default_rng(7)
    n, shape = 20000, (40, 50)
    rec = np.empty(n, np.dtype([("pixel", "<i4"), ("depth", "<f4"), ("rgb", "u1", 3)]))
    rec["pixel"] = rng.integers(0, shape[0] * shape[1], n)
    rec["depth"] = np.where(rng.random(n) < 0.3, 0.05, 0.0) + rng.normal(0, 0.002, n)  # two layers in many pixels
    rec["rgb"] = rng.integers(0, 256, (n, 3))
    assert not rec["depth"].flags.c_contiguous
    pixel = rec["pixel"].astype(np.int64)
    got = front_layers(pixel, rec["depth"], rec["rgb"], shape, gap_m=0.02, far_m=0.25)
    want = front_layers(pixel, rec["depth"].copy(), rec["rgb"].copy(), shape, gap_m=0.02, far_m=0.25)
    assert np.isfinite(want.depth).sum() > 100
    for a, b in zip((got.depth, got.colour, got.points, got.front_points),
                    (want.depth, want.colour, want.points, want.front_points), strict=True):
        np.testing.assert_array_equal(a, b)
