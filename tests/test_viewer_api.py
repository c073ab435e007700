"""GET /api/projects/{pid}/viewer through the router factory, with a stand-in auth dependency."""

from __future__ import annotations

import urllib.request

import pytest
from fastapi import FastAPI, Header, HTTPException
from fastapi.testclient import TestClient

from app.viewer.api import viewer_router
from app.viewer.backend import InMemoryBackend, ProjectData
from app.viewer.manager import ViewerManager
from app.viewer.scene import SceneSettings
from app.viewer.synthetic import write_synthetic_project


def require_token(authorization: str = Header(default="")) -> str:
    if authorization != "Bearer good":
        raise HTTPException(401, "missing or invalid API token")
    return "alice"


@pytest.fixture()
def client(tmp_path):
    sp = write_synthetic_project(tmp_path / "out", rooms=1, walls_per_room=1, objects_per_wall=1,
                                 points=1000)
    backend = InMemoryBackend()
    backend.add_detection_dir(7, sp.out_dir)
    manager = ViewerManager(backend, settings=SceneSettings(poll_s=0.05))
    app = FastAPI()
    app.state.viewer = manager
    app.include_router(viewer_router(lambda request: request.app.state.viewer, require_token))
    try:
        yield TestClient(app), manager
    finally:
        manager.stop_all()


def test_viewer_url(client):
    http, manager = client
    r = http.get("/api/projects/7/viewer", headers={"Authorization": "Bearer good"})
    assert r.status_code == 200
    url = r.json()["url"]
    assert url == manager.url_for(7) and url.startswith("http://127.0.0.1:")
    manager.wait_ready(7, 30)
    with urllib.request.urlopen(url, timeout=10) as page:  # a browser can open it as it is
        assert page.status == 200 and b"<html" in page.read(4096).lower()
    assert http.get("/api/projects/7/viewer", headers={"Authorization": "Bearer good"}).json()["ready"]


def test_viewer_errors(client):
    http, manager = client
    assert http.get("/api/projects/7/viewer").status_code == 401
    r = http.get("/api/projects/8/viewer", headers={"Authorization": "Bearer good"})
    assert r.status_code == 404 and "project 8" in r.json()["detail"]
    assert manager.running() == []  # nothing started for an unknown project


@pytest.mark.slow
def test_viewer_router_with_manager_object(tmp_path):
    backend = InMemoryBackend()
    backend.add_project(ProjectData(pid=1, name="empty", detections={"schema": "sbsc.detections/1",
                                                                   "walls": [], "openings": [],
                                                                   "detections": []}))
    manager = ViewerManager(backend, host="0.0.0.0", settings=SceneSettings(poll_s=0))
    app = FastAPI()
    app.include_router(viewer_router(manager, lambda: "anyone"))
    try:
        r = TestClient(app).get("/api/projects/1/viewer")
        assert r.status_code == 200 and r.json()["url"].startswith("http://testserver:")
        assert manager.wait_ready(1, 10).status_text().startswith("### empty")
    finally:
        manager.stop_all()
