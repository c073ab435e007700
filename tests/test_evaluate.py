"""``sbsc evaluate``: matching and the paper's Table 1 columns."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.cli import main
from sbsc_core.evaluate import evaluate, evaluate_files, format_table, match_class
from sbsc_core.io.documents import TruthDocument, TruthObject, detections_document, read_truth
from sbsc_core.types import Detection, WallFrame

SBSC = Path(sys.executable).with_name("sbsc")
FRAME = WallFrame(origin=np.zeros(3), axis_u=np.array([1.0, 0, 0]), axis_v=np.array([0, 0, 1.0]),
                  normal=np.array([0, 1.0, 0]), width_m=20.0, height_m=3.0)

# (class, u along the wall, height): objects at least 0.5 m apart
LAYOUT = [("socket_x1", 0.5, 0.3), ("socket_x1", 1.5, 0.3), ("socket_x1", 2.5, 0.3), ("socket_x1", 3.5, 0.3),
          ("switch", 4.5, 1.1), ("switch", 5.5, 1.1), ("switch", 6.5, 1.1),
          ("radiator", 8.0, 0.45), ("radiator", 10.0, 0.45),
          ("extinguisher_sign", 12.0, 1.95), ("extinguisher_sign", 13.0, 1.95),
          ("custom_valve", 15.0, 1.0)]


def _truth() -> TruthDocument:
    return TruthDocument(objects=[
        TruthObject(class_id=c, position=FRAME.to_world(u, v), normal=FRAME.normal.copy(),
                    width_m=0.1, height_m=0.1, wall="W01", u=u, v=v) for c, u, v in LAYOUT])


def _truth_json(truth: TruthDocument) -> dict:
    return {"schema": "sbsc.truth/1", "objects": [
        {"class": o.class_id, "position": o.position.tolist(), "normal": o.normal.tolist(),
         "width_m": o.width_m, "height_m": o.height_m, "wall": o.wall, "u": o.u, "v": o.v}
        for o in truth.objects]}


def _detections(truth: TruthDocument, edit=None) -> dict:
    """Detections copied from the truth (alpha 1); ``edit(i, det)`` may change or drop (None) each."""
    dets = []
    for i, o in enumerate(truth.objects):
        d = Detection(id=f"D{i:04d}", class_id=o.class_id, wall_id="W01", u=o.u, v=o.v,
                      position=o.position.copy(), width_m=o.width_m, height_m=o.height_m, alpha=1.0,
                      rho_depth=0.9, rho_colour=0.05, source="both")
        d = edit(i, d) if edit else d
        if d is not None:
            dets.append(d)
    return detections_document([("W01", FRAME)], [], dets)


def test_truth_against_itself_is_perfect():
    truth = _truth()
    table = evaluate(_detections(truth), truth)
    t = table.total
    assert (t.instances, t.tp, t.fn, t.fp) == (12, 12, 0, 0)
    assert (t.tp_pct, t.fn_pct, t.fp_pct, t.tp_alpha_high_pct) == (100.0, 0.0, 0.0, 100.0)
    assert (t.h_mean_mm, t.v_mean_mm, t.h_max_mm, t.v_max_mm) == (0.0, 0.0, 0.0, 0.0)
    # the bundled library's order (its model.json "order") first, then other classes alphabetically
    assert [r.class_id for r in table.rows] == ["socket_x1", "switch", "radiator", "extinguisher_sign", "custom_valve"]
    assert table.rows[0].name == "Socket x1" and table.unknown_class_detections == 0


def _perturb(i: int, d: Detection) -> Detection | None:
    if i == 1:  # socket shifted 30 mm along the wall (horizontal) and 20 mm up
        d.position = d.position + np.array([0.03, 0.0, 0.02])
        d.alpha = 0.95
    elif i == 2:  # socket relabelled as a switch (far from every switch)
        d.class_id = "switch"
    elif i == 5:  # a switch missed
        return None
    elif i == 8:  # radiator placed 0.2 m off: one FN and one FP
        d.position = d.position + np.array([0.0, 0.0, 0.2])
    elif i == 10:  # found with low coherence
        d.alpha = 0.5
    elif i == 11:  # a class that is not in the ground truth at all
        d.class_id = "exit_light"
    return d


def test_perturbed_copy_reports_exactly_the_changes():
    truth = _truth()
    table = evaluate(_detections(truth, _perturb), truth)
    rows = {r.class_id: r for r in table.rows}
    assert list(rows) == ["socket_x1", "switch", "radiator", "exit_light", "extinguisher_sign", "custom_valve"]
    counts = {c: (r.instances, r.tp, r.fn, r.fp) for c, r in rows.items()}
    assert counts == {"socket_x1": (4, 3, 1, 0), "switch": (3, 2, 1, 1), "radiator": (2, 1, 1, 1),
                      "exit_light": (0, 0, 0, 1), "extinguisher_sign": (2, 2, 0, 0), "custom_valve": (1, 0, 1, 0)}
    s = rows["socket_x1"]
    assert s.tp_pct == 75.0 and s.fn_pct == 25.0 and s.fp_pct == 0.0
    assert s.h_max_mm == pytest.approx(30.0) and s.v_max_mm == pytest.approx(20.0)
    assert s.h_mean_mm == pytest.approx(10.0) and s.v_mean_mm == pytest.approx(20.0 / 3)
    assert rows["switch"].fp_pct == pytest.approx(100 / 3)
    assert rows["radiator"].h_max_mm == 0.0 and rows["radiator"].v_max_mm == 0.0
    assert rows["extinguisher_sign"].tp_alpha_high_pct == 50.0
    e = rows["exit_light"]
    assert e.tp_pct is None and e.fp_pct is None and e.h_mean_mm is None
    t = table.total
    assert (t.instances, t.tp, t.fn, t.fp) == (12, 8, 4, 3)
    assert t.tp_pct == pytest.approx(100 * 8 / 12) and t.fp_pct == pytest.approx(25.0)
    assert t.tp_alpha_high_pct == pytest.approx(100 * 7 / 8)
    assert t.h_mean_mm == pytest.approx(30 / 8) and t.v_mean_mm == pytest.approx(20 / 8)
    assert (t.h_max_mm, t.v_max_mm) == (pytest.approx(30.0), pytest.approx(20.0))
    assert table.unknown_class_detections == 1
    # a wider radius turns the 0.2 m radiator into a true positive with a 200 mm vertical error
    wide = {r.class_id: r for r in evaluate(_detections(truth, _perturb), truth, max_distance_m=0.25).rows}
    assert (wide["radiator"].tp, wide["radiator"].v_max_mm) == (2, pytest.approx(200.0))


def test_greedy_matching_is_closest_first_and_one_to_one():
    truth = np.array([[0.0, 0, 0], [0.1, 0, 0]])
    dets = np.array([[0.06, 0, 0], [0.16, 0, 0]])
    # closest pair (truth 1, det 0) at 0.04 m goes first; then truth 0 has no free detection
    assert match_class(truth, dets, 0.10) == [(1, 0)]
    assert match_class(truth, dets[:0], 0.10) == []
    assert sorted(match_class(truth, truth + 0.01, 0.10)) == [(0, 0), (1, 1)]


def test_format_table():
    truth = _truth()
    text = format_table(evaluate(_detections(truth, _perturb), truth))
    lines = text.splitlines()
    assert lines[0].split()[:2] == ["Object", "Inst"] and "a>.9%" in lines[0]
    socket = next(line for line in lines if line.startswith("Socket x1"))
    assert socket.split()[2:11] == ["4", "75.0", "25.0", "0.0", "100.0", "10.0", "6.7", "30.0", "20.0"]
    total = next(line for line in lines if line.startswith("TOTAL"))
    assert total.split()[1:5] == ["12", "66.7", "33.3", "25.0"]
    assert "1 detection(s) of classes absent from the ground truth" in text
    rows = [line for line in lines if not line.startswith(("match radius", "Inst:", "dh, dv"))]
    assert len({len(line) for line in rows}) == 1  # fixed width
    assert max(len(line) for line in lines) <= 100  # fits a 100-column terminal


def _write_files(tmp_path: Path, edit=None) -> tuple[Path, Path]:
    truth = _truth()
    (tmp_path / "truth.json").write_text(json.dumps(_truth_json(truth)))
    (tmp_path / "detections.json").write_text(json.dumps(_detections(truth, edit)))
    return tmp_path / "detections.json", tmp_path / "truth.json"


def test_evaluate_files_writes_json(tmp_path):
    det, tru = _write_files(tmp_path, _perturb)
    assert len(read_truth(tru).objects) == 12
    text = evaluate_files(det, tru, json_out=tmp_path / "out" / "eval.json")
    assert "TOTAL" in text
    out = json.loads((tmp_path / "out" / "eval.json").read_text())
    assert out["schema"] == "sbsc.evaluation/1" and out["unknown_class_detections"] == 1
    assert [r["class"] for r in out["rows"]][:3] == ["socket_x1", "switch", "radiator"]
    assert {k: out["total"][k] for k in ("instances", "tp", "fn", "fp")} == {"instances": 12, "tp": 8, "fn": 4, "fp": 3}
    assert out["rows"][0]["h_max_mm"] == pytest.approx(30.0)


def test_cli_evaluate(tmp_path, capsys):
    det, tru = _write_files(tmp_path)
    assert main(["evaluate", "--detections", str(det), "--truth", str(tru), "--json", str(tmp_path / "e.json")]) == 0
    out = capsys.readouterr().out
    assert "TOTAL" in out and "100.0" in out
    assert json.loads((tmp_path / "e.json").read_text())["total"]["tp"] == 12
    # malformed input: exit 2, one line naming the file and the field, no JSON written
    doc = json.loads(det.read_text())
    doc["detections"][3]["position"] = [1, 2]
    det.write_text(json.dumps(doc))
    assert main(["evaluate", "--detections", str(det), "--truth", str(tru), "--json", str(tmp_path / "f.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"sbsc: error: {det}: detections[3].position: expected 3 numbers, got [1, 2]"]
    assert not (tmp_path / "f.json").exists()


def _library(root: Path, classes: dict[str, dict]) -> Path:
    """A model library of ``classes`` (class id -> extra model.json fields) with a tiny view each."""
    import cv2

    for cid, extra in classes.items():
        (root / cid).mkdir(parents=True)
        (root / cid / "model.json").write_text(json.dumps(
            {"name": cid.title(), "ifc_class": "IfcOutlet", "width_m": 0.1, "height_m": 0.1, **extra}))
        cv2.imwrite(str(root / cid / "colour.png"), np.zeros((8, 8, 3), np.uint8))
    return root


def test_rows_follow_the_library_order_and_names(tmp_path):
    truth = _truth()
    lib = _library(tmp_path / "models", {"switch": {"order": 2}, "radiator": {"order": 1, "name": "Heater"},
                                         "socket_x1": {}, "extinguisher_sign": {}})
    from sbsc_core.io.models import read_library_metadata

    table = evaluate(_detections(truth), truth, library=read_library_metadata(lib))
    # ordered classes first, then the library's others by id, then classes it does not hold
    assert [r.class_id for r in table.rows] == ["radiator", "switch", "extinguisher_sign", "socket_x1",
                                                 "custom_valve"]
    assert [r.name for r in table.rows][:2] == ["Heater", "Switch"] and table.rows[-1].name == "custom_valve"
    det, tru = _write_files(tmp_path)
    text = evaluate_files(det, tru, models=lib)
    assert text.splitlines()[2].startswith("Heater")
    assert main(["evaluate", "--detections", str(det), "--truth", str(tru), "--models", str(lib)]) == 0


def test_production_code_does_not_import_the_simulator():
    """evaluate, bim and the review service read class metadata from the model library."""
    code = ("import sys, sbsc_core.evaluate, sbsc_core.bim, sbsc_core.bim.design, sbsc_core.bim.export, "
            "app.review_service, app.libraries as r; r.bundled_classes(); sbsc_core.bim.class_typings(); "
            "sys.exit(any(m.startswith('sbsc_core.simulate') for m in sys.modules))")
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", code], cwd=root, env={"PYTHONPATH": str(root)},
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr or "sbsc_core.simulate was imported"


@pytest.mark.skipif(not SBSC.exists(), reason="console script not installed")
def test_cli_subprocess_missing_file(tmp_path):
    _, tru = _write_files(tmp_path)
    r = subprocess.run([str(SBSC), "evaluate", "--detections", str(tmp_path / "none.json"), "--truth", str(tru)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [f"sbsc: error: {tmp_path / 'none.json'}: no such file"]
    assert r.stdout == ""
