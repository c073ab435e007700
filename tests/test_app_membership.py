"""Projects belong to their members (issue 30): every route under a project is a 404 for a user
of another project, roles in a project are capped by the global role, membership is managed by
REST and by ``sbsc user``, audited, and the migration makes existing creators members."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from app.auth import create_user
from app.config import AppSettings
from app.db import Database, alembic_config, upgrade
from app.models import Project, ProjectEvent, SuggestionRow
from app.sample import ensure_sample_project
from app.server import create_app

from .app_support import _fake_output, write_small_ply

# routes that need no project: checked on their own below
OUTSIDE = {"/api/health", "/api/me", "/api/users", "/api/projects", "/api/session", "/api/scan-formats"}
ADMIN_ONLY = {"/api/admin/jobs/{jid}/log", "/api/projects/{pid}/reopen"}


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Project A (with results, a suggestion and a viewer member) and project B of an outsider."""
    tmp = tmp_path_factory.mktemp("members")
    settings = AppSettings(data_dir=tmp / "d", viewer=True, viewer_idle_s=5.0)
    out = tmp / "out"
    _fake_output(out, 5, lambda s, f: None, 0.0)
    pid = ensure_sample_project(write_small_ply(tmp / "scan.ply", n=321), out, settings=settings)
    with TestClient(create_app(settings, start_jobs=False)) as client:
        db = client.app.state.db
        tokens = {}
        with db.write() as s:
            for name, role in (("ada", "admin"), ("olga", "manager"), ("vic", "manager"), ("rita", "reviewer")):
                tokens[name] = create_user(s, name, role)[1]
            p = s.get(Project, pid)
            s.add(SuggestionRow(project_id=pid, job_id=p.current_job_id, class_id="socket_x1", wall_key="W01",
                                u=1.0, v=0.3, width_m=0.08, height_m=0.08, source="depth", score=0.5,
                                reason="below_threshold"))
        h = {n: {"Authorization": f"Bearer {t}"} for n, t in tokens.items()}
        # olga (a manager) creates B; ada makes vic a viewer of A
        other = client.post("/api/projects", json={"name": "B"}, headers=h["olga"]).json()["id"]
        r = client.post(f"/api/projects/{pid}/members", json={"user": "vic", "role": "viewer"}, headers=h["ada"])
        assert r.status_code == 201, r.text
        job = client.get(f"/api/projects/{pid}", headers=h["ada"]).json()["jobs"][0]["id"]
        doc = client.get(f"/api/projects/{pid}/detections", headers=h["ada"]).json()
        sid = client.get(f"/api/projects/{pid}/suggestions", headers=h["ada"]).json()[0]["id"]
        ids = {"pid": pid, "jid": job, "did": doc["detections"][0]["id"], "sid": sid,
               "wall": doc["walls"][0]["id"], "kind": "colour", "user": "vic", "class_id": "switch"}
        yield client, h, ids, other


def _operations(client: TestClient):
    spec = client.get("/openapi.json").json()
    for path, item in spec["paths"].items():
        for method in item:
            if method in ("get", "post", "patch", "put", "delete"):
                yield path, method.upper()


def _call(client, method, path, ids, headers):  # noqa: ANN001, ANN202
    url = re.sub(r"\{(\w+)\}", lambda m: str(ids[m.group(1)]), path)
    body = {} if method in ("POST", "PATCH", "PUT") else None
    return client.request(method, url, json=body, headers=headers)


def test_every_route_under_a_project_is_404_for_a_user_of_another_project(world):
    client, h, ids, _ = world
    walked = 0
    for path, method in _operations(client):
        if path in OUTSIDE:
            continue
        r = _call(client, method, path, ids, h["olga"])
        if path in ADMIN_ONLY:  # a role limit of the route itself, for members too
            assert r.status_code in (403, 404), (method, path, r.status_code, r.text)
        else:
            assert r.status_code == 404, (method, path, r.status_code, r.text)
            assert r.json()["detail"].endswith("not found"), (method, path, r.text)
        walked += 1
    assert walked >= 35  # every project route, its jobs, detections, files, exports and the 3D scene
    # the same routes answer the admin (a member of every project): none is a 404 of membership
    for path in ("/api/projects/{pid}", "/api/jobs/{jid}/log", "/api/detections/{did}",
                 "/api/projects/{pid}/export.json"):
        assert _call(client, "GET", path, ids, h["ada"]).status_code == 200, path


def test_a_viewer_reads_but_may_not_change(world):
    client, h, ids, _ = world
    for path, method in _operations(client):
        if path in OUTSIDE or path == "/api/admin/jobs/{jid}/log" or path.endswith("/viewer"):
            continue
        r = _call(client, method, path, ids, h["vic"])
        if method == "GET":
            refused = r.status_code in (401, 403) or (r.status_code == 404 and r.json()["detail"].endswith("not found"))
            assert not refused, (method, path, r.status_code, r.text)
        else:  # vic is a manager in general, but only a viewer here
            assert r.status_code == 403, (method, path, r.status_code, r.text)


def test_project_list_creator_roles_and_audit(world):
    client, h, ids, other = world
    pid = ids["pid"]
    assert [p["id"] for p in client.get("/api/projects", headers=h["olga"]).json()] == [other]
    assert [p["id"] for p in client.get("/api/projects", headers=h["vic"]).json()] == [pid]
    assert {p["id"] for p in client.get("/api/projects", headers=h["ada"]).json()} == {pid, other}
    assert client.get(f"/api/projects/{other}/members", headers=h["olga"]).json() == [
        {"user": "olga", "role": "manager"}]
    # a manager of B manages B's members; the global role caps the project role
    r = client.post(f"/api/projects/{other}/members", json={"user": "rita", "role": "manager"}, headers=h["olga"])
    assert r.status_code == 422 and "at most" in r.json()["detail"]
    r = client.post(f"/api/projects/{other}/members", json={"user": "nobody", "role": "viewer"}, headers=h["olga"])
    assert r.status_code == 404
    r = client.post(f"/api/projects/{other}/members", json={"user": "rita", "role": "reviewer"}, headers=h["olga"])
    assert r.status_code == 201 and r.json() == {"user": "rita", "role": "reviewer"}
    assert client.get(f"/api/projects/{other}", headers=h["rita"]).status_code == 200
    # rita, a reviewer of B, may not manage its members; olga removes her again
    r = client.post(f"/api/projects/{other}/members", json={"user": "vic", "role": "viewer"}, headers=h["rita"])
    assert r.status_code == 403
    assert client.delete(f"/api/projects/{other}/members/rita", headers=h["olga"]).status_code == 200
    assert client.get(f"/api/projects/{other}", headers=h["rita"]).status_code == 404
    assert client.delete(f"/api/projects/{other}/members/rita", headers=h["olga"]).status_code == 404
    events = client.get(f"/api/projects/{other}/events", headers=h["olga"]).json()
    kinds = [(e["kind"], e.get("data", {}).get("user")) for e in events if e["kind"].startswith("member_")]
    assert kinds.count(("member_added", "rita")) == 1 and kinds.count(("member_removed", "rita")) == 1
    with client.app.state.db.read() as s:
        by = {e.kind: e.user_name for e in s.scalars(select(ProjectEvent).where(ProjectEvent.project_id == other))}
    assert by["member_added"] == "olga" and by["member_removed"] == "olga"


@pytest.mark.slow
def test_sbsc_user_adds_and_removes_members(world, tmp_path):
    data = tmp_path / "d"
    settings = AppSettings(data_dir=data)
    settings.ensure_dirs()
    db = Database(settings.db_url)
    upgrade(db)
    with db.write() as s:
        create_user(s, "rob", "reviewer")
        s.add(Project(name="P", status="open", created_by="x"))
    db.dispose()
    env = {"SBSC_DATA_DIR": str(data), "PYTHONPATH": str(__import__("pathlib").Path.cwd())}

    def sbsc(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "app", "user", *args], capture_output=True, text=True,
                              env={**__import__("os").environ, **env}, timeout=120)

    r = sbsc("add-member", "rob", "1", "--role", "reviewer")
    assert r.returncode == 0 and "reviewer of project 1" in r.stdout, r.stderr
    r = sbsc("add-member", "rob", "1", "--role", "manager")
    assert r.returncode != 0 and "at most" in r.stderr and "Traceback" not in r.stderr
    r = sbsc("add-member", "rob", "7", "--role", "viewer")
    assert r.returncode != 0 and "project 7 not found" in r.stderr
    r = sbsc("remove-member", "rob", "1")
    assert r.returncode == 0 and "no longer a member" in r.stdout
    r = sbsc("add-member", "rob", "x", "--role", "viewer")
    assert r.returncode == 2


def test_migration_makes_creators_members(tmp_path):
    from alembic import command

    db = Database(f"sqlite:///{tmp_path / 'm.db'}")
    cfg = alembic_config(db.url)
    with db.engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "0005")
        conn.exec_driver_sql("INSERT INTO users (name, role, token_hash, created_at, disabled) VALUES "
                             "('mo', 'manager', 'a', CURRENT_TIMESTAMP, 0), "
                             "('re', 'reviewer', 'b', CURRENT_TIMESTAMP, 0), "
                             "('ad', 'admin', 'c', CURRENT_TIMESTAMP, 0)")
        conn.exec_driver_sql("INSERT INTO projects (name, status, created_at, created_by) VALUES "
                             "('p1', 'open', CURRENT_TIMESTAMP, 'mo'), ('p2', 'open', CURRENT_TIMESTAMP, 're'), "
                             "('p3', 'open', CURRENT_TIMESTAMP, 'ad'), ('p4', 'open', CURRENT_TIMESTAMP, 'gone')")
    upgrade(db)
    with db.engine.connect() as conn:
        rows = conn.exec_driver_sql("SELECT project_id, user_id, role FROM project_members "
                                    "ORDER BY project_id").all()
    db.dispose()
    assert [tuple(r) for r in rows] == [(1, 1, "manager"), (2, 2, "reviewer")]
