"""The realism options of the simulated building (``sbsc simulate --scenario building --all-realism``).

Every storey gets the realistic scanner, its own clutter and furniture, and with
``--survey-frame`` the station files and the truth are at UTM-like coordinates. Without
the options the building is the plain one, byte for byte.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.cli import main
from sbsc_core.evaluate import evaluate
from sbsc_core.io.documents import read_detections, read_truth
from sbsc_core.io.scans import read_scans
from sbsc_core.simulate.building_scenario import build_storey, plan_building, simulate_building
from sbsc_core.simulate.survey import UTM_LIKE_OFFSET

pytestmark = pytest.mark.slow

# sha256 over the station PLYs, ground_truth.json and expected.json of the plain 2-storey
# one_room building at 2 degrees, seed 0, as written before the realism options existed
# (main at d50b2bb). If you change the plain simulator on purpose, update it.
PLAIN_DIGEST = "7e4aac43223a0aea68a81ea116913de64fc2e837101e0bff75a6f92568e5fa18"


def _digest(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted([*root.glob("stations/*.ply"), root / "ground_truth.json", root / "expected.json"]):
        h.update(p.relative_to(root).as_posix().encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def _simulate(out: Path, *options: str, step: str = "1.0", storeys: str = "2") -> Path:
    assert main(["-q", "simulate", "--scenario", "building", "--scene", "one_room", "--storeys", storeys,
                 "--step", step, *options, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def realistic(tmp_path_factory) -> Path:
    return _simulate(tmp_path_factory.mktemp("building") / "sim", "--all-realism")


def test_without_options_the_building_is_byte_identical_to_the_plain_one(tmp_path: Path) -> None:
    out = _simulate(tmp_path / "plain", step="2.0")
    assert _digest(out) == PLAIN_DIGEST
    truth = json.loads((out / "ground_truth.json").read_text())
    assert not {"distractors", "registration_errors", "survey_frame"} & set(truth)
    assert not any("visible_fraction" in o for o in truth["objects"])


def test_all_realism_reaches_every_storey_of_the_truth(realistic: Path) -> None:
    truth = json.loads((realistic / "ground_truth.json").read_text())
    walls = {w["id"]: w["storey"] for w in truth["walls"]}
    # clutter and furniture on both storeys, on that storey's walls, laid out differently
    dist = truth["distractors"]
    assert {d["storey"] for d in dist} == {"S1", "S2"}
    assert all(walls[d["wall"]] == d["storey"] for d in dist)
    assert any(d["furniture"] for d in dist) and any(not d["furniture"] for d in dist)
    layout = {s: sorted((d["kind"], d["wall"].split("-", 1)[1], d["u"]) for d in dist if d["storey"] == s)
              for s in ("S1", "S2")}
    assert layout["S1"] != layout["S2"]
    levels = {s["id"]: (s["floor_z"], s["ceiling_z"]) for s in truth["storeys"]}
    for d in dist:
        lo, hi = levels[d["storey"]]
        assert lo - 0.01 <= d["centre"][2] - d["size_m"][1] / 2 and d["centre"][2] + d["size_m"][1] / 2 <= hi
    # what the scanner saw of each object
    assert all(0.0 <= o["visible_fraction"] <= 1.0 for o in truth["objects"])
    assert np.mean([o["visible_fraction"] for o in truth["objects"]]) > 0.5
    # one registration error per station, counted over the whole building
    reg = truth["registration_errors"]
    assert [r["station"] for r in reg] == list(range(len(truth["stations"]))) == [0, 1, 2, 3]
    assert [r["file"] for r in reg] == [f"stations/{p.name}" for p in sorted((realistic / "stations").iterdir())]
    assert [r["storey"] for r in reg] == ["S1", "S1", "S2", "S2"]
    assert len({tuple(r["translation_m"]) for r in reg}) == 4
    assert all(np.linalg.norm(r["translation_m"]) < 0.05 and r["rotation_deg"] < 0.2 for r in reg)


def test_survey_frame_puts_station_files_and_truth_at_large_coordinates(realistic: Path) -> None:
    truth = json.loads((realistic / "ground_truth.json").read_text())
    off = np.array(UTM_LIKE_OFFSET)
    assert truth["survey_frame"]["offset"] == list(UTM_LIKE_OFFSET)
    for o in [*truth["objects"], *truth["distractors"]]:
        assert np.linalg.norm(np.array(o["position"][:2]) - off[:2]) < 50
    s1, s2 = truth["storeys"]
    assert s1["floor_z"] == pytest.approx(off[2]) and s2["floor_z"] > s1["ceiling_z"] > off[2]
    for k, path in enumerate(sorted((realistic / "stations").iterdir())):
        assert b"property double x" in path.read_bytes()[:400]  # float32 would round to ~0.5 m here
        xyz = read_scans([path]).world()
        station = np.array(truth["stations"][k])
        assert np.linalg.norm(station[:2] - off[:2]) < 50
        dist = np.linalg.norm(xyz - station, axis=1)
        assert dist.min() > 0.3 and np.median(dist) < 6.0  # the points surround their own station
        storey = truth["storeys"][k // 2]
        assert storey["floor_z"] - 0.03 < xyz[:, 2].min() and xyz[:, 2].max() < storey["ceiling_z"] + 0.03


def test_the_realistic_building_is_deterministic_and_storeys_differ_by_seed(tmp_path: Path) -> None:
    a = _simulate(tmp_path / "a", "--all-realism", step="2.0")
    b = _simulate(tmp_path / "b", "--all-realism", step="2.0")
    assert _digest(a) == _digest(b)
    c = _simulate(tmp_path / "c", "--all-realism", "--seed", "1", step="2.0")
    assert _digest(a) != _digest(c)
    da, dc = (json.loads((p / "ground_truth.json").read_text())["distractors"] for p in (a, c))
    assert [d["u"] for d in da] != [d["u"] for d in dc]


def test_each_option_alone(tmp_path: Path) -> None:
    clutter = json.loads((_simulate(tmp_path / "c", "--clutter", step="2.0") / "ground_truth.json").read_text())
    assert clutter["distractors"] and not any(d["furniture"] for d in clutter["distractors"])
    assert "registration_errors" not in clutter and "survey_frame" not in clutter
    assert all("visible_fraction" in o for o in clutter["objects"])
    real = json.loads((_simulate(tmp_path / "r", "--realistic", step="2.0") / "ground_truth.json").read_text())
    assert len(real["registration_errors"]) == 4 and "distractors" not in real
    assert abs(real["stations"][0][0]) < 100


@pytest.mark.parametrize("fmt", ["e57", "las"])
def test_e57_and_las_keep_survey_coordinates_exact(tmp_path: Path, fmt: str) -> None:
    for f in ("ply", fmt):
        _simulate(tmp_path / f, "--survey-frame", "--realistic", "--format", f, step="2.0", storeys="1")
    a = read_scans(sorted((tmp_path / "ply" / "stations").iterdir()))
    b = read_scans(sorted((tmp_path / fmt / "stations").iterdir()))
    assert len(a) == len(b) > 1000
    assert np.abs(a.origin - np.array(UTM_LIKE_OFFSET)).max() < 100
    assert np.abs(a.world() - b.world()).max() < 1e-3
    assert np.array_equal(a.rgb, b.rgb)


def test_build_storey_lays_out_distractors_per_storey() -> None:
    plans = plan_building(2, "one_room", clutter=True, furniture=True)
    s1, s2 = (build_storey(p, seed=3) for p in plans)
    assert s1.distractors and s2.distractors
    assert [(d.kind, d.u) for d in s1.distractors] != [(d.kind, d.u) for d in s2.distractors]
    again = build_storey(plans[1], seed=3)
    assert [(d.kind, d.u, d.variant) for d in again.distractors] == [(d.kind, d.u, d.variant) for d in s2.distractors]
    assert (s2.mesh.tri_label == -2).any()  # in the storey's mesh, on its floor
    assert s2.mesh.vertices[:, 2].min() >= plans[1].floor_z - 1e-6


@pytest.mark.slow
def test_detect_and_evaluate_run_on_a_realistic_two_storey_building(tmp_path: Path) -> None:
    sim = _simulate(tmp_path / "sim", "--all-realism", step="0.4")
    out = tmp_path / "det"
    scans = [str(p) for p in sorted((sim / "stations").iterdir())]
    assert main(["-q", "detect", *scans, "--models", str(sim / "models"), "--expected", str(sim / "expected.json"),
                 "--out", str(out)]) == 0
    table = evaluate(read_detections(out / "detections.json"), read_truth(sim / "ground_truth.json"))
    assert table.total.instances == 26  # runs end to end; the figures are measured, not asserted
    assert main(["-q", "evaluate", "--detections", str(out / "detections.json"),
                 "--truth", str(sim / "ground_truth.json")]) == 0


def test_simulate_building_keeps_its_plain_signature(tmp_path: Path) -> None:
    s = simulate_building(tmp_path / "x", 1, scene="one_room", angular_step_deg=3.0, clutter=True)
    assert s.storeys == 1 and s.stations == 2 and s.points > 0
