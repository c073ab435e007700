"""Ceilings and columns in the review app (issue 11, point 5): a run with ``--ceilings --columns``
imported, served, reviewed, added to and exported like a run on walls only."""

from __future__ import annotations

import io
import math

import ifcopenshell
import ifcopenshell.util.placement
import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.config import AppSettings
from app.membership import set_member
from app.sample import ensure_sample_project
from app.server import create_app
from app.surfaces import point_on
from app.users import create_user

from .app_support import auth, served_fake_sample, write_small_ply
from .surfaces_output import CEILING, SURFACE_OBJECTS, surfaces, write_surfaces_output


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    base = tmp_path_factory.mktemp("surfaces")
    settings = AppSettings(data_dir=base / "data", viewer=False)
    doc = write_surfaces_output(base / "out")
    pid = ensure_sample_project(write_small_ply(base / "scan.ply", n=200), base / "out", settings=settings,
                                points=200, name="Ceilings and columns")
    return settings, pid, doc


@pytest.fixture(scope="module")
def client(project):
    settings, pid, doc = project
    with TestClient(create_app(settings, start_jobs=False)) as c:
        with c.app.state.db.write() as s:
            _, c.token = create_user(s, "rita", "reviewer")
            set_member(s, pid, "rita", "reviewer", None)
        yield c


def _by_ref(served: dict) -> dict[str, dict]:
    return {d["ref"]: d for d in served["detections"]}


def test_surfaces_are_imported_and_served(project, client) -> None:
    settings, pid, doc = project
    served = client.get(f"/api/projects/{pid}/detections", headers=auth(client.token)).json()
    assert [w["id"] for w in served["walls"]] == ["W01", "W02"]
    assert sorted(served["surfaces"], key=lambda s: s["id"]) == sorted(surfaces(), key=lambda s: s["id"])
    round_col = next(s for s in served["surfaces"] if s["id"] == "COL2")
    assert round_col["radius_m"] == 0.25 and round_col["centre"] == [3.0, 2.0] and round_col["column"] == "COL2"
    dets = _by_ref(served)
    for ref, cls, sid, *_ in SURFACE_OBJECTS:
        d = dets[ref]
        assert (d["class"], d["wall"]) == (cls, sid)
        assert d["surface"] == ("ceiling" if sid == "C01" else "column")
    assert "surface" not in dets["D0001"]  # a detection on a wall stays without
    # the document stays a valid contract-4 document (the same check as evaluate and the export)
    from sbsc_core.io.detections_model import parse_detections
    parse_detections(served)


def test_a_walls_only_run_has_no_surfaces(tmp_path) -> None:
    served = served_fake_sample(tmp_path, 100, name="walls")
    assert "surfaces" not in served and all("kind" not in w for w in served["walls"])


def test_point_on_a_round_column_is_on_its_cylinder() -> None:
    col = next(s for s in surfaces() if s["id"] == "COL2")
    for u in (0.0, 0.3, 1.0, 1.5):
        x, y, z = point_on(col, u, 1.2)
        assert math.hypot(x - 3.0, y - 2.0) == pytest.approx(0.25, abs=1e-5) and z == pytest.approx(1.2)
        assert math.atan2(y - 2.0, x - 3.0) % (2 * math.pi) == pytest.approx(u / 0.25 % (2 * math.pi), abs=1e-4)
    assert point_on(CEILING, 1.0, 0.5) == [1.0, 2.5, 2.5]  # axis_v = -y on the ceiling plane


def test_ceiling_and_column_objects_are_reviewed_and_shown(project, client) -> None:
    settings, pid, doc = project
    h = auth(client.token)
    dets = _by_ref(client.get(f"/api/projects/{pid}/detections", headers=h).json())
    for ref in ("D0101", "D0102", "D0103"):
        d = dets[ref]
        r = client.patch(f"/api/detections/{d['id']}", json={"status": "accepted", "version": d["review"]["version"]},
                         headers=h)
        assert r.status_code == 200 and r.json()["review"]["status"] == "accepted"
        assert r.json()["surface"] == d["surface"]
        for kind in ("colour", "depth"):
            t = client.get(f"/api/detections/{d['id']}/thumbnail/{kind}", headers=h)
            assert t.status_code == 200 and io.BytesIO(t.content).read(4) == b"\x89PNG"
    # the whole ceiling orthoimage, where a reviewer clicks to add a missed object
    img = client.get(f"/api/projects/{pid}/walls/C01/image/colour", headers=h)
    assert img.status_code == 200 and img.content[:4] == b"\x89PNG"
    # the thumbnail shows the smoke detector (its colour) in the middle of the crop
    import cv2
    t = client.get(f"/api/detections/{dets['D0101']['id']}/thumbnail/colour", headers=h)
    crop = cv2.imdecode(np.frombuffer(t.content, np.uint8), cv2.IMREAD_COLOR)
    assert crop is not None and crop.shape[0] > 10


def test_moving_an_object_on_a_round_column_keeps_it_on_the_cylinder(project, client) -> None:
    settings, pid, doc = project
    h = auth(client.token)
    d = _by_ref(client.get(f"/api/projects/{pid}/detections", headers=h).json())["D0103"]
    r = client.patch(f"/api/detections/{d['id']}", json={"u": 1.0, "v": 0.5, "version": d["review"]["version"]},
                     headers=h)
    assert r.status_code == 200, r.text
    x, y, z = r.json()["position"]
    assert math.hypot(x - 3.0, y - 2.0) == pytest.approx(0.25, abs=1e-4) and z == pytest.approx(0.5)
    r = client.patch(f"/api/detections/{d['id']}", json={"u": 2.0, "version": r.json()["review"]["version"]},
                     headers=h)  # the round face is 2 pi r = 1.571 m round
    assert r.status_code == 422 and "outside column COL2" in r.json()["detail"]


def test_adding_a_missed_object_on_a_ceiling_and_a_column(project, client) -> None:
    settings, pid, doc = project
    h = auth(client.token)
    r = client.post(f"/api/projects/{pid}/detections", headers=h,
                    json={"class": "smoke_detector", "wall": "C01", "u": 3.2, "v": 0.8, "snap": False})
    assert r.status_code == 201, r.text
    added = r.json()
    assert added["surface"] == "ceiling" and added["source"] == "reviewer"
    assert added["review"]["status"] == "accepted"
    assert added["position"] == pytest.approx([3.2, 2.2, 2.5])  # on the ceiling plane
    r = client.post(f"/api/projects/{pid}/detections", headers=h,
                    json={"class": "fire_extinguisher", "wall": "COL1-E", "u": 0.2, "v": 0.6})
    assert r.status_code == 201, r.text
    assert r.json()["surface"] == "column" and r.json()["position"][0] == pytest.approx(1.2)
    r = client.post(f"/api/projects/{pid}/detections", headers=h,
                    json={"class": "socket_x1", "wall": "COL2", "u": 0.0, "v": 0.3, "snap": False})
    assert r.status_code == 201 and r.json()["position"] == pytest.approx([3.25, 2.0, 0.3])
    bad = client.post(f"/api/projects/{pid}/detections", headers=h,
                      json={"class": "smoke_detector", "wall": "C01", "u": 4.5, "v": 0.8})
    assert bad.status_code == 422 and "outside ceiling C01" in bad.json()["detail"]
    served = client.get(f"/api/projects/{pid}/detections", headers=h).json()
    assert sum(d["source"] == "reviewer" and bool(d.get("surface")) for d in served["detections"]) == 3


def test_a_class_goes_only_on_the_surfaces_its_model_lists(project, client) -> None:
    """model.json ``mount``: no radiator on a ceiling, no smoke detector on a column, added or relabelled."""
    settings, pid, doc = project
    h = auth(client.token)
    before = client.get(f"/api/projects/{pid}/detections", headers=h).json()
    for cls, sid, kind in (("radiator", "C01", "ceiling"), ("smoke_detector", "COL1-E", "column")):
        r = client.post(f"/api/projects/{pid}/detections", headers=h,
                        json={"class": cls, "wall": sid, "u": 0.2, "v": 0.5, "snap": False})
        assert r.status_code == 422, r.text
        assert r.json()["detail"].startswith(f"class: '{cls}' is mounted on wall") and f"not on {kind} {sid}" in r.json()["detail"]
    d = _by_ref(before)["D0101"]  # the smoke detector on the ceiling
    r = client.patch(f"/api/detections/{d['id']}", json={"class": "radiator", "version": d["review"]["version"]},
                     headers=h)
    assert r.status_code == 422 and "not on ceiling C01" in r.json()["detail"]
    r = client.patch(f"/api/detections/{d['id']}", json={"class": "exit_light", "version": d["review"]["version"]},
                     headers=h)  # also a ceiling class
    assert r.status_code == 200 and r.json()["class"] == "exit_light"
    after = client.get(f"/api/projects/{pid}/detections", headers=h).json()
    assert len(after["detections"]) == len(before["detections"])  # nothing was added by the refused calls


def test_export_of_ceiling_and_column_objects(project, client, tmp_path) -> None:
    settings, pid, doc = project
    h = auth(client.token)
    served = client.get(f"/api/projects/{pid}/detections", headers=h).json()
    pending = [d["id"] for d in served["detections"] if d.get("surface") and d["review"]["status"] == "pending"]
    if pending:
        assert client.post(f"/api/projects/{pid}/decisions", headers=h,
                           json={"status": "accepted", "ids": pending}).status_code == 200
    served = client.get(f"/api/projects/{pid}/detections", headers=h).json()
    on_surfaces = [d for d in served["detections"] if d.get("surface") and d["review"]["status"] == "accepted"]
    assert len(on_surfaces) >= len(SURFACE_OBJECTS)
    r = client.get(f"/api/projects/{pid}/export.ifc", headers=h)
    assert r.status_code == 200, r.text  # not 422 "unknown wall"
    path = tmp_path / "export.ifc"
    path.write_bytes(r.content)
    model = ifcopenshell.open(str(path))
    objects = {e.Tag: e for e in model.by_type("IfcElement") if getattr(e, "Tag", None)}
    hosts = {c.Tag: c for c in [*model.by_type("IfcCovering"), *model.by_type("IfcColumn")]}

    by_id = {sf["id"]: sf for sf in served["surfaces"]}
    for d in on_surfaces:
        el = objects[d["ref"]]
        at = ifcopenshell.util.placement.get_local_placement(el.ObjectPlacement)[:3, 3]
        assert np.linalg.norm(at - np.asarray(d["position"])) <= 0.001  # back within 1 mm
        sf = by_id[d["wall"]]
        host = hosts.get(sf["id"] if sf["kind"] == "ceiling" else sf.get("column"))
        assert host is not None  # an IfcCovering per ceiling, an IfcColumn per column
        assert el.ObjectPlacement.PlacementRelTo == host.ObjectPlacement  # placed relative to it
    js = client.get(f"/api/projects/{pid}/export.json", headers=h).json()
    assert len(js["surfaces"]) == len(surfaces())


def test_old_databases_upgrade(tmp_path) -> None:
    """A database of the previous schema (0004) upgrades to surfaces; its walls stay walls."""
    from alembic import command
    from sqlalchemy import inspect

    from app.db import Database, alembic_config

    db = Database(f"sqlite:///{tmp_path / 't.db'}")
    try:
        cfg = alembic_config(db.url)
        with db.engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "0004")
            conn.exec_driver_sql("INSERT INTO projects (name, status, created_at) VALUES ('p', 'open', '2026-01-01')")
            command.upgrade(cfg, "head")
        cols = {c["name"] for c in inspect(db.engine).get_columns("walls")}
        jcols = {c["name"] for c in inspect(db.engine).get_columns("jobs")}
        assert {"kind", "extra"} <= cols and "expected_storeys" in jcols
        with db.engine.begin() as conn:
            cfg.attributes["connection"] = conn
            command.downgrade(cfg, "0004")
        assert "kind" not in {c["name"] for c in inspect(db.engine).get_columns("walls")}
    finally:
        db.dispose()
