"""The review app's as-designed model: IFC upload, comparison JSON, HTML report and BCF.

The project's results are the hand-written room of ``tests/bim_fixtures`` (every
object built and detected); the design is written from the same room with deliberate
differences (two moved, two left out, two added), which the comparison must report.
"""

from __future__ import annotations

import io
import json
import zipfile

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.auth import create_user
from app.config import AppSettings
from app.membership import set_member
from app.models import DesignRow, Project
from app.sample import ensure_sample_project
from app.server import create_app
from sbsc_core.bim.design_writer import write_as_designed_ifc

from .app_support import write_small_ply
from .bim_fixtures import HEIGHT, OBJECTS, detections_document, truth_document

PIXEL_M = 0.01


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    base = tmp_path_factory.mktemp("app_design")
    out = base / "out"
    (out / "orthoimages").mkdir(parents=True)
    doc = detections_document()
    for d in doc["detections"]:
        del d["review"]  # as the pipeline writes it: not reviewed yet
    (out / "detections.json").write_text(json.dumps(doc))
    colour = np.full((int(HEIGHT / PIXEL_M), int(5.0 / PIXEL_M), 3), (185, 200, 205), np.uint8)
    cv2.imwrite(str(out / "orthoimages" / "W1_colour.png"), colour)
    settings = AppSettings(data_dir=base / "data", viewer=False)
    pid = ensure_sample_project(write_small_ply(base / "scan.ply", n=100), out, settings=settings,
                                name="Room", points=100)
    design = base / "as_designed.ifc"
    diffs = write_as_designed_ifc(truth_document(), design, seed=0, n_moved=2, n_removed=2,
                                  n_added=2)["design_differences"]
    with TestClient(create_app(settings, start_jobs=False)) as client:
        with client.app.state.db.write() as s:
            _, token = create_user(s, "rita", "reviewer")
            set_member(s, pid, "rita", "reviewer", None)
        yield {"client": client, "pid": pid, "h": {"Authorization": f"Bearer {token}"},
               "design": design, "diffs": diffs, "settings": settings}


def _upload(env, name: str, data: bytes, headers=None):  # noqa: ANN001, ANN202
    return env["client"].post(f"/api/projects/{env['pid']}/design", files={"file": (name, data)},
                              headers=env["h"] if headers is None else headers)


def _stored(env) -> list:  # noqa: ANN001
    d = env["settings"].projects_dir / str(env["pid"]) / "design"
    return sorted(d.iterdir()) if d.is_dir() else []


def test_design_upload_and_comparison(env):
    c, pid, h = env["client"], env["pid"], env["h"]
    # no token, no design yet, bad files
    assert _upload(env, "d.ifc", env["design"].read_bytes(), headers={}).status_code == 401
    assert c.get(f"/api/projects/{pid}/comparison").status_code == 401
    r = c.get(f"/api/projects/{pid}/comparison", headers=h)
    assert r.status_code == 404 and "no as-designed model" in r.json()["detail"]
    for name, data in [("garbage.ifc", b"hello, not a model\n" * 50),
                       ("cut.ifc", env["design"].read_bytes()[:2000])]:
        r = _upload(env, name, data)
        assert r.status_code == 422, r.text
        detail = r.json()["detail"]
        assert detail.startswith(f"{name}: ") and "\n" not in detail and "/tmp" not in detail, detail
    assert _upload(env, "design.txt", b"x").status_code == 415
    assert _stored(env) == [] and not any(env["settings"].tmp_dir.iterdir())

    # upload the design
    r = _upload(env, "as designed.ifc", env["design"].read_bytes())
    assert r.status_code == 201, r.text
    up = r.json()
    n_designed = len(OBJECTS) - 2 + 2
    assert up["filename"] == "as_designed.ifc" and up["objects"] == n_designed
    assert sum(up["expected_counts"].values()) == n_designed
    assert len(_stored(env)) == 1
    assert c.get(f"/api/projects/{pid}", headers=h).json()["design"]["objects"] == n_designed

    # the comparison finds exactly the deliberate differences
    comp = c.get(f"/api/projects/{pid}/comparison", headers=h).json()
    assert comp["schema"] == "sbsc.comparison/1" and comp["as_designed"] == "as_designed.ifc"
    assert comp["summary"] == {"found": len(OBJECTS) - 4, "displaced": 2, "missing": 2,
                               "unexpected": 2, "not_scanned": 0}
    assert sum(comp["summary"].values()) == len(comp["items"])
    moved = sorted(d["class"] for d in env["diffs"] if d["kind"] == "moved")
    assert sorted(it["class"] for it in comp["items"] if it["status"] == "displaced") == moved
    added = sorted(d["class"] for d in env["diffs"] if d["kind"] == "added")
    assert sorted(it["class"] for it in comp["items"] if it["status"] == "missing") == added

    # report and BCF
    r = c.get(f"/api/projects/{pid}/comparison.html", headers=h)
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    assert "<html" in r.text.lower() and "data:image/png;base64," in r.text
    r = c.get(f"/api/projects/{pid}/comparison.bcf", headers=h)
    assert r.status_code == 200 and "findings.bcf" in r.headers["content-disposition"]
    with zipfile.ZipFile(io.BytesIO(r.content)) as zf:
        markups = [n for n in zf.namelist() if n.endswith("markup.bcf")]
    assert len(markups) == 6  # one topic per finding
    assert c.get(f"/api/projects/{pid}/comparison.bcf").status_code == 401
    assert not any(env["settings"].tmp_dir.iterdir())

    # rejecting a detection that matched a design object makes that object missing
    doc = c.get(f"/api/projects/{pid}/detections", headers=h).json()
    found = next(it for it in comp["items"] if it["status"] == "found")
    det = next(d for d in doc["detections"] if d["ref"] == found["detection"]["id"])
    r = c.patch(f"/api/detections/{det['id']}", headers=h,
                json={"status": "rejected", "version": det["review"]["version"]})
    assert r.status_code == 200, r.text
    after = c.get(f"/api/projects/{pid}/comparison", headers=h).json()["summary"]
    assert after["found"] == comp["summary"]["found"] - 1
    assert after["missing"] == comp["summary"]["missing"] + 1

    # signed-off projects take no new design
    with c.app.state.db.write() as s:
        s.get(Project, pid).status = "signed_off"
    assert _upload(env, "d.ifc", env["design"].read_bytes()).status_code == 423
    with c.app.state.db.read() as s:
        assert s.query(DesignRow).count() == 1
    assert len(_stored(env)) == 1


def test_exports_keep_their_globalids_and_every_bcf_topic_selects_an_element(env, tmp_path):
    """Issue 29: two exports of the same reviewed project give the same GlobalIds; every BCF
    topic selects an element of the as-designed or of the as-is IFC, named in its header;
    topic types come from the BCF's extension list; dates carry a time zone."""
    import ifcopenshell
    from lxml import etree

    c, pid, h = env["client"], env["pid"], env["h"]
    if c.get(f"/api/projects/{pid}/comparison", headers=h).status_code == 404:
        assert _upload(env, "as_designed.ifc", env["design"].read_bytes()).status_code == 201
    with c.app.state.db.write() as s:  # the test before left it signed off by hand, with pending objects
        s.get(Project, pid).status = "open"
    r = c.post(f"/api/projects/{pid}/decisions", json={"status": "accepted", "filter": {"review": "pending"}},
               headers=h)
    assert r.status_code == 200, r.text
    files = []
    for k in range(2):
        r = c.get(f"/api/projects/{pid}/export.ifc", headers=h)
        assert r.status_code == 200
        assert r.headers["content-disposition"] == f'attachment; filename="Room-{pid}.ifc"'
        (tmp_path / f"asis{k}.ifc").write_bytes(r.content)
        files.append(ifcopenshell.open(str(tmp_path / f"asis{k}.ifc")))
    first, second = ({e.Tag: e.GlobalId for e in f.by_type("IfcElement") if e.Tag} for f in files)
    assert first and first == second  # the same object, the same GlobalId
    assert {e.GlobalId for e in files[0].by_type("IfcRoot")} == {e.GlobalId for e in files[1].by_type("IfcRoot")}
    assert len({e.GlobalId for e in files[0].by_type("IfcRoot")}) == len(files[0].by_type("IfcRoot"))
    asis = files[0]
    assert asis.by_type("IfcProject")[0].Name == "Room"
    header = asis.header.file_name
    assert header.name == f"Room-{pid}.ifc" and header.author == ("rita",) and "sbsc" in header.originating_system
    design = ifcopenshell.open(str(env["design"]))
    held = {f"Room-{pid}.ifc": {e.GlobalId for e in asis.by_type("IfcRoot")},
            "as_designed.ifc": {e.GlobalId for e in design.by_type("IfcRoot")}}
    r = c.get(f"/api/projects/{pid}/comparison.bcf", headers=h)
    assert r.status_code == 200
    with zipfile.ZipFile(io.BytesIO(r.content)) as z:
        names = z.namelist()
        project = etree.fromstring(z.read("project.bcfp"))
        xsd_name = project.findtext("ExtensionSchema")
        assert xsd_name in names
        types = etree.fromstring(z.read(xsd_name)).xpath(
            "//xs:simpleType[@name='TopicType']//xs:enumeration/@value",
            namespaces={"xs": "http://www.w3.org/2001/XMLSchema"})
        assert sorted(types) == ["Displaced", "Missing", "Unexpected"]
        kinds = set()
        for name in (n for n in names if n.endswith("markup.bcf")):
            markup = etree.fromstring(z.read(name))
            topic = markup.find("Topic")
            kind = topic.get("TopicType")
            assert kind in types
            kinds.add(kind)
            date = topic.findtext("CreationDate")
            assert date.endswith(("Z", "+00:00")), date  # with its time zone
            header_files = [f.findtext("Filename") for f in markup.findall("Header/File")]
            assert header_files and all(f in held for f in header_files)
            vp = markup.findtext("Viewpoints/Viewpoint")
            viewpoint = etree.fromstring(z.read(name.replace("markup.bcf", vp)))
            selected = [comp.get("IfcGuid") for comp in viewpoint.findall("Components/Selection/Component")]
            assert selected, f"{kind} topic selects nothing"
            for guid in selected:  # each selected element is in a file the topic names
                assert any(guid in held[f] for f in header_files), (kind, guid, header_files)
            if kind == "Unexpected":
                assert header_files == [f"Room-{pid}.ifc"]
    assert kinds == {"Missing", "Displaced", "Unexpected"}
