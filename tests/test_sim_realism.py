"""The realistic scanner (``sbsc_core.simulate.realism``): each effect's physical behaviour."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sbsc_core.simulate import mesh as M
from sbsc_core.simulate.realism import (
    ScanEffects,
    camera_response,
    range_sigma,
    return_probability,
    station_camera,
    station_pose_error,
)
from sbsc_core.simulate.scanner import ScannerSettings, scan_mesh

QUIET = ScannerSettings(angular_step_deg=0.5, range_sigma_m=0.0, colour_sigma=0.0, gain_sigma=0.0,
                        tint_sigma=0.0, offset_sigma=0.0, gradient_amplitude=0.0, drop_fraction=0.0,
                        grazing_cos=0.0, min_range_m=0.0)
OFF = ScanEffects.none()


def _plane_x(x: float, colour=(200, 200, 200), half: float = 20.0) -> M.ColouredMesh:
    return M.quad((x, half, -half), (0, -2 * half, 0), (0, 0, 2 * half), colour)


def _range_error(scan, x: float) -> tuple[np.ndarray, np.ndarray]:
    d = scan.xyz.astype(np.float64)
    r = np.linalg.norm(d, axis=1)
    cos_inc = d[:, 0] / r
    return r - x / cos_inc, cos_inc


def test_no_effects_gives_the_plain_scanner() -> None:
    plain = scan_mesh(_plane_x(3.0), [(0, 0, 0)], QUIET.replace(range_sigma_m=0.002), seed=1)
    off = scan_mesh(_plane_x(3.0), [(0, 0, 0)], QUIET.replace(range_sigma_m=0.002), seed=1, effects=None)
    assert np.array_equal(plain.xyz, off.xyz) and np.array_equal(plain.rgb, off.rgb)


def test_range_noise_grows_with_range_and_incidence() -> None:
    e = ScanEffects(range_noise_floor_m=0.0005, range_noise_10m_m=0.0015, reference_reflectance=0.5)
    # the model: 1.58 mm at 10 m, normal incidence, reference reflectance; more when oblique
    assert range_sigma(np.array([10.0]), np.array([1.0]), np.array([0.5]), e)[0] == pytest.approx(
        math.hypot(0.0005, 0.0015), rel=1e-4)
    only_noise = ScanEffects(**{**OFF.__dict__, "range_noise_floor_m": 0.0005, "range_noise_10m_m": 0.0015})
    near = scan_mesh(_plane_x(2.0), [(0, 0, 0)], QUIET, seed=2, effects=only_noise)
    far = scan_mesh(_plane_x(10.0), [(0, 0, 0)], QUIET, seed=2, effects=only_noise)
    err_n, cos_n = _range_error(near, 2.0)
    err_f, cos_f = _range_error(far, 10.0)
    head_on_n, head_on_f = err_n[cos_n > 0.97], err_f[cos_f > 0.97]
    assert head_on_f.std() > 1.8 * head_on_n.std()
    # measured noise at 10 m head-on: the published figure (~1.6 mm for the reference reflectance)
    rho = 0.58  # linear luminance of sRGB (200, 200, 200)
    assert head_on_f.std() == pytest.approx(math.hypot(0.0005, 0.0015) * math.sqrt(0.5 / rho), rel=0.15)
    oblique = err_n[(cos_n > 0.3) & (cos_n < 0.45)]
    assert oblique.std() > 2.0 * head_on_n.std()


def test_mixed_pixels_lie_between_fore_and_background() -> None:
    fore = M.box((0.02, 1.0, 1.0), (250, 250, 250), (2.0, 0.0, 0.0))  # front face at x = 1.99
    mesh = M.merge([_plane_x(3.0), fore])
    e = ScanEffects(**{**OFF.__dict__, "beam_exit_diameter_m": 0.0035, "beam_divergence_rad": 0.0003,
                       "mixed_min_jump_m": 0.005})
    plain = scan_mesh(mesh, [(0, 0, 0)], QUIET.replace(angular_step_deg=0.2), seed=4)
    real = scan_mesh(mesh, [(0, 0, 0)], QUIET.replace(angular_step_deg=0.2), seed=4, effects=e)
    assert len(plain) == len(real)
    x_plain, x_real = plain.xyz[:, 0], real.xyz[:, 0]
    assert not ((x_plain > 2.02) & (x_plain < 2.98)).any()  # a perfect scanner: two surfaces only
    between = (x_real > 2.02) & (x_real < 2.98)
    assert between.sum() > 20  # the edge of the box (~ 4 x 290 rays) gives mixed pixels
    # they lie on the rays of the box's silhouette, between 1.99 and 3.0 m
    yz = real.xyz[between][:, 1:] / real.xyz[between][:, :1]
    assert np.all(np.abs(np.abs(yz).max(axis=1) - 0.5 / 1.99) < 0.02)


def test_dropouts_on_dark_and_glossy_surfaces() -> None:
    e = ScanEffects()
    r, c = np.array([8.0, 8.0, 8.0, 8.0]), np.array([0.5, 0.5, 0.5, 1.0])
    p = return_probability(r, c, np.array([0.7, 0.005, 0.7, 0.7]), np.array([0.0, 0.0, 0.9, 0.9]), e)
    assert p[0] > 0.99 and p[1] < 0.7 and p[2] < p[0] - 0.15 and p[3] > p[2]
    only = ScanEffects(**{**OFF.__dict__, "min_reflectance": 0.004})
    white = scan_mesh(_plane_x(8.0, (230, 230, 230)), [(0, 0, 0)], QUIET, seed=5, effects=only)
    black = scan_mesh(_plane_x(8.0, (18, 18, 18)), [(0, 0, 0)], QUIET, seed=5, effects=only)
    assert len(black) < 0.8 * len(white)


def test_registration_error_moves_a_station_by_the_set_amount() -> None:
    e = ScanEffects(**{**OFF.__dict__, "registration_translation_m": 0.003, "registration_rotation_deg": 0.01})
    stations = [(0.0, 0.0, 0.0), (0.5, 0.2, 0.0)]
    plain = scan_mesh(_plane_x(4.0), stations, QUIET, seed=6, keep_station=True)
    moved = scan_mesh(_plane_x(4.0), stations, QUIET, seed=6, keep_station=True, effects=e)
    assert np.array_equal(plain.xyz[plain.station == 0], moved.xyz[moved.station == 0])  # the reference
    rot, shift = station_pose_error(6, 1, e)
    assert moved.pose_errors is not None and np.allclose(moved.pose_errors[1][1], shift)
    o = np.array(stations[1])
    p = plain.xyz[plain.station == 1].astype(np.float64)
    expect = o + (p - o) @ rot.T + shift
    assert np.abs(moved.xyz[moved.station == 1] - expect).max() < 2e-5
    assert 0.0005 < np.linalg.norm(shift) < 0.02
    angle = math.degrees(math.acos(min(1.0, (np.trace(rot) - 1) / 2)))
    assert 0.0 < angle < 0.1


def test_exposure_and_white_balance_per_station() -> None:
    e = ScanEffects()
    cams = [station_camera(3, k, e) for k in range(6)]
    assert len({round(c[0], 6) for c in cams}) == 6  # each station its own exposure
    grey = np.full((1, 3), 128, np.uint8)
    out = np.array([camera_response(grey, g, wb)[0] for g, wb in cams])
    assert np.ptp(out[:, 0] - out[:, 2]) > 3  # the white balance tints each panorama differently
    brighter = camera_response(grey, 2.0, np.ones(3, np.float32))[0]
    assert brighter[0] == pytest.approx(255 * (2 * (128 / 255) ** 2.2) ** (1 / 2.2), rel=0.03)  # +1 EV


def test_highlights_on_glossy_surfaces_only() -> None:
    e = ScanEffects(**{**OFF.__dict__, "highlight_strength": 0.6, "highlight_exponent": 30.0,
                       "light_height_m": 1.0})
    matte = _plane_x(2.0, (120, 120, 120))
    glossy = matte.glossy(1.0)
    a = scan_mesh(matte, [(0, 0, 0)], QUIET, seed=7, effects=e)
    b = scan_mesh(glossy, [(0, 0, 0)], QUIET, seed=7, effects=e)
    assert a.rgb.max() <= 121
    # the mirror point of the light (1 m up) on the plane is at z = 0.5: bright there, not elsewhere
    near = np.linalg.norm(b.xyz[:, 1:] - [0.0, 0.5], axis=1) < 0.1
    far = np.linalg.norm(b.xyz[:, 1:] - [0.0, 0.5], axis=1) > 1.5
    assert b.rgb[near, 0].mean() > 200 and b.rgb[far, 0].mean() < 125
