"""The virtual terrestrial laser scanner: geometry, noise, occlusion, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sbsc_core.simulate import mesh as M
from sbsc_core.simulate.scanner import ScannerSettings, angular_grid, scan_mesh

QUIET = ScannerSettings(angular_step_deg=0.5, range_sigma_m=0.0, colour_sigma=0.0, gain_sigma=0.0,
                        tint_sigma=0.0, offset_sigma=0.0, gradient_amplitude=0.0, drop_fraction=0.0,
                        grazing_cos=0.0, min_range_m=0.0)


def _plane_x(x: float, colour=(200, 100, 50), half: float = 20.0) -> M.ColouredMesh:
    """A big vertical plane x = const facing -x."""
    return M.quad((x, half, -half), (0, -2 * half, 0), (0, 0, 2 * half), colour)


def test_noise_free_scan_hits_a_plane_at_the_right_distance() -> None:
    scan = scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], QUIET)
    assert len(scan) > 1000
    assert np.abs(scan.xyz[:, 0] - 3.0).max() < 1e-4
    assert (scan.rgb == [200, 100, 50]).all()
    # every point lies on its ray: the elevation is inside the VZ-400 field
    r = np.linalg.norm(scan.xyz, axis=1)
    el = np.degrees(np.arcsin(scan.xyz[:, 2] / r))
    assert el.min() >= -40.0 - 1e-3 and el.max() <= 60.0 + 1e-3
    # and only the half space in front of the scanner is seen
    assert scan.rays == len(angular_grid(QUIET)[0]) * len(angular_grid(QUIET)[1])
    assert 0.4 < len(scan) / scan.rays < 0.55


def test_range_noise_is_gaussian_along_the_ray() -> None:
    s = QUIET.replace(range_sigma_m=0.0025)
    scan = scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], s, seed=3)
    d = scan.xyz.astype(np.float64)
    r = np.linalg.norm(d, axis=1)
    t_true = 3.0 * r / d[:, 0]  # distance along the ray to the plane
    err = r - t_true
    assert abs(err.mean()) < 3e-4
    assert err.std() == pytest.approx(0.0025, rel=0.1)
    # the noise is along the ray: same seed, same rays, the points keep their directions
    clean = scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], QUIET, seed=3).xyz.astype(np.float64)
    assert len(clean) == len(d)
    unit = d / r[:, None]
    assert np.abs(unit - clean / np.linalg.norm(clean, axis=1)[:, None]).max() < 1e-5


def test_occlusion_leaves_a_shadow() -> None:
    blocker = M.box((0.2, 1.0, 1.0), (255, 0, 0), (1.5, 0.0, 0.0))  # between scanner and plane
    mesh = M.merge([_plane_x(3.0), blocker.labelled(0)])
    scan = scan_mesh(mesh, [(0.0, 0.0, 0.0)], QUIET, keep_labels=True)
    on_plane = np.abs(scan.xyz[:, 0] - 3.0) < 1e-3
    # the box (1 m at 1.4 m) shadows |y|, |z| < ~1.07 m on the plane
    shadow = on_plane & (np.abs(scan.xyz[:, 1]) < 0.95) & (np.abs(scan.xyz[:, 2]) < 0.95)
    assert not shadow.any()
    assert (scan.label == 0).sum() > 100
    assert np.all(scan.rgb[scan.label == 0] == [255, 0, 0])
    # a second station beside the box sees behind it
    scan2 = scan_mesh(mesh, [(0.0, 0.0, 0.0), (2.5, 1.5, 0.0)], QUIET)
    seen = (np.abs(scan2.xyz[:, 0] - 3.0) < 1e-3) & (np.abs(scan2.xyz[:, 1]) < 0.5) & (np.abs(scan2.xyz[:, 2]) < 0.5)
    assert seen.sum() > 50


def test_max_and_min_range() -> None:
    far = QUIET.replace(max_range_m=2.5)
    assert len(scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], far)) == 0
    s = QUIET.replace(min_range_m=3.5)
    scan = scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], s)
    assert len(scan) > 0 and np.linalg.norm(scan.xyz, axis=1).min() >= 3.5 - 1e-4


def test_determinism_by_seed() -> None:
    s = ScannerSettings(angular_step_deg=0.5, drop_fraction=0.05)
    mesh = _plane_x(3.0)
    a = scan_mesh(mesh, [(0.0, 0.0, 0.0), (0.5, 0.5, 0.2)], s, seed=7)
    b = scan_mesh(mesh, [(0.0, 0.0, 0.0), (0.5, 0.5, 0.2)], s, seed=7)
    c = scan_mesh(mesh, [(0.0, 0.0, 0.0), (0.5, 0.5, 0.2)], s, seed=8)
    assert np.array_equal(a.xyz, b.xyz) and np.array_equal(a.rgb, b.rgb)
    assert len(a) != len(c) or not np.array_equal(a.xyz, c.xyz)
    # chunking does not change the result
    d = scan_mesh(mesh, [(0.0, 0.0, 0.0), (0.5, 0.5, 0.2)], s.replace(chunk_rays=50_000), seed=7)
    assert np.array_equal(a.xyz, d.xyz) and np.array_equal(a.rgb, d.rgb)


def test_dropped_returns_and_grazing() -> None:
    s = QUIET.replace(drop_fraction=0.1)
    full = len(scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], QUIET))
    dropped = len(scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], s))
    assert dropped / full == pytest.approx(0.9, abs=0.01)
    g = QUIET.replace(grazing_cos=0.5)  # beams more than 60 degrees off the normal are lost
    scan = scan_mesh(_plane_x(3.0), [(0.0, 0.0, 0.0)], g)
    cos_inc = 3.0 / np.linalg.norm(scan.xyz, axis=1)
    assert cos_inc.min() >= 0.5 - 1e-4


def test_per_station_illumination_differs() -> None:
    s = QUIET.replace(gain_sigma=0.05, offset_sigma=3.0)
    mesh = _plane_x(3.0, colour=(150, 150, 150))
    scan = scan_mesh(mesh, [(0.0, 0.0, 0.0), (0.0, 0.3, 0.0), (0.0, -0.3, 0.0)], s, seed=1, keep_station=True)
    means = [scan.rgb[scan.station == k].astype(float).mean(axis=0) for k in range(3)]
    spread = np.ptp([m.mean() for m in means])
    assert spread > 1.0  # the stations' colours do not agree exactly
    # within one station the colour is uniform (no noise configured, no gradient)
    assert scan.rgb[scan.station == 0].std(axis=0).max() < 1e-6
    # colour noise is gaussian with the configured sigma
    n = scan_mesh(mesh, [(0.0, 0.0, 0.0)], QUIET.replace(colour_sigma=3.0), seed=2)
    assert n.rgb.astype(float).std(axis=0).mean() == pytest.approx(3.0, rel=0.1)


def test_angular_grid_matches_the_step() -> None:
    s = ScannerSettings(angular_step_deg=0.1)
    az, el = angular_grid(s)
    assert len(az) == 3600
    assert np.degrees(el[0]) == pytest.approx(-40.0) and np.degrees(el[-1]) <= 60.0 + 1e-9
    assert np.allclose(np.diff(el), math.radians(0.1))


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError):
        ScannerSettings(angular_step_deg=0.0)
    with pytest.raises(ValueError):
        ScannerSettings(range_sigma_m=-1.0)
    with pytest.raises(ValueError):
        ScannerSettings(min_range_m=5.0, max_range_m=1.0)
