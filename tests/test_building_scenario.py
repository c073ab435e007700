"""The simulated building (``sbsc simulate --scenario building``) and detect on it, storey by storey."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.cli import main
from sbsc_core.errors import InputError
from sbsc_core.evaluate import evaluate
from sbsc_core.io.documents import read_detections, read_truth
from sbsc_core.io.scans import read_scans
from sbsc_core.simulate.building_scenario import SLAB_M, build_storey, plan_building
from sbsc_core.simulate.raycast import MeshRaycaster

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def two_storeys(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("building") / "sim"
    assert main(["-q", "simulate", "--scenario", "building", "--scene", "one_room", "--storeys", "2",
                 "--step", "0.2", "--out", str(out)]) == 0
    return out


def test_one_file_per_station_and_truth_with_storeys(two_storeys: Path) -> None:
    files = sorted(p.name for p in (two_storeys / "stations").iterdir())
    assert files == ["S1_001.ply", "S1_002.ply", "S2_001.ply", "S2_002.ply"]
    truth = json.loads((two_storeys / "ground_truth.json").read_text())
    assert [s["id"] for s in truth["storeys"]] == ["S1", "S2"]
    s1, s2 = truth["storeys"]
    assert s2["floor_z"] == pytest.approx(s1["ceiling_z"] + SLAB_M[0])
    assert s1["ceiling_z"] - s1["floor_z"] != pytest.approx(s2["ceiling_z"] - s2["floor_z"])  # storeys differ
    assert {o["storey"] for o in truth["objects"]} == {"S1", "S2"} and len(truth["objects"]) == 26
    for o in truth["objects"]:
        st = s1 if o["storey"] == "S1" else s2
        assert st["floor_z"] < o["position"][2] < st["ceiling_z"] and o["wall"].startswith(o["storey"] + "-")
    counts = json.loads((two_storeys / "expected.json").read_text())["counts"]
    assert sum(counts.values()) == 26
    # contract 3's optional per-storey counts: each storey's objects, adding up to the building's
    from sbsc_core.io.documents import read_expected_counts

    expected = read_expected_counts(two_storeys / "expected.json")
    assert sorted(expected.storeys) == ["S1", "S2"]
    for sid, per in expected.storeys.items():
        assert sum(per.values()) == sum(o["storey"] == sid for o in truth["objects"])
    # a station sees its own storey only
    cloud = read_scans([two_storeys / "stations" / "S2_001.ply"])
    z = cloud.world()[:, 2]
    assert z.min() > s2["floor_z"] - 0.02 and z.max() < s2["ceiling_z"] + 0.02


def test_detect_finds_both_storeys_and_their_walls_and_objects(two_storeys: Path, tmp_path: Path, capsys) -> None:
    scans = [str(p) for p in sorted((two_storeys / "stations").iterdir())]
    out = tmp_path / "det"
    assert main(["detect", *scans, "--models", str(two_storeys / "models"),
                 "--expected", str(two_storeys / "expected.json"), "--out", str(out)]) == 0
    err = capsys.readouterr().err  # the log names the storeys, early and with their results
    assert "2 storeys: S1 (z 0.00 to " in err and "storey S2: floor z = " in err and " of 13 expected" in err
    doc = json.loads((out / "detections.json").read_text())
    truth = json.loads((two_storeys / "ground_truth.json").read_text())
    assert [s["id"] for s in doc["storeys"]] == ["S1", "S2"]
    for got, want in zip(doc["storeys"], truth["storeys"], strict=True):
        assert got["floor_z"] == pytest.approx(want["floor_z"], abs=0.01)
        assert got["ceiling_z"] == pytest.approx(want["ceiling_z"], abs=0.01)
    for sid in ("S1", "S2"):
        walls = [w for w in doc["walls"] if w["storey"] == sid]
        assert sorted(w["id"] for w in walls) == [f"{sid}-W0{k}" for k in range(1, 5)]
        want = next(s for s in truth["storeys"] if s["id"] == sid)
        for w in walls:
            assert w["height_m"] == pytest.approx(want["ceiling_z"] - want["floor_z"], abs=0.01)
    table = evaluate(read_detections(out / "detections.json"), read_truth(two_storeys / "ground_truth.json"))
    assert table.total.instances == 26 and table.total.tp >= 24 and table.total.fp <= 2
    by_storey = {}
    wall_storey = {w["id"]: w["storey"] for w in doc["walls"]}
    for d in doc["detections"]:
        by_storey.setdefault(wall_storey[d["wall"]], []).append(d)
    assert {k: len(v) >= 12 for k, v in by_storey.items()} == {"S1": True, "S2": True}


def test_scenario_storeys_vary_and_one_room_has_a_lower_ceiling() -> None:
    plans = plan_building(4)
    heights = [p.height_m for p in plans]
    assert len(set(heights)) == 4
    floors = [p.floor_z for p in plans]
    slabs = [round(floors[k + 1] - floors[k] - heights[k], 3) for k in range(3)]
    assert len(set(slabs)) == 3 and min(slabs) >= 0.2
    assert [bool(p.room_ceilings) for p in plans] == [False, True, False, True]
    assert plans[0].scene.rooms[0].paint != plans[1].scene.rooms[0].paint  # Scenario I and II paints
    b = build_storey(plans[1])
    rc = MeshRaycaster(b.mesh)
    up = rc.cast(np.array([[4.0, 4.0, floors[1] + 1.5], [15.0, 5.0, floors[1] + 1.5]], np.float32),
                 np.array([[0, 0, 1], [0, 0, 1]], np.float32))
    low = plans[1].room_ceilings["R3"]
    np.testing.assert_allclose(up.t + 1.5, [low, heights[1]], atol=1e-4)  # R3 (at 4, 4) and R4 (at 15, 5)
    r3 = [w for w in b.layout.walls.values() if w.room == "R3"]
    assert r3 and all(w.frame.height_m == pytest.approx(low) for w in r3)
    assert all(o.position[2] > floors[1] for o in b.objects)


@pytest.mark.parametrize("fmt", ["e57", "las"])
def test_station_files_in_e57_and_las_hold_the_same_points(tmp_path: Path, fmt: str) -> None:
    for f in ("ply", fmt):
        assert main(["-q", "simulate", "--scenario", "building", "--scene", "one_room", "--storeys", "1",
                     "--step", "1.0", "--format", f, "--out", str(tmp_path / f)]) == 0
    names = sorted((tmp_path / fmt / "stations").iterdir())
    assert [p.suffix for p in names] == [f".{fmt}"] * 2
    a = read_scans(sorted((tmp_path / "ply" / "stations").iterdir()))
    b = read_scans(names)
    assert len(a) == len(b) > 10_000
    assert np.abs(a.world() - b.world()).max() < 1e-3
    assert np.array_equal(a.rgb, b.rgb)


def test_bad_building_options_are_refused(tmp_path: Path, capsys) -> None:
    with pytest.raises(InputError, match="--storeys"):
        plan_building(0)
    with pytest.raises(SystemExit) as stop:  # an argument error: argparse's, before any work
        main(["-q", "simulate", "--scenario", "building", "--storeys", "0", "--out", str(tmp_path / "x")])
    assert stop.value.code == 2 and "--storeys" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
