"""The partition pass: the walls' points are assigned chunk by chunk, the orthoimage from a
wall's partition is the one built from its points in memory, and the parts of a file can
be processed in any split and order."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sbsc_core.imaging import partition
from sbsc_core.imaging.orthoimage import build_orthoimage
from sbsc_core.imaging.partition import (
    SampleBuffer,
    WallIndex,
    assign_chunk,
    partition_part,
    plan_parts,
    sample_cloud,
    sample_part,
    sample_step,
    scan_origin,
    wall_orthoimage,
)
from sbsc_core.io.ply import write_ply
from sbsc_core.scene.segmentation import segment_floor_ceiling_walls
from sbsc_core.settings import DetectionSettings
from sbsc_core.types import Wall
from tests.synthetic_rooms import Block, Hole, Room, make_scene

ORIGIN = (500_000.0, 4_000_000.0, 100.0)


@pytest.fixture(scope="module")
def scene():
    """Two rooms sharing a partition (walls meeting at T-junctions and corners)."""
    a = Room([(0, 0), (4, 0), (4, 3), (0, 3)], {0: [Block(1.0, 1.3, 0.3, 0.5, 0.02, (250, 250, 250))], 2: [Hole("door", 1, 1.9, 0, 2.0)]})
    b = Room([(4.2, 0), (7, 0), (7, 3), (4.2, 3)], {1: [Block(1.0, 1.2, 1.0, 1.2, 0.03, (200, 30, 30))]})
    cloud, _ = make_scene([a, b], spacing=0.02, noise_m=0.002, see_through_m=0.0, origin=ORIGIN)
    seg = segment_floor_ceiling_walls(cloud)
    return cloud, seg


def _assigned(xyz, index, n_walls):
    out = [[] for _ in range(n_walls)]
    for w, idx, _uvd in assign_chunk(xyz, index):
        out[w].append(idx)
    return [np.sort(np.concatenate(o)) if o else np.zeros(0, np.int64) for o in out]


def test_assignment_is_the_same_chunk_by_chunk(scene):
    cloud, seg = scene
    s = DetectionSettings()
    index = WallIndex.build(seg.walls, cloud.origin, s.segmentation)
    whole = _assigned(cloud.xyz, index, len(seg.walls))
    cuts = [0, 777, 50_000, 123_457, len(cloud)]
    parts = [_assigned(cloud.xyz[a:b], index, len(seg.walls)) for a, b in zip(cuts, cuts[1:], strict=False)]
    for w in range(len(seg.walls)):
        joined = np.concatenate([p[w] + a for p, a in zip(parts, cuts, strict=False)])
        np.testing.assert_array_equal(joined, whole[w])
        assert len(whole[w]) > 1000
    # every point goes to at most one wall, and it lies in the wall's slab
    every = np.concatenate(whole)
    assert len(every) == len(np.unique(every))


def test_a_points_nearest_plane_wins_over_a_brute_force_check(scene):
    cloud, seg = scene
    s = DetectionSettings().segmentation
    index = WallIndex.build(seg.walls, cloud.origin, s)
    got = _assigned(cloud.xyz, index, len(seg.walls))
    owner = np.full(len(cloud), -1)
    for w, idx in enumerate(got):
        owner[idx] = w
    # brute force over every wall for a sample of points
    pick = np.random.default_rng(0).choice(len(cloud), 20_000, replace=False)
    from sbsc_core.imaging.orthoimage import wall_coordinates

    best = np.full(len(pick), np.inf)
    want = np.full(len(pick), -1)
    for w, wall in enumerate(seg.walls):
        uvd = wall_coordinates(cloud.xyz[pick], wall.frame, cloud.origin)
        ok = partition._inside(uvd, wall.frame, index) & (np.abs(uvd[:, 2]) < best)
        best[ok] = np.abs(uvd[ok, 2])
        want[ok] = w
    np.testing.assert_array_equal(owner[pick], want)


@pytest.mark.slow
@pytest.mark.parametrize("band_pixels", [1 << 19, 3000])
def test_partition_orthoimage_equals_the_in_memory_one(scene, tmp_path, monkeypatch, band_pixels):
    monkeypatch.setattr(partition, "BAND_PIXELS", band_pixels)  # 3000: a few rows a band, many bands
    cloud, seg = scene
    s = DetectionSettings()
    path = tmp_path / "room.ply"
    write_ply(path, cloud.world(), cloud.rgb, double=True)
    parts, total = plan_parts([path], part_points=60_000)
    assert len(parts) > 3 and total == len(cloud)
    origin = scan_origin(path)
    step = sample_step(total, s)
    samples = [sample_part(p, origin, step, str(tmp_path)) for p in parts]
    assert sum(x.points for x in samples) == len(cloud)
    index = WallIndex.build(seg.walls, origin, s.segmentation)
    for p, smp in reversed(list(zip(parts, samples, strict=True))):  # any order
        partition_part(p, origin, index, str(tmp_path), points=smp.points, spilled=smp.spilled,
                       ortho=s.orthoimage)
    # the same walls, their points assigned in memory
    local = cloud.xyz.astype(np.float64) + (cloud.origin - origin)
    mine = _assigned(local.astype(np.float32), index, len(seg.walls))
    from sbsc_core.types import PointCloud

    moved = PointCloud(local.astype(np.float32), cloud.rgb, origin)
    bands = [len(list((tmp_path / f"wall-{w:04d}").glob("b*"))) for w in range(len(seg.walls))]
    if band_pixels < 1e4:
        assert min(bands) > 5
    for w, wall in enumerate(seg.walls):
        a = wall_orthoimage(tmp_path, w, wall.id, wall.frame, s.orthoimage)
        b = build_orthoimage(moved, Wall(wall.id, wall.frame, mine[w]), s.orthoimage)
        np.testing.assert_array_equal(a.colour, b.colour)
        np.testing.assert_array_equal(a.mask, b.mask)
        np.testing.assert_array_equal(np.nan_to_num(a.depth, nan=9), np.nan_to_num(b.depth, nan=9))


def test_spilled_formats_are_decoded_once(scene, tmp_path):
    cloud, _ = scene
    path = tmp_path / "room.xyz"
    sub = slice(0, 20_000)
    np.savetxt(path, np.column_stack([cloud.world()[sub], cloud.rgb[sub]]), fmt="%.4f %.4f %.4f %d %d %d")
    parts, _ = plan_parts([path])
    assert len(parts) == 1
    smp = sample_part(parts[0], np.asarray(ORIGIN), 7, str(tmp_path))
    assert smp.spilled and smp.points == 20_000 and len(smp.xyz) == len(range(0, 20_000, 7))
    spill = list(Path(tmp_path).glob("spill-*"))
    assert sorted(p.suffix for p in spill) == [".rgb", ".xyz"]
    assert (tmp_path / f"spill-{parts[0].key}.xyz").stat().st_size == 20_000 * 12


@pytest.mark.slow
def test_pool_workers_start_with_the_worker_environment(monkeypatch):
    from sbsc_core.pipeline import executors, worker_env

    monkeypatch.setattr(executors, "worker_environment", lambda: {"SBSC_TEST_WORKER_MARK": "set"})
    pool = executors.wall_pool(DetectionSettings(workers=2))
    try:
        assert [pool.submit(worker_env._environ, "SBSC_TEST_WORKER_MARK").result() for _ in range(4)] == ["set"] * 4
    finally:
        pool.shutdown()
    import os

    assert "SBSC_TEST_WORKER_MARK" not in os.environ


def test_numpy_environment_only_on_amd_zen4(monkeypatch):
    from sbsc_core.pipeline import cpu_features

    zen4 = "vendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\nflags\t\t: fpu avx2 avx512f avx512dq\n"
    zen3 = zen4.replace(" avx512f avx512dq", "")
    intel = zen4.replace("AuthenticAMD", "GenuineIntel").replace(": 25", ": 6")
    assert cpu_features.is_amd_zen4(zen4)
    assert not cpu_features.is_amd_zen4(zen3) and not cpu_features.is_amd_zen4(intel)
    monkeypatch.delenv("NPY_DISABLE_CPU_FEATURES", raising=False)
    monkeypatch.setattr(cpu_features, "is_amd_zen4", lambda: False)
    assert cpu_features.numpy_environment() == {}
    monkeypatch.setattr(cpu_features, "is_amd_zen4", lambda: True)
    assert "X86_V4" in cpu_features.numpy_environment()["NPY_DISABLE_CPU_FEATURES"]
    assert not cpu_features.prefer_fast_sort()  # numpy is imported here: too late, nothing set
    monkeypatch.setenv("NPY_DISABLE_CPU_FEATURES", "")  # the user's own choice wins
    assert cpu_features.numpy_environment() == {}


@pytest.mark.parametrize("step", [1, 3, 7])
def test_sample_buffer_gathers_what_sample_cloud_concatenates(scene, tmp_path, step):
    """Samples copied into place as they arrive (in any order) give sample_cloud's cloud; a
    sample of another size falls back to the concatenation."""
    cloud, _ = scene
    path = tmp_path / "room.ply"
    write_ply(path, cloud.world(), cloud.rgb, double=True)
    parts, _ = plan_parts([path], part_points=50_000)
    origin = scan_origin(path)
    samples = [sample_part(p, origin, step, str(tmp_path)) for p in parts]
    for limit in (10**9, len(cloud) // (2 * step)):  # without and with the final thinning
        want = sample_cloud(samples, origin, ["room"], limit)
        buf = SampleBuffer(parts, step)
        got = [None] * len(parts)
        for k in reversed(range(len(parts))):
            got[k] = buf.add(k, samples[k])
        assert not any(len(g.xyz) for g in got)
        c = buf.cloud(got, origin, ["room"], limit)
        assert c.xyz.tobytes() == want.xyz.tobytes() and c.rgb.tobytes() == want.rgb.tobytes()
    short = list(samples)
    short[1] = partition.PartSample(samples[1].xyz[:-1], samples[1].rgb[:-1], samples[1].points, False)
    buf = SampleBuffer(parts, step)
    got = [buf.add(k, smp) for k, smp in enumerate(short)]
    c = buf.cloud(got, origin, ["room"], 10**9)
    want = sample_cloud(short, origin, ["room"], 10**9)
    assert c.xyz.tobytes() == want.xyz.tobytes() and c.rgb.tobytes() == want.rgb.tobytes()
