"""Fine registration of stations given as several files (sbsc_core.scene.registration)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sbsc_core.imaging.partition import (
    SampleBuffer,
    ScanPart,
    apply_pose,
    part_chunks,
    plan_parts,
    sample_part,
)
from sbsc_core.scene.registration import refine_registration
from sbsc_core.settings import RegistrationSettings

from .stations import _disagreement_mm, _motion, _stations


def test_refine_registration_removes_the_stations_disagreement():
    rng = np.random.default_rng(3)
    errors = [np.eye(4)] + [_motion(rng, 0.003, 0.01) for _ in range(3)]
    before = _disagreement_mm([np.eye(4)] * 4, errors)
    reg = refine_registration(_stations(4, 60_000, errors), settings=RegistrationSettings())
    after = _disagreement_mm(reg.poses, errors)
    assert before > 4.0
    assert after < 0.5, (before, after)
    assert reg.groups == [[0, 1, 2, 3]] and not reg.kept_as_given
    assert len(reg.edges) == 6
    # the given registration is trusted on average: the common motion left is no larger than the errors' mean
    common = reg.poses[0] @ errors[0]
    mean_shift = np.linalg.norm(np.mean([E[:3, 3] - errors[0][:3, 3] for E in errors], axis=0))
    assert np.linalg.norm(common[:3, 3]) < mean_shift + 0.002


def test_stations_that_already_agree_are_kept_as_registered():
    """Stations 0.3 mm apart agree within the refinement's own precision: nothing moves (the
    given registration is as good), while the same stations are moved with the gate off."""
    from dataclasses import replace

    rng = np.random.default_rng(11)
    errors = [np.eye(4)] + [_motion(rng, 0.0003, 0.0005) for _ in range(2)]
    clouds = _stations(12, 40_000, errors)
    reg = refine_registration(clouds, settings=RegistrationSettings())
    assert all(np.array_equal(P, np.eye(4)) for P in reg.poses)
    assert reg.kept_as_given == [0, 1, 2] and len(reg.edges) == 3
    free = refine_registration(clouds, settings=replace(RegistrationSettings(), min_disagreement_m=0.0))
    assert not free.kept_as_given and any(not np.array_equal(P, np.eye(4)) for P in free.poses)


def test_stations_that_do_not_overlap_stay_as_given():
    rng = np.random.default_rng(5)
    errors = [np.eye(4), _motion(rng, 0.003, 0.01)]
    clouds = _stations(6, 30_000, errors)
    clouds[1] = clouds[1] + np.float32([20.0, 0, 0])  # another building, 20 m away
    reg = refine_registration(clouds, settings=RegistrationSettings())
    assert reg.edges == [] and reg.groups == [[0], [1]]
    assert all(np.array_equal(P, np.eye(4)) for P in reg.poses)


def test_a_station_far_off_does_not_pull_the_others():
    """The refinement is for millimetres: a station 10 cm off along a room's length (its
    floor and long walls still overlap) neither spoils the others nor is moved far."""
    rng = np.random.default_rng(7)
    errors = [np.eye(4), _motion(rng, 0.002, 0.01), _motion(rng, 0.002, 0.01)]
    errors[2][:3, 3] += [0.10, 0.0, 0.0]
    reg = refine_registration(_stations(8, 40_000, errors), settings=RegistrationSettings())
    assert _disagreement_mm(reg.poses[:2], errors[:2]) < 0.5
    assert np.linalg.norm(reg.poses[2][:3, 3]) < RegistrationSettings().max_shift_m
    assert [r["file"] for r in reg.records(["a.ply", "b.ply", "c.ply"])] == ["a.ply", "b.ply", "c.ply"]


def test_apply_pose_moves_recentred_points():
    T = np.eye(4)
    c, s = math.cos(0.1), math.sin(0.1)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = [0.001, -0.002, 0.003]
    xyz = np.float32([[1, 0, 0], [0, 2, 1]])
    got = apply_pose(xyz, T)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, xyz @ T[:3, :3].T + T[:3, 3], atol=1e-6)
    assert apply_pose(xyz, None) is xyz


def test_a_posed_part_is_moved_wherever_it_is_read(tmp_path):
    from sbsc_core.io.ply import write_ply

    rng = np.random.default_rng(1)
    xyz = rng.random((5000, 3)) * 4
    write_ply(tmp_path / "a.ply", xyz.astype(np.float32), np.full((5000, 3), 200, np.uint8))
    (part,), total = plan_parts([tmp_path / "a.ply"])
    origin = np.zeros(3)
    T = np.eye(4)
    T[:3, 3] = [0.004, 0.0, -0.002]
    moved = part.posed(T)
    assert part.posed(np.eye(4)).pose is None
    raw = np.concatenate([c.xyz for c in part_chunks(part, origin)])
    got = np.concatenate([c.xyz for c in part_chunks(moved, origin)])
    np.testing.assert_allclose(got - raw, np.tile([0.004, 0.0, -0.002], (len(raw), 1)), atol=1e-6)
    smp = sample_part(moved, origin, 7, None)
    np.testing.assert_allclose(smp.xyz, raw[::7] + np.float32([0.004, 0.0, -0.002]), atol=1e-6)
    buf = SampleBuffer([part], 7)
    kept = [buf.add(0, sample_part(part, origin, 7, None))]
    buf.move(0, kept, T)
    cloud = buf.cloud(kept, origin, ["a.ply"], 10**6)
    np.testing.assert_allclose(cloud.xyz, smp.xyz, atol=1e-6)
    assert isinstance(moved, ScanPart) and moved.station == 0 and moved.scan is None


def test_many_stations_keep_fewer_points_each():
    from sbsc_core.scene.registration import station_points, station_sample_points

    s = RegistrationSettings()
    assert station_points(29, s) == s.max_points
    assert station_points(1000, s) == s.max_total_points // 1000
    assert station_points(10**6, s) == 2_000
    assert station_sample_points(29, s) == s.sample_points
    assert station_sample_points(1000, s) == 4 * s.max_total_points // 1000


@pytest.mark.parametrize("enabled", [True, False])
def test_settings_file_turns_registration_off(enabled):
    from sbsc_core.settings import DetectionSettings

    s = DetectionSettings.from_dict({"registration": {"enabled": enabled}})
    assert s.registration.enabled is enabled


def test_each_scan_of_an_e57_file_is_a_station(tmp_path):
    """A survey delivered as one E57 of several scans: each scan is a part and a station,
    read alone, so the scans' registration is refined like separate files'."""
    import pye57

    rng = np.random.default_rng(2)
    errors = [np.eye(4), _motion(rng, 0.003, 0.01)]
    clouds = _stations(9, 20_000, errors)
    with pye57.E57(str(tmp_path / "two.e57"), mode="w") as e:
        for xyz in clouds:
            x = xyz.astype(np.float64)
            rgb = np.full(len(x), 180.0)
            e.write_scan_raw({"cartesianX": x[:, 0].copy(), "cartesianY": x[:, 1].copy(),
                              "cartesianZ": x[:, 2].copy(), "colorRed": rgb, "colorGreen": rgb, "colorBlue": rgb})
    parts, total = plan_parts([tmp_path / "two.e57"])
    assert total == 40_000
    assert [(p.station, p.scan, p.first) for p in parts] == [(0, 0, 0), (1, 1, 20_000)]
    from sbsc_core.imaging.partition import station_names

    assert station_names(parts) == ["two.e57#0", "two.e57#1"]
    origin = np.zeros(3)
    got = [np.concatenate([c.xyz for c in part_chunks(p, origin)]) for p in parts]
    np.testing.assert_allclose(got[1], clouds[1], atol=1e-5)
    reg = refine_registration(got, settings=RegistrationSettings())
    assert _disagreement_mm([np.eye(4)] * 2, errors) > 2.0
    assert _disagreement_mm(reg.poses, errors) < 0.5
