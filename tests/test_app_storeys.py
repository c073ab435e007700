"""The review app names the storey of each wall and object (issue 12: "progress, logs and the
review app name the storey"): the API documents, the project page, the gallery's storey filter
and the 3D scene's wall labels and object panel."""

from __future__ import annotations

import json
from pathlib import Path

import httpx
import numpy as np
import pytest

from app.config import AppSettings
from app.db import Database
from app.membership import set_member
from app.models import Project
from app.results import job_dict, project_document
from app.sample import ensure_sample_project
from app.users import add_user
from app.viewer.labels import wall_label
from sbsc_core.types import WallFrame

from .app_support import (
    ServerProcess,
    _fake_output,
    auth,
    join,
    served_fake_sample,
    write_small_ply,
)

STOREYS = [{"id": "S1", "floor_z": 0.0, "ceiling_z": 2.5}, {"id": "S2", "floor_z": 2.8, "ceiling_z": 5.3}]


def _two_storey_output(out: Path) -> dict:
    """A finished ``sbsc detect`` output whose wall W01 is on storey S1 and W02 on S2."""
    _fake_output(out, 8, lambda stage, f: None, 0.0)
    doc = json.loads((out / "detections.json").read_text())
    doc["storeys"] = STOREYS
    for w in doc["walls"]:
        w["storey"] = "S1" if w["id"] == "W01" else "S2"
    (out / "detections.json").write_text(json.dumps(doc))
    return doc


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    base = tmp_path_factory.mktemp("storeys")
    settings = AppSettings(data_dir=base / "data", viewer=False)
    doc = _two_storey_output(base / "out")
    pid = ensure_sample_project(write_small_ply(base / "scan.ply", n=200), base / "out", settings=settings,
                                points=200, name="Two storeys")
    return settings, pid, doc


def test_documents_carry_the_storeys(project) -> None:
    settings, pid, doc = project
    db = Database(settings.db_url)
    try:
        with db.read() as s:
            p = s.get(Project, pid)
            served = project_document(s, p)
            from app.models import Job

            job = job_dict(s.get(Job, p.current_job_id))
    finally:
        db.dispose()
    assert served["storeys"] == STOREYS and job["storeys"] == STOREYS
    assert {w["id"]: w["storey"] for w in served["walls"]} == {"W01": "S1", "W02": "S2"}
    assert len(served["detections"]) == len(doc["detections"])


def test_one_storey_documents_stay_as_they_were(tmp_path) -> None:
    served = served_fake_sample(tmp_path, 200)
    assert "storeys" not in served and all("storey" not in w for w in served["walls"])


def test_scene_names_the_storey() -> None:
    f = WallFrame(origin=np.zeros(3), axis_u=np.array([1.0, 0, 0]), axis_v=np.array([0, 0, 1.0]),
                  normal=np.array([0, 1.0, 0]), width_m=4.0, height_m=2.5)
    assert wall_label("S2-W07", f, "S2") == "S2-W07  4.00 m"  # the id carries it
    assert wall_label("W02", f, "S2") == "W02 (S2)  4.00 m"
    assert wall_label("W02", f, None) == "W02  4.00 m"


@pytest.mark.slow
@pytest.mark.browser
def test_gallery_filters_by_storey(project, browser) -> None:
    settings, pid, doc = project
    token = add_user(settings, "sam", "manager")
    join(settings, pid, "sam", "manager")
    server = ServerProcess(settings.data_dir, {"SBSC_VIEWER": "false"}).start()
    page = browser.new_page(viewport={"width": 1440, "height": 900})
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            assert c.get(f"/api/projects/{pid}/detections", headers=auth(token)).json()["storeys"] == STOREYS
        page.goto(server.url + "/index.html")
        page.fill("#token", token)
        page.click("#login-form button[type=submit]")
        page.wait_for_selector("#projects", state="visible")
        page.goto(f"{server.url}/project.html?id={pid}")
        page.wait_for_selector("#counts:has-text('2 storeys: S1 (z 0.00–2.50 m), S2 (z 2.80–5.30 m)')")
        page.goto(f"{server.url}/review.html?id={pid}&storey=S2")
        page.wait_for_selector(".det")
        assert page.locator("#f-storey-box").is_visible()
        on_s2 = [d for d in doc["detections"] if d["wall"] == "W02"]
        assert page.locator(".det").count() == len(on_s2) > 0
        assert page.locator("#p-facts").inner_text().count("S2") >= 1
        page.select_option("#f-storey", "")
        page.wait_for_function(f"() => document.querySelectorAll('.det').length === {len(doc['detections'])}")
        page.select_option("#f-storey", "S1")
        page.wait_for_function(f"() => document.querySelectorAll('.det').length === {len(doc['detections']) - len(on_s2)}")
        assert "(S1)" in page.locator(".det .where").first.inner_text()  # W01 does not carry its storey
    finally:
        page.close()
        server.stop()


EXPECTED_DOC = {"schema": "sbsc.expected/1", "counts": {"socket_x1": 3, "switch": 2},
                "storeys": {"S1": {"socket_x1": 1, "switch": 2}, "S2": {"socket_x1": 2}}}


def test_expected_storeys_are_parsed_and_checked() -> None:
    from app.job_worker import runner_expected
    from app.jobs import parse_expected, parse_expected_storeys
    from sbsc_core.errors import InputError
    from sbsc_core.io.documents import ExpectedCounts

    assert parse_expected(EXPECTED_DOC) == {"socket_x1": 3, "switch": 2}
    assert parse_expected_storeys(EXPECTED_DOC) == EXPECTED_DOC["storeys"]
    assert parse_expected_storeys({"counts": {"switch": 1}}) is None
    assert parse_expected_storeys({"switch": 1}) is None  # bare counts: no storeys
    got = runner_expected(parse_expected(EXPECTED_DOC), parse_expected_storeys(EXPECTED_DOC))
    assert got == ExpectedCounts({"socket_x1": 3, "switch": 2}, EXPECTED_DOC["storeys"])
    assert runner_expected({"switch": 1}, None) == {"switch": 1}
    for bad, where in (({**EXPECTED_DOC, "storeys": {"S1": {"socket_x1": 1}}}, "storeys.*.socket_x1"),
                       ({**EXPECTED_DOC, "storeys": {"first": {"socket_x1": 3, "switch": 2}}}, "storeys.first"),
                       ({**EXPECTED_DOC, "storeys": ["S1"]}, "expected.storeys"),
                       ({**EXPECTED_DOC, "storeys": {"S1": {"socket_x1": -1}}}, "storeys.S1.socket_x1")):
        with pytest.raises(InputError, match=where.replace("*", r"\*")):
            parse_expected_storeys(bad)


def test_job_api_keeps_the_expected_storeys(tmp_path) -> None:
    """Issue 12: a whole expected.json with ``storeys`` reaches the job (and its retry) whole."""
    from fastapi.testclient import TestClient

    from app.job_worker import runner_expected
    from app.models import Job
    from app.server import create_app
    from app.users import create_user

    settings = AppSettings(data_dir=tmp_path / "data", viewer=False)
    _two_storey_output(tmp_path / "out")
    pid = ensure_sample_project(write_small_ply(tmp_path / "scan.ply", n=100), tmp_path / "out",
                                settings=settings, points=100, name="storeys job")
    with TestClient(create_app(settings, start_jobs=False)) as c:
        with c.app.state.db.write() as s:
            _, token = create_user(s, "max", "manager")
            set_member(s, pid, "max", "manager", None)
        r = c.post(f"/api/projects/{pid}/jobs", json={"expected": EXPECTED_DOC}, headers=auth(token))
        assert r.status_code == 202, r.text
        job = r.json()
        assert job["expected"] == EXPECTED_DOC["counts"] and job["expected_storeys"] == EXPECTED_DOC["storeys"]
        assert c.get(f"/api/jobs/{job['id']}", headers=auth(token)).json()["expected_storeys"] == EXPECTED_DOC["storeys"]
        with c.app.state.db.read() as s:
            row = s.get(Job, job["id"])
            assert runner_expected(row.expected, row.expected_storeys).storeys == EXPECTED_DOC["storeys"]
        bad = {**EXPECTED_DOC, "storeys": {"S1": {"socket_x1": 1}}}
        c.delete(f"/api/jobs/{job['id']}", headers=auth(token))
        r = c.post(f"/api/projects/{pid}/jobs", json={"expected": bad}, headers=auth(token))
        assert r.status_code == 422 and "storeys" in r.json()["detail"]
        r = c.post(f"/api/jobs/{job['id']}/retry", headers=auth(token))
        assert r.status_code == 202 and r.json()["expected_storeys"] == EXPECTED_DOC["storeys"]
