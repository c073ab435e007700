"""Expected counts, ground truth and detections documents (contracts 3-5)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.io.documents import (
    detections_document,
    read_detections,
    read_expected,
    read_expected_counts,
    read_truth,
    write_detections,
)
from sbsc_core.types import Detection, Opening, WallFrame

FRAME = WallFrame(origin=np.array([1.0, 2.0, 0.0]), axis_u=np.array([1.0, 0.0, 0.0]),
                  axis_v=np.array([0.0, 0.0, 1.0]), normal=np.array([0.0, 1.0, 0.0]),
                  width_m=6.1, height_m=2.7)


def _detection(i: int, cls: str = "socket_x1", source: str = "both") -> Detection:
    u, v = 0.5 + i, 0.3
    return Detection(id=f"D{i:04d}", class_id=cls, wall_id="W03", u=u, v=v,
                     position=FRAME.to_world(u, v), width_m=0.08, height_m=0.08, alpha=0.94,
                     rho_depth=0.82 if source != "colour" else None,
                     rho_colour=0.07 if source != "depth" else None, source=source)


def _doc() -> dict:
    return detections_document(
        [("W03", FRAME)], [Opening("W03", "door", 1.2, 2.1, 0.0, 2.05)],
        [_detection(1), _detection(2, "switch", "depth"), _detection(3, "radiator", "colour")],
        extra={"run": {"seconds": 1.5}})


def _write(path: Path, doc) -> Path:
    path.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    return path


def _error(fn, path: Path) -> str:
    with pytest.raises(InputError) as info:
        fn(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    return msg


# --------------------------------------------------------------------------- expected


def test_read_expected(tmp_path):
    p = _write(tmp_path / "expected.json",
               {"schema": "sbsc.expected/1", "counts": {"socket_x1": 20, "switch": 0}, "note": "x"})
    assert read_expected(p) == {"socket_x1": 20, "switch": 0}


@pytest.mark.parametrize("doc, fragment", [
    ({"counts": {"switch": 1}}, "missing key 'schema'"),
    ({"schema": "sbsc.expected/2", "counts": {}}, "schema: expected 'sbsc.expected/1'"),
    ({"schema": "sbsc.expected/1"}, "missing key 'counts'"),
    ({"schema": "sbsc.expected/1", "counts": [1]}, "counts: expected a JSON object"),
    ({"schema": "sbsc.expected/1", "counts": {"switch": -1}}, "counts.switch: expected a non-negative integer"),
    ({"schema": "sbsc.expected/1", "counts": {"switch": 1.5}}, "counts.switch: expected a non-negative integer"),
    ({"schema": "sbsc.expected/1", "counts": {"switch": True}}, "counts.switch: expected a non-negative integer"),
    ({"schema": "sbsc.expected/1", "counts": {"Switch": 1}}, "counts.Switch: expected lower case"),
    ('{"schema": "sbsc.expected/1", "counts": {"switch": NaN}}', "invalid JSON (NaN is not valid JSON)"),
    ('{"schema": ', "invalid JSON (line 1"),
    ("[]", "expected a JSON object"),
])
def test_bad_expected(tmp_path, doc, fragment):
    msg = _error(read_expected, _write(tmp_path / "expected.json", doc))
    assert fragment in msg, msg


def test_read_expected_per_storey(tmp_path):
    """Contract 3's optional ``storeys``: each storey's counts, adding up to ``counts``."""
    doc = {"schema": "sbsc.expected/1", "counts": {"socket_x1": 5, "switch": 2},
           "storeys": {"S1": {"socket_x1": 3, "switch": 2}, "S2": {"socket_x1": 2}}}
    got = read_expected_counts(_write(tmp_path / "e.json", doc))
    assert got.counts == {"socket_x1": 5, "switch": 2}
    assert got.storeys == {"S1": {"socket_x1": 3, "switch": 2}, "S2": {"socket_x1": 2}}
    assert read_expected(tmp_path / "e.json") == {"socket_x1": 5, "switch": 2}  # the old reader: counts
    old = read_expected_counts(_write(tmp_path / "old.json", {"schema": "sbsc.expected/1", "counts": {"switch": 1}}))
    assert (old.counts, old.storeys) == ({"switch": 1}, None)


@pytest.mark.parametrize("storeys, fragment", [
    ([1], "storeys: expected a JSON object"),
    ({"first": {"switch": 2}}, "storeys.first: storey ids are S1, S2"),
    ({"S1": {"switch": -1}}, "storeys.S1.switch: expected a non-negative integer"),
    ({"S1": {"switch": 1}, "S2": {"switch": 2}}, "storeys.*.switch: the storeys hold 3 in all, counts.switch is 2"),
    ({"S1": {"switch": 2, "radiator": 1}}, "storeys.*.radiator: the storeys hold 1 in all, counts.radiator is 0"),
])
def test_bad_expected_storeys(tmp_path, storeys, fragment):
    doc = {"schema": "sbsc.expected/1", "counts": {"switch": 2}, "storeys": storeys}
    msg = _error(read_expected, _write(tmp_path / "expected.json", doc))
    assert fragment in msg and "\n" not in msg, msg


def test_missing_file(tmp_path):
    assert "no such file" in _error(read_expected, tmp_path / "nope.json")
    assert "no such file" in _error(read_truth, tmp_path / "nope.json")
    assert "no such file" in _error(read_detections, tmp_path / "nope.json")


# --------------------------------------------------------------------------- truth


def _truth_doc() -> dict:
    objs = [{"class": "switch", "position": [1.0, 2.0, 1.1], "normal": [0, 1, 0], "width_m": 0.08,
             "height_m": 0.08, "wall": "W01", "u": 0.5, "v": 1.1, "id": "T1"},
            {"class": "radiator", "position": [3, 2, 0.45], "normal": [0, 1, 0], "width_m": 0.8, "height_m": 0.6}]
    return {"schema": "sbsc.truth/1", "objects": objs, "walls": [{"id": "W01"}],
            "openings": [{"wall": "W01", "kind": "door"}], "scenario": "I"}


def test_read_truth(tmp_path):
    t = read_truth(_write(tmp_path / "ground_truth.json", _truth_doc()))
    assert [o.class_id for o in t.objects] == ["switch", "radiator"]
    a, b = t.objects
    np.testing.assert_array_equal(a.position, [1.0, 2.0, 1.1])
    assert a.position.dtype == np.float64 and a.normal.shape == (3,)
    assert (a.wall, a.u, a.v, a.extra) == ("W01", 0.5, 1.1, {"id": "T1"})
    assert (b.wall, b.u, b.v, b.width_m) == (None, None, None, 0.8)
    assert t.walls == [{"id": "W01"}] and t.openings[0]["kind"] == "door"
    assert t.extra == {"scenario": "I"}


def test_truth_error_names_field(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    doc = _truth_doc()
    doc["objects"] = doc["objects"] * 2
    doc["objects"][3] = dict(doc["objects"][3], position=[1, 2])
    _write(Path("truth.json"), doc)
    with pytest.raises(InputError) as info:
        read_truth(Path("truth.json"))
    assert str(info.value) == "truth.json: objects[3].position: expected 3 numbers, got [1, 2]"


@pytest.mark.parametrize("change, fragment", [
    (lambda d: d["objects"][0].pop("class"), "objects[0]: missing key 'class'"),
    (lambda d: d["objects"][1].update(width_m=0), "objects[1].width_m: must be > 0"),
    (lambda d: d["objects"][1].update(normal=[0, "1", 0]), "objects[1].normal: expected 3 numbers"),
    (lambda d: d["objects"][0].update(wall=7), "objects[0].wall: expected a non-empty string"),
    (lambda d: d.update(objects={}), "objects: expected a list"),
    (lambda d: d.update(schema="sbsc.detections/1"), "schema: expected 'sbsc.truth/1'"),
    (lambda d: d.update(walls=[3]), "walls[0]: expected a JSON object"),
])
def test_bad_truth(tmp_path, change, fragment):
    doc = _truth_doc()
    change(doc)
    msg = _error(read_truth, _write(tmp_path / "t.json", doc))
    assert fragment in msg, msg


# --------------------------------------------------------------------------- detections


def test_detections_roundtrip(tmp_path):
    doc = _doc()
    assert doc["schema"] == "sbsc.detections/1" and doc["run"] == {"seconds": 1.5}
    assert doc["walls"][0]["id"] == "W03" and doc["walls"][0]["width_m"] == 6.1
    assert doc["openings"][0] == {"wall": "W03", "kind": "door", "u_min": 1.2, "u_max": 2.1,
                                  "v_min": 0.0, "v_max": 2.05}
    write_detections(tmp_path / "out" / "detections.json", doc)
    back = read_detections(tmp_path / "out" / "detections.json")
    assert back == json.loads(json.dumps(doc))
    d = back["detections"][1]
    assert d["class"] == "switch" and d["rho_colour"] is None and d["source"] == "depth"
    np.testing.assert_allclose(d["position"], FRAME.to_world(2.5, 0.3), atol=1e-5)
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["detections.json"]  # no temp files left
    # the web API adds a review block per detection: still a valid document
    back["detections"][0]["review"] = {"status": "pending", "by": None, "at": None, "version": 1}
    write_detections(tmp_path / "d2.json", back)
    assert read_detections(tmp_path / "d2.json")["detections"][0]["review"]["version"] == 1


def test_detections_document_refuses_key_clash():
    with pytest.raises(ValueError):
        detections_document([("W03", FRAME)], [], [], extra={"walls": []})


@pytest.mark.parametrize("change, fragment", [
    (lambda d: d.pop("walls"), "missing key 'walls'"),
    (lambda d: d["detections"][0].pop("alpha"), "detections[0]: missing key 'alpha'"),
    (lambda d: d["detections"][1].update(alpha=1.5), "detections[1].alpha: must be between 0 and 1"),
    (lambda d: d["detections"][2].update(source="laser"), "detections[2].source: expected one of both, depth, colour"),
    (lambda d: d["detections"][2].update(wall="W99"), "detections[2].wall: unknown wall \"W99\""),
    (lambda d: d["detections"][2].update(id="D0001"), "detections[2].id: duplicate detection id"),
    (lambda d: d["detections"][0].update(position=[0, 0, None]), "detections[0].position: expected 3 numbers"),
    (lambda d: d["detections"][0].update(rho_depth="high"), "detections[0].rho_depth: expected a number or null"),
    (lambda d: d["detections"][0].update({"class": "Socket"}), "detections[0].class: expected lower case"),
    (lambda d: d["walls"][0].update(axis_u=[1, 0]), "walls[0].axis_u: expected 3 numbers"),
    (lambda d: d["openings"][0].update(kind="hatch"), "openings[0].kind: expected one of door, window"),
    (lambda d: d["openings"][0].update(u_min=3.0), "openings[0]: u_min/v_min must not exceed"),
])
def test_bad_detections(tmp_path, change, fragment):
    doc = json.loads(json.dumps(_doc()))
    change(doc)
    msg = _error(read_detections, _write(tmp_path / "detections.json", doc))
    assert fragment in msg, msg
    with pytest.raises(InputError):
        write_detections(tmp_path / "never.json", doc)
    assert not (tmp_path / "never.json").exists()
