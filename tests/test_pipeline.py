"""`sbsc detect` end to end on a small simulated room, and its refusals of bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.cli import main
from sbsc_core.evaluate import evaluate
from sbsc_core.io.documents import read_detections, read_truth
from sbsc_core.io.ply import write_ply
from sbsc_core.paths import bundled_models_dir, sample_projects_dir
from sbsc_core.simulate.scenarios import simulate_scene


@pytest.fixture(scope="module")
def one_room(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("one_room") / "scan"
    simulate_scene(sample_projects_dir() / "one_room.yaml", out, seed=1, angular_step_deg=0.12)
    return out


@pytest.fixture(scope="module")
def detected(one_room: Path) -> Path:
    out = one_room.parent / "detect"
    rc = main(["-q", "detect", str(one_room / "scan.ply"), "--models", str(one_room / "models"),
               "--expected", str(one_room / "expected.json"), "--out", str(out)])
    assert rc == 0
    return out


@pytest.mark.slow
def test_detect_finds_the_objects_of_a_room(one_room: Path, detected: Path) -> None:
    doc = read_detections(detected / "detections.json")
    table = evaluate(doc, read_truth(one_room / "ground_truth.json"))
    total = table.total
    assert total.instances == 13
    assert total.tp >= 12, total  # at most one miss on a clean room
    assert total.fp <= 1
    assert total.h_mean_mm <= 5.0 and total.v_mean_mm <= 5.0


@pytest.mark.slow
def test_detect_writes_walls_openings_and_images(one_room: Path, detected: Path) -> None:
    doc = json.loads((detected / "detections.json").read_text())
    # a scan without registration error is written without stations: one station, nothing refined
    assert "registration" not in doc
    truth = json.loads((one_room / "ground_truth.json").read_text())
    assert len(doc["walls"]) == len(truth["walls"])
    assert {o["kind"] for o in doc["openings"]} == {o["kind"] for o in truth["openings"]}
    rois = json.loads((detected / "rois.json").read_text())
    for wall in doc["walls"]:
        for suffix in ("colour.png", "depth.png", "depth.npy", "overlay.png"):
            assert (detected / "orthoimages" / f"{wall['id']}_{suffix}").is_file()
        assert set(rois["walls"][wall["id"]]) == {"depth", "colour"}
    depth = np.load(detected / "orthoimages" / f"{doc['walls'][0]['id']}_depth.npy")
    assert depth.dtype == np.float32 and np.isnan(depth).any() and np.isfinite(depth).mean() > 0.5


@pytest.mark.slow
def test_without_expected_every_class_is_searched(one_room: Path, tmp_path: Path) -> None:
    out = tmp_path / "all"
    assert main(["-q", "detect", str(one_room / "scan.ply"), "--models", str(one_room / "models"),
                 "--out", str(out)]) == 0
    doc = read_detections(out / "detections.json")
    assert len(doc["classes_searched"]) == 13
    table = evaluate(doc, read_truth(one_room / "ground_truth.json"))
    assert table.total.tp >= 11 and table.total.fp <= 3


def _refused(capsys, args: list[str], out: Path, needle: str) -> None:
    rc = main(["-q", "detect", *args, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and needle in err, err
    assert not (out / "detections.json").exists()


@pytest.mark.slow
def test_bad_scans_are_refused_with_one_line(tmp_path: Path, capsys) -> None:
    models = str(bundled_models_dir())
    garbage = tmp_path / "garbage.ply"
    garbage.write_bytes(b"\x00\x01not a ply at all")
    _refused(capsys, [str(garbage), "--models", models], tmp_path / "o1", "garbage.ply")
    empty = tmp_path / "empty.xyz"
    empty.write_text("")
    _refused(capsys, [str(empty), "--models", models], tmp_path / "o2", "empty.xyz")
    grey = tmp_path / "grey.xyz"
    grey.write_text("0 0 0\n1 0 0\n0 1 0\n")
    _refused(capsys, [str(grey), "--models", models], tmp_path / "o3", "grey.xyz")
    nan = tmp_path / "nan.xyz"
    nan.write_text("0 0 0 1 2 3\nnan 0 0 1 2 3\n")
    _refused(capsys, [str(nan), "--models", models], tmp_path / "o4", "nan.xyz")
    _refused(capsys, [str(tmp_path / "missing.ply"), "--models", models], tmp_path / "o5", "missing.ply")


@pytest.mark.slow
def test_scan_without_walls_is_refused(tmp_path: Path, capsys) -> None:
    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(0, 5, 50_000), rng.uniform(0, 5, 50_000), np.zeros(50_000)])
    rgb = np.full((50_000, 3), 128, np.uint8)
    write_ply(tmp_path / "floor.ply", xyz.astype(np.float32), rgb)
    _refused(capsys, [str(tmp_path / "floor.ply"), "--models", str(bundled_models_dir())],
             tmp_path / "o", "wall")


@pytest.mark.slow
def test_empty_or_malformed_library_is_refused(one_room: Path, tmp_path: Path, capsys) -> None:
    scan = str(one_room / "scan.ply")
    (tmp_path / "empty_lib").mkdir()
    _refused(capsys, [scan, "--models", str(tmp_path / "empty_lib")], tmp_path / "o1", "empty_lib")
    bad = tmp_path / "bad_lib"
    shutil.copytree(bundled_models_dir(), bad)
    meta = json.loads((bad / "switch" / "model.json").read_text())
    del meta["width_m"]
    (bad / "switch" / "model.json").write_text(json.dumps(meta))
    _refused(capsys, [scan, "--models", str(bad)], tmp_path / "o2", "switch/model.json")
    exp = tmp_path / "expected.json"
    exp.write_text(json.dumps({"schema": "sbsc.expected/1", "counts": {"toaster": 2}}))
    _refused(capsys, [scan, "--models", str(bundled_models_dir()), "--expected", str(exp)],
             tmp_path / "o3", "toaster")


@pytest.mark.slow
def test_compare_finds_every_deliberate_design_difference(one_room: Path, detected: Path) -> None:
    from sbsc_core.bim.compare_outputs import compare_to_dir

    out = one_room.parent / "compare"
    compare_to_dir(one_room / "as_designed.ifc", detected / "detections.json", out)
    items = json.loads((out / "comparison.json").read_text())["items"]
    truth = json.loads((one_room / "ground_truth.json").read_text())
    diffs = truth["design_differences"]
    assert {d["kind"] for d in diffs} == {"moved", "removed", "added"}
    status_of_kind = {"moved": "displaced", "removed": "unexpected", "added": "missing"}
    findings = [i for i in items if i["status"] != "found"]
    for d in diffs:
        assert any(i["status"] == status_of_kind[d["kind"]] and i["class"] == d["class"] for i in findings), d
    table = evaluate(read_detections(detected / "detections.json"), read_truth(one_room / "ground_truth.json"))
    # no false difference among correctly recognized objects: extra findings only from FN/FP
    assert len(findings) - len(diffs) <= table.total.fn + table.total.fp
