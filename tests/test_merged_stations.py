"""Stations of a merged scan file, told by a per-point station property (sbsc_core.io.merged_stations)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.imaging.partition import part_chunks, plan_parts, sample_part, station_names
from sbsc_core.io.merged_stations import station_runs
from sbsc_core.io.ply import write_ply
from sbsc_core.io.scan_source import station_field
from sbsc_core.io.scans import open_scan, read_scan
from sbsc_core.scene.registration import refine_registration
from sbsc_core.settings import RegistrationSettings

from .scan_files import _write_ply_struct
from .stations import _disagreement_mm, _motion, _stations


def _grey(n: int) -> np.ndarray:
    return np.full((n, 3), 170, np.uint8)


def _write_fields(path: Path, xyz: np.ndarray, fields: dict[str, np.ndarray], fmt: str = "binary_little_endian"
                  ) -> None:
    """A PLY of ``xyz``, grey colours and the given extra per-point properties (any numeric type)."""
    dtype = [("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    dtype += [(k, v.dtype.str[1:]) for k, v in fields.items()]
    rec = np.empty(len(xyz), dtype)
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["red"] = rec["green"] = rec["blue"] = 170
    for k, v in fields.items():
        rec[k] = v
    _write_ply_struct(path, rec, fmt)


def _station_points(parts, origin) -> list[np.ndarray]:
    """Every point of each station of the parts, read part by part (as the pipeline reads them)."""
    got: dict[int, list[np.ndarray]] = {}
    for p in parts:
        got.setdefault(p.station, []).extend(c.xyz for c in part_chunks(p, origin))
    return [np.concatenate(got[k]) for k in range(len(got))]


def test_a_merged_file_is_refined_as_the_separate_files(tmp_path):
    """Three stations of a room with known registration errors, merged into one PLY with a
    ``scan_index`` property: its parts are the stations, read alone, and the registration
    they give is the one of the three files."""
    rng = np.random.default_rng(11)
    errors = [np.eye(4)] + [_motion(rng, 0.003, 0.01) for _ in range(2)]
    clouds = _stations(12, 20_000, errors)
    for k, c in enumerate(clouds):
        write_ply(tmp_path / f"s{k}.ply", c, _grey(len(c)))
    merged = np.concatenate(clouds)
    write_ply(tmp_path / "scan.ply", merged, _grey(len(merged)), station=np.repeat([0, 1, 2], 20_000))
    assert open_scan(tmp_path / "scan.ply").station_field == "scan_index"

    parts, total = plan_parts([tmp_path / "scan.ply"], part_points=15_000)  # each run cut in two
    assert total == 60_000
    assert [(p.station, p.start, p.stop, p.first) for p in parts] == [
        (0, 0, 10_000, 0), (0, 10_000, 20_000, 10_000), (1, 20_000, 30_000, 20_000), (1, 30_000, 40_000, 30_000),
        (2, 40_000, 50_000, 40_000), (2, 50_000, 60_000, 50_000)]
    assert len({p.key for p in parts}) == len(parts)
    assert station_names(parts) == ["scan.ply#0", "scan.ply#1", "scan.ply#2"]
    separate, _ = plan_parts([tmp_path / f"s{k}.ply" for k in range(3)])
    origin = np.zeros(3)
    got, want = _station_points(parts, origin), _station_points(separate, origin)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)

    s = RegistrationSettings()
    reg = refine_registration(got, settings=s)
    assert _disagreement_mm([np.eye(4)] * 3, errors) > 3.0
    assert _disagreement_mm(reg.poses, errors) < 0.5
    for P, Q in zip(reg.poses, refine_registration(want, settings=s).poses, strict=True):
        np.testing.assert_allclose(P, Q, atol=1e-9)
    assert [r["file"] for r in reg.records(station_names(parts))] == station_names(parts)
    # a posed part of a merged file is moved wherever it is read (sample and re-read)
    moved = parts[3].posed(reg.poses[1])
    raw = np.concatenate([c.xyz for c in part_chunks(parts[3], origin)])
    smp = sample_part(moved, origin, 7, None)
    np.testing.assert_allclose(smp.xyz, raw[(-parts[3].first) % 7::7] @ reg.poses[1][:3, :3].T.astype(np.float32)
                               + reg.poses[1][:3, 3].astype(np.float32), atol=1e-5)


def test_runs_of_one_value_anywhere_are_one_station(tmp_path):
    """A station may come back later in the file (runs 5, 2, 5): both of its runs are one
    station, named by its value."""
    xyz = np.random.default_rng(1).random((9_000, 3)).astype(np.float32)
    write_ply(tmp_path / "m.ply", xyz, _grey(9_000), station=np.repeat([5, 2, 5], 3_000))
    parts, _ = plan_parts([tmp_path / "m.ply"])
    assert [(p.station, p.start, p.stop) for p in parts] == [(0, 0, 3_000), (1, 3_000, 6_000), (0, 6_000, 9_000)]
    assert station_names(parts) == ["m.ply#5", "m.ply#2"]
    # a merged file after another file: stations and sample indices continue
    write_ply(tmp_path / "a.ply", xyz[:100], _grey(100))
    parts, total = plan_parts([tmp_path / "a.ply", tmp_path / "m.ply"])
    assert total == 9_100 and [p.first for p in parts] == [0, 100, 3_100, 6_100]
    assert station_names(parts) == ["a.ply", "m.ply#5", "m.ply#2"]


@pytest.mark.parametrize("values", [np.zeros(20_000, np.uint16),  # one value
                                    np.arange(20_000, dtype=np.uint16) % 2,  # interleaved
                                    np.repeat(np.arange(40, dtype=np.uint16) % 3, 500),  # runs too short
                                    np.where(np.arange(20_000) < 10_000, 0.0, np.nan).astype(np.float32)])
def test_a_field_that_is_not_stations_leaves_one_station(tmp_path, values):
    xyz = np.random.default_rng(2).random((20_000, 3)).astype(np.float32)
    _write_fields(tmp_path / "one.ply", xyz, {"scan_index": values})
    assert station_runs(open_scan(tmp_path / "one.ply")) is None
    parts, _ = plan_parts([tmp_path / "one.ply"])
    assert {p.station for p in parts} == {0} and station_names(parts) == ["one.ply"]
    np.testing.assert_allclose(read_scan(tmp_path / "one.ply").world(), xyz, atol=1e-6)


def test_cloudcompare_float_field_big_endian(tmp_path):
    """CloudCompare's merge writes ``scalar_Original_cloud_index`` as float; any byte order."""
    xyz = np.random.default_rng(3).random((6_000, 3)).astype(np.float32)
    index = np.repeat(np.float32([1.0, 0.0]), 3_000)
    _write_fields(tmp_path / "cc.ply", xyz, {"scalar_Intensity": np.ones(6_000, np.float32),
                                             "scalar_Original_cloud_index": index}, "binary_big_endian")
    src = open_scan(tmp_path / "cc.ply")
    assert src.station_field == "scalar_Original_cloud_index"
    parts, _ = plan_parts([tmp_path / "cc.ply"])
    assert [(p.station, p.start, p.stop) for p in parts] == [(0, 0, 3_000), (1, 3_000, 6_000)]
    assert station_names(parts) == ["cc.ply#1", "cc.ply#0"]
    got = np.concatenate([c.xyz for p in parts for c in part_chunks(p, np.zeros(3))])
    np.testing.assert_allclose(got, xyz, atol=1e-6)


def test_station_field_names():
    assert station_field(["x", "scalar_Original_cloud_index"]) == "scalar_Original_cloud_index"
    assert station_field(["Scan_ID", "intensity"]) == "Scan_ID"
    assert station_field(["POINT_SOURCE_ID"]) == "POINT_SOURCE_ID"
    assert station_field(["Station", "scan_index"]) == "scan_index"  # the first of STATION_FIELDS wins
    assert station_field(["scalar_station"]) == "scalar_station"
    assert station_field(["intensity", "scan_angle", "stations", "classification"]) is None


def test_ascii_ply_with_a_station_field_reads_as_one_station(tmp_path):
    xyz = np.random.default_rng(4).random((3_000, 3)).astype(np.float32)
    _write_fields(tmp_path / "a.ply", xyz, {"scan_index": np.repeat(np.uint16([0, 1]), 1_500)}, "ascii")
    parts, _ = plan_parts([tmp_path / "a.ply"])
    assert len(parts) == 1 and station_names(parts) == ["a.ply"]
    np.testing.assert_allclose(read_scan(tmp_path / "a.ply").world(), xyz, atol=1e-6)


def test_bad_merged_files_refused_with_one_line(tmp_path):
    xyz = np.random.default_rng(5).random((4_000, 3)).astype(np.float32)
    write_ply(tmp_path / "t.ply", xyz, _grey(4_000), station=np.repeat([0, 1], 2_000))
    data = (tmp_path / "t.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-5])
    for call in (lambda: plan_parts([tmp_path / "t.ply"]), lambda: read_scan(tmp_path / "t.ply")):
        with pytest.raises(InputError) as info:
            call()
        msg = str(info.value)
        assert str(tmp_path / "t.ply") in msg and "truncated" in msg and "\n" not in msg
    (tmp_path / "l.ply").write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        b"property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
        b"property list uchar int scan_index\nend_header\n")
    with pytest.raises(InputError) as info:
        plan_parts([tmp_path / "l.ply"])
    assert "list properties" in str(info.value) and "\n" not in str(info.value)
    with pytest.raises(ValueError):
        write_ply(tmp_path / "w.ply", xyz, _grey(4_000), station=np.zeros(3, np.uint16))


@pytest.mark.slow
def test_detect_refines_the_stations_of_a_simulated_merged_scan(tmp_path):
    """The realistic simulator's merged ``scan.ply`` keeps each point's station; ``sbsc detect``
    refines them (records named ``scan.ply#k``) and takes most of the simulated error away."""
    import json

    from sbsc_core.cli import main
    from sbsc_core.paths import sample_projects_dir
    from sbsc_core.simulate.scenarios import simulate_scene

    out = tmp_path / "sim"
    simulate_scene(sample_projects_dir() / "one_room.yaml", out, seed=4, angular_step_deg=0.4, design=False,
                   realistic=True)
    assert open_scan(out / "scan.ply").station_field == "scan_index"
    truth = json.loads((out / "ground_truth.json").read_text())
    parts, _ = plan_parts([out / "scan.ply"])
    assert station_names(parts) == ["scan.ply#0", "scan.ply#1"] == [f"scan.ply#{r['station']}"
                                                                    for r in truth["registration_errors"]]
    assert main(["-q", "detect", str(out / "scan.ply"), "--models", str(out / "models"),
                 "--out", str(tmp_path / "run")]) == 0
    doc = json.loads((tmp_path / "run" / "detections.json").read_text())
    assert [r["file"] for r in doc["registration"]] == ["scan.ply#0", "scan.ply#1"]
    # station 1's error relative to station 0, before and after: the refinement removes most of it
    given = np.subtract(*[r["translation_m"] for r in truth["registration_errors"][::-1]])
    fixed = given + np.subtract(*[r["translation_m"] for r in doc["registration"][::-1]])
    assert np.linalg.norm(given) > 0.002 and np.linalg.norm(fixed) < 0.5 * np.linalg.norm(given)
