"""The scan's level of detail: at most max_points, recentred, cached beside the project."""

from __future__ import annotations

import numpy as np
import pytest

import app.viewer.lod as lod_mod
from app.viewer.lod import downsample, scan_lod, stream_downsample
from sbsc_core.io.ply import write_ply
from sbsc_core.io.scan_source import ScanChunk


def _room_points(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A 10 x 8 x 3 m box: floor, ceiling and four walls, densely and unevenly sampled."""
    face = rng.integers(0, 6, n)
    a, b = rng.random(n), rng.random(n)
    xyz = np.empty((n, 3))
    xyz[:, 0], xyz[:, 1], xyz[:, 2] = a * 10, b * 8, rng.random(n) * 3
    xyz[face == 0, 2], xyz[face == 1, 2] = 0.0, 3.0
    xyz[face == 2, 1], xyz[face == 3, 1] = 0.0, 8.0
    xyz[face == 4, 0], xyz[face == 5, 0] = 0.0, 10.0
    rgb = (rng.random((n, 3)) * 255).astype(np.uint8)
    return xyz, rgb


def test_downsample_keeps_at_most_max_points_spread_evenly():
    rng = np.random.default_rng(1)
    xyz, rgb = _room_points(300_000, rng)
    xyz[:100_000, 2] = 0.0  # a dense patch near a scanner station on the floor
    xyz[:100_000, :2] *= 0.1
    out, col, voxel = downsample(xyz.astype(np.float32), rgb, 40_000)
    assert 15_000 < len(out) <= 40_000 and voxel > 0
    assert out.dtype == np.float32 and col.dtype == np.uint8 and col.shape == out.shape
    # the dense patch no longer dominates: its share falls from 1/3 to its share of the area
    patch = (out[:, 0] < 1.0) & (out[:, 1] < 0.8) & (out[:, 2] < 0.01)
    assert patch.mean() < 0.05
    small, _, v0 = downsample(xyz[:1000].astype(np.float32), rgb[:1000], 40_000)
    assert len(small) == 1000 and v0 == 0.0


def test_scan_lod_recentres_and_caches(tmp_path, monkeypatch):
    rng = np.random.default_rng(2)
    xyz, rgb = _room_points(60_000, rng)
    xyz += [712_345.0, 4_321_000.0, 250.0]  # projected coordinates, as real scans have
    scan = tmp_path / "scan.ply"
    write_ply(scan, xyz, rgb, double=True)
    lod = scan_lod([scan], max_points=10_000, cache_dir=tmp_path / "cache", overview_points=3_000)
    assert len(lod) <= 10_000 and lod.source_points == 60_000
    assert 1_000 < len(lod.overview) <= 3_000 and lod.overview.voxel_m > lod.voxel_m
    world = lod.xyz.astype(np.float64) + lod.centre
    assert np.allclose(world.min(axis=0), xyz.min(axis=0), atol=lod.voxel_m)
    assert np.abs(lod.xyz).max() < 6.0  # recentred on the bounding box
    assert list((tmp_path / "cache").glob("viewer_lod_*.npz"))

    def no_reading(*_args, **_kw):
        raise AssertionError("the cache should have been used")

    monkeypatch.setattr(lod_mod, "iter_scan", no_reading)
    again = scan_lod([scan], max_points=10_000, cache_dir=tmp_path / "cache", overview_points=3_000)
    assert np.array_equal(again.xyz, lod.xyz) and np.array_equal(again.centre, lod.centre)
    assert np.array_equal(again.overview.xyz, lod.overview.xyz)
    with pytest.raises(AssertionError):  # another level of detail is another cache entry
        scan_lod([scan], max_points=5_000, cache_dir=tmp_path / "cache")


def test_stream_downsample_never_holds_the_whole_scan(monkeypatch):
    """A scan of 40 chunks: at most keep_factor x max_points points kept plus one chunk, and
    the result spreads over the whole floor like a downsampling of the whole cloud."""
    rng = np.random.default_rng(3)
    xyz, rgb = _room_points(400_000, rng)
    order = np.argsort(xyz[:, 0])  # a scan sweeps the floor: chunks cover different parts
    xyz, rgb = xyz[order].astype(np.float32), rgb[order]
    origin = np.array([100.0, 200.0, 0.0])
    chunks = (ScanChunk(xyz[i:i + 10_000], rgb[i:i + 10_000], origin, i) for i in range(0, 400_000, 10_000))
    sizes: list[int] = []
    watched = {}
    for name in ("_grid_down",):
        real = getattr(lod_mod, name)
        watched[name] = lambda p, c, voxel, real=real: sizes.append(len(p)) or real(p, c, voxel)
        monkeypatch.setattr(lod_mod, name, watched[name])
    out, col, voxel, n, org = stream_downsample(chunks, 20_000, keep_factor=2)
    assert n == 400_000 and np.array_equal(org, origin) and voxel > 0
    assert 8_000 < len(out) <= 20_000 and col.shape == out.shape
    assert max(sizes) <= 2 * 20_000 + 10_000  # never the 400 000 points at once
    assert np.allclose(out.min(axis=0), xyz.min(axis=0), atol=2 * voxel)
    assert np.allclose(out.max(axis=0), xyz.max(axis=0), atol=2 * voxel)
    # spread over the floor as a downsampling of the whole cloud at once is (the end bands
    # also hold the walls at x = 0 and x = 10, whose share depends on where the voxels fall)
    whole, _, _ = downsample(xyz, rgb, 20_000)
    share = np.histogram(out[:, 0], bins=10, range=(0, 10))[0] / len(out)
    ref = np.histogram(whole[:, 0], bins=10, range=(0, 10))[0] / len(whole)
    assert np.abs(share - ref)[1:-1].max() < 0.01 and np.abs(share - ref).max() < 0.06, (share, ref)
