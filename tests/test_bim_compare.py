"""Scan-vs-BIM comparison: verdicts, report pictures and the BCF file."""

from __future__ import annotations

import base64
import copy
import json
import re

import cv2
import numpy as np
import pytest
from bcf.v2.bcfxml import BcfXml

from sbsc_core.bim import bundled_typings
from sbsc_core.bim.compare import compare
from sbsc_core.bim.compare_outputs import compare_to_dir
from sbsc_core.bim.design import read_as_designed
from sbsc_core.bim.design_writer import write_as_designed_ifc
from tests.bim_fixtures import OBJECTS, detections_document, truth_document

TYPINGS = bundled_typings()


def _design(tmp_path, truth=None, **kw):
    path = tmp_path / "as_designed.ifc"
    res = write_as_designed_ifc(truth or truth_document(), path, typings=TYPINGS, **kw)
    return path, res["design_differences"]


def _near(a, b, tol=1e-3) -> bool:
    return a is not None and b is not None and float(np.linalg.norm(np.asarray(a) - np.asarray(b))) < tol


@pytest.mark.parametrize("seed", [0, 5])
def test_finds_exactly_the_deliberate_differences(tmp_path, seed):
    path, diffs = _design(tmp_path, seed=seed, n_moved=2, n_removed=2, n_added=2)
    doc = detections_document(noise_m=0.01, seed=seed)  # everything built, recognized correctly
    comp = compare(read_as_designed(path, typings=TYPINGS), doc, tolerance_m=0.10)
    findings = comp.findings
    assert len(findings) == len(diffs) == 6
    for d in diffs:
        if d["kind"] == "moved":
            hit = [f for f in findings if f.status == "displaced" and _near(f.designed_position, d["designed_position"])]
            assert len(hit) == 1 and hit[0].detection is not None
            assert hit[0].deviation_m == pytest.approx(d["shift_m"], abs=0.05)
        elif d["kind"] == "added":
            hit = [f for f in findings if f.status == "missing" and _near(f.designed_position, d["designed_position"])]
        else:
            hit = [f for f in findings if f.status == "unexpected" and _near(f.detected_position, d["built_position"], 0.05)]
        assert len(hit) == 1, d
    found = [it for it in comp.items if it.status == "found"]
    assert len(found) == len(OBJECTS) - 4
    assert all(it.deviation_m < 0.05 and it.design_wall == it.detection_wall for it in found)
    assert comp.summary() == {"found": 4, "displaced": 2, "missing": 2, "unexpected": 2, "not_scanned": 0}


def test_recognition_errors_stay_local(tmp_path):
    path, _ = _design(tmp_path, n_moved=0, n_removed=0, n_added=0)
    doc = detections_document(noise_m=0.01)
    doc["detections"][4]["class"] = "radiator"  # the extinguisher taken for a radiator
    del doc["detections"][1]  # the switch not recognized
    doc["detections"][0]["review"]["status"] = "rejected"  # a reviewer rejected the W1 socket
    comp = compare(read_as_designed(path, typings=TYPINGS), doc)
    verdicts = sorted((it.status, it.class_id) for it in comp.findings)
    assert verdicts == [("missing", "fire_extinguisher"), ("missing", "socket_x1"), ("missing", "switch"),
                        ("unexpected", "radiator")]
    assert comp.summary()["found"] == len(OBJECTS) - 3


def test_back_to_back_objects_are_not_paired_through_the_wall(tmp_path):
    truth = truth_document()
    del truth["objects"][0]  # the design lacks the W1 socket ...
    path, _ = _design(tmp_path, truth=truth, n_moved=0, n_removed=0, n_added=0)
    doc = detections_document(objects=OBJECTS[:7])  # ... the scan lacks the W3 socket 0.15 m behind it
    comp = compare(read_as_designed(path, typings=TYPINGS), doc)
    verdicts = sorted((it.status, it.wall) for it in comp.findings)
    assert verdicts == [("missing", "W3"), ("unexpected", "W1")]


def test_objects_on_unscanned_walls_are_not_findings(tmp_path):
    path, _ = _design(tmp_path, n_moved=0, n_removed=0, n_added=0)
    doc = detections_document(objects=[o for o in OBJECTS if o[1] != "W2"])
    doc["walls"] = [w for w in doc["walls"] if w["id"] != "W2"]
    doc["openings"] = [o for o in doc["openings"] if o["wall"] != "W2"]
    comp = compare(read_as_designed(path, typings=TYPINGS), doc)
    assert comp.findings == []
    assert comp.summary()["not_scanned"] == sum(o[1] == "W2" for o in OBJECTS) == 4


def _decode_images(html: str) -> list[np.ndarray]:
    return [cv2.imdecode(np.frombuffer(base64.b64decode(b), np.uint8), cv2.IMREAD_COLOR)
            for b in re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", html)]


def test_compare_to_dir_writes_json_report_and_bcf(tmp_path):
    path, diffs = _design(tmp_path, seed=1, n_moved=1, n_removed=1, n_added=1)
    scan_dir = tmp_path / "scan"
    (scan_dir / "orthoimages").mkdir(parents=True)
    det_path = scan_dir / "detections.json"
    det_path.write_text(json.dumps(detections_document(noise_m=0.005)))
    ortho = np.zeros((540, 1000, 3), np.uint8)
    ortho[:] = (255, 200, 0)  # BGR: an unmistakable colour for W1's orthoimage
    cv2.imwrite(str(scan_dir / "orthoimages" / "W1_colour.png"), ortho)
    out = tmp_path / "cmp"
    comp = compare_to_dir(path, det_path, out, tolerance_m=0.10)
    assert sorted(p.name for p in out.iterdir()) == ["comparison.json", "expected.json", "findings.bcf",
                                                     "report.html"]
    data = json.loads((out / "comparison.json").read_text())
    assert data["schema"] == "sbsc.comparison/1"
    assert data["summary"] == comp.summary() and sum(data["summary"].values()) == len(data["items"])
    assert {it["status"] for it in data["items"]} >= {"found", "displaced", "missing", "unexpected"}
    assert json.loads((out / "expected.json").read_text())["counts"] == comp.design.expected_counts()

    html = (out / "report.html").read_text()
    walls_drawn = re.findall(r"<h2 id=.wall-W\d.>Wall (W\d)</h2>", html)
    images = _decode_images(html)
    assert len(images) == len(walls_drawn) >= 2
    for wid, img in zip(walls_drawn, images, strict=True):
        ratio = img.shape[1] / img.shape[0]
        frame = comp.walls[wid]
        assert ratio == pytest.approx(frame.width_m / frame.height_m, rel=0.02)
        share = np.mean(np.all(img == (255, 200, 0), axis=2))
        assert (share > 0.8) if wid == "W1" else (share == 0.0), wid

    findings = comp.findings
    assert len(findings) == len(diffs) == 3
    with BcfXml.load(out / "findings.bcf") as bcf:
        topics = list(bcf.topics.values())
        assert len(topics) == len(findings)
        titles = sorted(t.topic.title.split()[0] for t in topics)
        assert titles == ["Displaced", "Missing", "Unexpected"]
        design_guids = {f.designed.guid for f in findings if f.designed is not None}
        selected = set()
        for t in topics:
            assert t.header.file[0].filename == "as_designed.ifc"
            assert t.topic.labels[0] in ("missing", "displaced", "unexpected")
            (vp,) = t.viewpoints.values()
            assert vp.snapshot and vp.snapshot.startswith(b"\x89PNG")
            selected |= set(vp.get_selected_guids() or [])
        assert selected == design_guids and len(design_guids) == 2


def test_compare_refuses_bad_tolerance_and_documents(tmp_path):
    from sbsc_core.errors import InputError

    path, _ = _design(tmp_path, n_moved=0, n_removed=0, n_added=0)
    design = read_as_designed(path, typings=TYPINGS)
    with pytest.raises(InputError, match="tolerance"):
        compare(design, detections_document(), tolerance_m=0.0)
    bad = copy.deepcopy(detections_document())
    bad["detections"][3]["position"] = [1.0, "x", 2.0]
    with pytest.raises(InputError, match=r"detections\[3\]\.position"):
        compare(design, bad)


def test_report_lists_the_findings_first_and_labels_never_overlap(tmp_path):
    """Issue 29: the findings come first, each linked to its wall; the header says what was
    compared (never "None"); on the pictures no label covers a box or another label."""
    from sbsc_core.bim.report import _Labels, _overlaps, render_report

    path, _ = _design(tmp_path, n_moved=2, n_removed=2, n_added=2)
    comp = compare(read_as_designed(path, typings=TYPINGS), detections_document(noise_m=0.01, seed=0),
                   tolerance_m=0.10)
    html = render_report(comp)
    findings = html.index("<h2>Findings (6)</h2>")
    assert findings < html.index("<h2 id='wall-")  # before any wall
    assert "Detections: <code>the review project" in html and "None" not in html
    n = comp.summary()
    assert f"({n['found'] + n['displaced'] + n['unexpected']} compared)" in html
    items = re.findall(r"<li><b class='(\w+)'>", html[findings:])
    assert sorted(items) == sorted(["missing"] * 2 + ["displaced"] * 2 + ["unexpected"] * 2)
    for anchor in set(re.findall(r"href='#(wall-[^']+)'", html)):
        assert f"<h2 id='{anchor}'>" in html
    # crowded boxes: five objects side by side, each with a long label
    img = np.full((300, 600, 3), 255, np.uint8)
    labels = _Labels()
    for k in range(5):
        p0, p1 = (200 + 30 * k, 140), (220 + 30 * k, 160)
        labels.box(p0, p1)
        labels.add(f"unexpected fire_alarm_switch_sign {k}", p0, p1, (200, 40, 200))
    placed: list = []
    real_rect = cv2.rectangle

    def spy(im, a, b, colour, thickness, *args):  # noqa: ANN001, ANN202
        if thickness == -1:
            placed.append((a[0], a[1], b[0] + 1, b[1] + 1))
        return real_rect(im, a, b, colour, thickness, *args)

    import sbsc_core.bim.report as rep

    old = rep.cv2.rectangle
    rep.cv2.rectangle = spy
    try:
        labels.draw(img)
    finally:
        rep.cv2.rectangle = old
    assert len(placed) == 5
    for i, a in enumerate(placed):
        assert not any(_overlaps(a, b) for b in labels.boxes), a
        assert not any(_overlaps(a, b) for b in placed[i + 1:]), a
