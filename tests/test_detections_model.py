"""The one validation path of contract 4 (sbsc_core.io.detections_model)."""

from __future__ import annotations

import copy
import json

import pytest

from sbsc_core.bim.export import parse_detections_document
from sbsc_core.errors import InputError
from sbsc_core.io.detections_model import parse_detections, validate_detections
from sbsc_core.io.safe_json import loads_bounded

from .bim_fixtures import detections_document


def _full() -> dict:
    """Every optional part of contract 4: storeys, surfaces, confidence, a reviewer's object."""
    doc = detections_document()
    doc["storeys"] = [{"id": "S1", "floor_z": 0.0, "ceiling_z": 2.7}]
    for w in doc["walls"]:
        w["storey"] = "S1"
    doc["surfaces"] = [{"id": "S1-R1-C", "kind": "ceiling", "origin": [0, 4, 2.7], "axis_u": [1, 0, 0],
                        "axis_v": [0, -1, 0], "normal": [0, 0, -1], "width_m": 5.0, "height_m": 4.0}]
    doc["detections"][0]["confidence"] = 0.93
    doc["detections"][1]["rotation_deg"] = 90.0
    doc["detections"].append({"id": "R1", "class": "smoke_detector", "wall": "S1-R1-C", "surface": "ceiling",
                              "position": [2.5, 2.0, 2.7], "u": 2.5, "v": 2.0, "width_m": 0.11,
                              "height_m": 0.11, "alpha": None, "rho_depth": None, "rho_colour": None,
                              "source": "reviewer", "review": {"status": "accepted", "version": 1},
                              "note": "added by hand"})
    return doc


def test_accepts_every_optional_part_and_keeps_extra_keys():
    doc = _full()
    before = copy.deepcopy(doc)
    assert validate_detections(doc) is doc and doc == before
    model = parse_detections(doc)
    assert model.detections[-1].source == "reviewer" and model.detections[-1].model_extra == {"note": "added by hand"}
    assert parse_detections_document(doc).walls.keys() == {"W1", "W2", "W3"}


@pytest.mark.parametrize("change, fragment", [
    (lambda d: d["detections"][0].update(position=[1e308, 0, 0]), "detections[0].position: coordinates must lie"),
    (lambda d: d["detections"][0].update({"class": "../../etc/passwd"}), "detections[0].class: expected lower case"),
    (lambda d: d["detections"][0].update(id="D\u202e1"), "detections[0].id: contains the control character U+202E"),
    (lambda d: d["detections"][0].update(confidence=1.5), "detections[0].confidence: must be between 0 and 1"),
    (lambda d: d["detections"][0].update(wall="S9"), "detections[0].wall: unknown wall"),
    (lambda d: d["walls"][1].update(storey="S7"), "walls[1].storey: unknown storey"),
    (lambda d: d["surfaces"][0].update(id="W1"), "surfaces[0].id: duplicate wall id"),
    (lambda d: d["detections"][-1].update(source="oracle"), "source: expected one of both, depth, colour, reviewer"),
    (lambda d: d["detections"][-1]["review"].update(status="maybe"), "review.status: expected one of"),
    (lambda d: d["walls"][0].update(width_m=1e5), "walls[0].width_m: must be between"),
    (lambda d: d.update(schema="sbsc.detections/9"), "schema: expected 'sbsc.detections/1'"),
])
def test_refuses_with_the_field_named(change, fragment):
    doc = _full()
    change(doc)
    with pytest.raises(InputError) as info:
        validate_detections(doc, "d.json")
    msg = str(info.value)
    assert msg.startswith("d.json: ") and fragment in msg and "\n" not in msg, msg


def test_bounded_json_refuses_depth_and_keys_before_recursing():
    with pytest.raises(InputError, match="nested deeper than 32"):
        loads_bounded("[" * 200_000 + "]" * 200_000, "x.json")
    with pytest.raises(InputError, match="keys"):
        loads_bounded(json.dumps({f"k{i}": i for i in range(20_000)}), "x.json")
    with pytest.raises(InputError, match="NaN is not valid JSON"):
        loads_bounded('{"a": NaN}', "x.json")
    assert loads_bounded('{"a": "[{"}', "x.json") == {"a": "[{"}  # brackets in strings do not count
