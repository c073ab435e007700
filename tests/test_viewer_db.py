"""The scene on the review service's database: one set of decisions for the scene and REST."""

from __future__ import annotations

import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from app.auth import create_user
from app.config import AppSettings
from app.membership import set_member
from app.models import ReviewDecision
from app.sample import ensure_sample_project
from app.server import create_app
from app.viewer.backend import Locked, NotFound, NotReady, StaleVersion
from app.viewer.db_backend import DbReviewBackend
from app.viewer.labels import STATUS_RGB
from app.viewer.manager import ViewerManager
from app.viewer.scene import SceneSettings
from app.viewer.synthetic import write_synthetic_project

from .viewer_support import FakeTab, wait_for

pytestmark = pytest.mark.slow


@pytest.fixture()
def service(tmp_path):
    sp = write_synthetic_project(tmp_path / "run", rooms=1, walls_per_room=2, objects_per_wall=2,
                                 points=5000)
    settings = AppSettings(data_dir=tmp_path / "data", static_dir=tmp_path / "no_static")
    app = create_app(settings, start_jobs=False)
    with TestClient(app) as http:
        db = app.state.db
        with db.write() as s:
            _, rita = create_user(s, "rita", "reviewer")
            _, mona = create_user(s, "mona", "manager")
        pid = ensure_sample_project(sp.scan, sp.out_dir, settings=settings, points=5000,
                                    name="viewer db test")
        with db.write() as s:  # projects belong to their members
            set_member(s, pid, "rita", "reviewer", None)
            set_member(s, pid, "mona", "manager", None)
        backend = DbReviewBackend(db, settings)
        manager = ViewerManager(backend, settings=SceneSettings(poll_s=0.1, fly_s=0.02, fly_steps=2))
        try:
            yield http, backend, manager, pid, {"rita": rita, "mona": mona}
        finally:
            manager.stop_all()


def auth(token: str) -> dict:
    return {"Authorization": f"Bearer {token}"}


def test_scene_and_rest_share_decisions(service):
    http, backend, manager, pid, tokens = service
    scene = manager.wait_ready(pid, 30)
    rest = http.get(f"/api/projects/{pid}/detections", headers=auth(tokens["rita"])).json()
    assert set(scene.spots) == {d["id"] for d in rest["detections"]} and len(scene.spots) == 4
    for d in rest["detections"]:
        assert np.allclose(scene.spots[d["id"]].position + scene.centre, d["position"])
    assert scene.nodes.get("rois_depth/W01") is not None and "images_colour/W01" in scene.nodes
    assert scene.data.scans and scene.lod is not None

    tab = FakeTab(manager.viewer(pid).port)
    try:
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        first = rest["detections"][0]
        tab.click_node(f"/spots/{first['id']}")
        wait_for(lambda: session.selected == first["id"], what="selection")
        tab.set_gui(session.ui_token, tokens["rita"])
        tab.press(session.ui_sign_in)
        wait_for(lambda: session.user is not None and not session.ui_accept.disabled, what="sign-in")
        tab.press(session.ui_accept)

        def audit_row():
            with backend.db.read() as s:
                return s.scalars(select(ReviewDecision)).first()

        row = wait_for(audit_row, what="audit row")
        assert row.user_name == "rita" and row.action == "accept" and row.version_to == 2
        got = http.get(f"/api/detections/{first['id']}", headers=auth(tokens["rita"])).json()
        assert got["review"]["status"] == "accepted" and got["review"]["by"] == "rita"

        # a REST decision shows in the scene within a second
        second = rest["detections"][1]
        t0 = time.monotonic()
        r = http.patch(f"/api/detections/{second['id']}", headers=auth(tokens["mona"]),
                       json={"status": "rejected", "version": 1})
        assert r.status_code == 200
        wait_for(lambda: tuple(scene.spots[second["id"]].color) == STATUS_RGB["rejected"], 1.0,
                 "REST decision in the scene")
        print(f"REST -> scene: {time.monotonic() - t0:.3f} s")
        # the scene's stale version answers 409 like the REST API does
        with pytest.raises(StaleVersion) as exc:
            backend.decide(pid, second["id"], "accepted", None, 1, session.user)
        assert exc.value.current["review"]["by"] == "mona"
        with pytest.raises(NotFound):
            backend.decide(pid + 1, second["id"], "accepted", None, 2, session.user)

        # sign-off through REST: the scene becomes read-only and says so
        for d in rest["detections"][2:]:
            assert http.patch(f"/api/detections/{d['id']}", headers=auth(tokens["rita"]),
                              json={"status": "accepted", "version": 1}).status_code == 200
        r = http.post(f"/api/projects/{pid}/signoff", headers=auth(tokens["mona"]),
                      json={"comment": "ok"})
        assert r.status_code == 200, r.text
        wait_for(lambda: scene.locked, 1.5, "lock")
        assert "read-only" in scene.status_text() and "mona" in scene.status_text()
        wait_for(lambda: session.ui_accept.disabled)
        with pytest.raises(Locked):
            backend.decide(pid, second["id"], "accepted", None, 2, session.user)
    finally:
        tab.close()


def test_unknown_and_empty_projects(service):
    http, backend, manager, pid, tokens = service
    with pytest.raises(NotFound):
        manager.url_for(pid + 99)
    r = http.post("/api/projects", headers=auth(tokens["rita"]), json={"name": "empty"})
    with pytest.raises(NotReady):
        manager.url_for(r.json()["id"])
    assert backend.resolve_token("sbsc_nope") is None
    assert backend.resolve_token(tokens["rita"]).role == "reviewer"
