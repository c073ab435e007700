"""The review app's REST API against a real uvicorn server, with a fake detection runner.

Covers uploads and their refusals, tokens and roles, review decisions with optimistic
concurrency, the audit trail, sign-off and its lock, and jobs that fail, are retried,
lose their worker process or their server.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import sqlite3
import threading
import time
from pathlib import Path

import httpx
import pytest

from app.config import AppSettings
from app.users import add_user

from .app_support import (
    ServerProcess,
    auth,
    db_rows_at,
    fake_control,
    pid_alive,
    server_with_users,
    wait_job,
    worker_pid,
    write_library_zip,
    write_small_ply,
)

pytestmark = pytest.mark.slow

RUNNER = "tests.app_support:fake_detect_to_dir"
LIMIT = 1 << 20  # scan size limit of the shared server


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    server = server_with_users(tmp_path_factory.mktemp("app_api"),
                               [("rita", "reviewer"), ("rob", "reviewer"), ("max", "manager"), ("ada", "admin")],
                               {"SBSC_JOB_RUNNER": RUNNER, "SBSC_MAX_SCAN_BYTES": str(LIMIT),
                                "SBSC_MAX_MODELS_ZIP_BYTES": str(LIMIT), "SBSC_UPLOAD_DRAIN_BYTES": str(4 * LIMIT)})
    fake_control(server.data, mode="ok", delay_s=0.2, detections=6)
    yield server
    server.stop()


@pytest.fixture()
def client(srv):
    with httpx.Client(base_url=srv.url, timeout=60) as c:
        yield c


def new_project(c: httpx.Client, token: str, name: str = "P") -> int:
    r = c.post("/api/projects", json={"name": name}, headers=auth(token))
    assert r.status_code == 201, r.text
    assert r.json()["status"] == "open"
    return r.json()["id"]


def upload_scan(c, token, pid, path: Path):  # noqa: ANN001, ANN201
    with open(path, "rb") as fh:
        return c.post(f"/api/projects/{pid}/scans", files={"file": (path.name, fh)}, headers=auth(token))


def share(c, srv, pid: int) -> None:  # noqa: ANN001
    """Make the test's other users members of project ``pid`` with their global role."""
    for name, role in (("rita", "reviewer"), ("rob", "reviewer"), ("max", "manager")):
        r = c.post(f"/api/projects/{pid}/members", json={"user": name, "role": role},
                   headers=auth(srv.tokens["ada"]))
        assert r.status_code == 201, r.text


def project_with_results(c, srv, name="P", detections=6) -> tuple[int, dict]:  # noqa: ANN001
    tok = srv.tokens["rita"]
    pid = new_project(c, tok, name)
    share(c, srv, pid)
    r = upload_scan(c, tok, pid, write_small_ply(srv.base / f"{name}.ply"))
    assert r.status_code == 201, r.text
    fake_control(srv.data_dir, mode="ok", delay_s=0.2, detections=detections)
    r = c.post(f"/api/projects/{pid}/jobs", json={}, headers=auth(tok))
    assert r.status_code == 202 and r.json()["status"] == "queued"
    job = wait_job(c, r.json()["id"], tok)
    assert job["status"] == "succeeded", job
    doc = c.get(f"/api/projects/{pid}/detections", headers=auth(tok)).json()
    return pid, doc


def raw_http(port: int, head: bytes, body: bytes = b"", read: bool = True) -> bytes:
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(head + body)
        if not read:
            return b""
        s.shutdown(socket.SHUT_WR) if not body else None
        chunks = []
        try:
            while chunk := s.recv(65536):
                chunks.append(chunk)
        except (ConnectionResetError, TimeoutError):
            pass
        return b"".join(chunks)


def db_rows(srv, sql: str) -> list:  # noqa: ANN001
    with sqlite3.connect(srv.data_dir / "sbsc.db") as con:
        return con.execute(sql).fetchall()


def tmp_is_empty(srv) -> bool:  # noqa: ANN001
    return not any((srv.data_dir / "tmp").iterdir())


# --------------------------------------------------------------------------- auth


def test_health_openapi_tokens_and_roles(client, srv):
    assert client.get("/api/health").json() == {"status": "ok"}
    spec = client.get("/openapi.json").json()
    for path in ("/api/projects", "/api/projects/{pid}/scans", "/api/detections/{did}",
                 "/api/projects/{pid}/signoff", "/api/projects/{pid}/export.ifc", "/api/jobs/{jid}"):
        assert path in spec["paths"], path
    r = client.get("/api/projects")
    assert r.status_code == 401 and "token" in r.json()["detail"]
    r = client.get("/api/projects", headers=auth("sbsc_not-a-real-token"))
    assert r.status_code == 401 and r.json()["detail"] == "invalid or revoked API token"
    assert client.get("/api/projects", headers={"Authorization": "Basic abc"}).status_code == 401
    # roles: a reviewer may not manage users; an admin may, and the new token works at once
    r = client.post("/api/users", json={"name": "eve", "role": "admin"}, headers=auth(srv.tokens["rita"]))
    assert r.status_code == 403 and "needs admin" in r.json()["detail"]
    r = client.post("/api/users", json={"name": "tim", "role": "reviewer"}, headers=auth(srv.tokens["ada"]))
    assert r.status_code == 201
    assert client.get("/api/me", headers=auth(r.json()["token"])).json()["name"] == "tim"
    # tokens are stored hashed only
    stored = [h for (h,) in db_rows(srv, "SELECT token_hash FROM users")]
    assert r.json()["token"] not in stored and all(len(h) == 64 for h in stored)
    # errors are one-line JSON details
    r = client.post("/api/projects", json={"nom": "x"}, headers=auth(srv.tokens["rita"]))
    assert r.status_code == 422 and isinstance(r.json()["detail"], str)


# --------------------------------------------------------------------------- uploads


def test_scan_upload_counts_points_and_stores_checksum(client, srv):
    tok = srv.tokens["rita"]
    pid = new_project(client, tok, "uploads-ok")
    ply = write_small_ply(srv.base / "ok.ply", n=1234)
    r = upload_scan(client, tok, pid, ply)
    assert r.status_code == 201, r.text
    body = r.json()
    assert body["points"] == 1234 and body["filename"] == "ok.ply"
    import hashlib

    assert body["sha256"] == hashlib.sha256(ply.read_bytes()).hexdigest()
    (path,) = db_rows(srv, f"SELECT path FROM scans WHERE id = {body['id']}")[0:1][0]
    assert (srv.data_dir / path).read_bytes() == ply.read_bytes()
    assert tmp_is_empty(srv)


def test_bad_scan_uploads_are_refused_and_leave_nothing(client, srv):
    tok = srv.tokens["rita"]
    pid = new_project(client, tok, "uploads-bad")
    h = auth(tok)
    good = write_small_ply(srv.base / "t.ply", n=2000).read_bytes()
    cases = {
        "garbage": (("g.ply", os.urandom(5000)), 422, "g.ply"),
        "truncated": (("t.ply", good[: len(good) // 2]), 422, "t.ply"),
        "empty": (("e.ply", b""), 422, "empty"),
        "no colour": (("c.xyz", b"0 0 0\n1 1 1\n2 2 2\n"), 422, "c.xyz"),
        "wrong type": (("scan.docx", b"hello"), 415, "unsupported file type"),
    }
    for name, (file, status, words) in cases.items():
        r = client.post(f"/api/projects/{pid}/scans", files={"file": file}, headers=h)
        assert r.status_code == status, (name, r.text)
        assert words in r.json()["detail"], (name, r.json())
    # no file field / not multipart
    r = client.post(f"/api/projects/{pid}/scans", files={"other": ("x.ply", good)}, headers=h)
    assert r.status_code == 400 and "'file'" in r.json()["detail"]
    r = client.post(f"/api/projects/{pid}/scans", content=good, headers={**h, "Content-Type": "application/octet-stream"})
    assert r.status_code == 415
    # too large, streamed without a length: cut at the limit, answered 413
    def chunks():
        yield b"--B\r\nContent-Disposition: form-data; name=\"file\"; filename=\"big.ply\"\r\n\r\n"
        for _ in range(2 * LIMIT // 65536 + 2):
            yield b"\0" * 65536
        yield b"\r\n--B--\r\n"
    r = client.post(f"/api/projects/{pid}/scans", content=chunks(),
                    headers={**h, "Content-Type": "multipart/form-data; boundary=B"})
    assert r.status_code == 413 and "too large" in r.json()["detail"]
    # too large by its declared length: refused before reading
    head = (f"POST /api/projects/{pid}/scans HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {tok}\r\n"
            "Content-Type: multipart/form-data; boundary=B\r\nContent-Length: 100000000000\r\n\r\n").encode()
    answer = raw_http(srv.port, head, b"--B\r\n")
    assert answer.startswith(b"HTTP/1.1 413"), answer[:200]
    # the client goes away in the middle of the body
    part = b"--B\r\nContent-Disposition: form-data; name=\"file\"; filename=\"cut.ply\"\r\n\r\n" + good[:20000]
    head = (f"POST /api/projects/{pid}/scans HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {tok}\r\n"
            f"Content-Type: multipart/form-data; boundary=B\r\nContent-Length: {len(part) + 50000}\r\n\r\n").encode()
    raw_http(srv.port, head, part, read=False)
    time.sleep(1.0)
    # nothing half-stored: no row, no file, scratch dir empty
    assert client.get(f"/api/projects/{pid}", headers=h).json()["scans"] == []
    scans_dir = srv.data_dir / "projects" / str(pid) / "scans"
    assert not scans_dir.exists() or not any(scans_dir.iterdir())
    assert tmp_is_empty(srv)


def test_model_library_zip_checked_entry_by_entry(client, srv):
    tok = srv.tokens["rita"]
    pid = new_project(client, tok, "models")
    h = auth(tok)

    def up(path: Path) -> httpx.Response:
        with open(path, "rb") as fh:
            return client.post(f"/api/projects/{pid}/models", files={"file": (path.name, fh)}, headers=h)

    r = up(write_library_zip(srv.base / "lib.zip"))
    assert r.status_code == 201, r.text
    assert r.json()["classes"] == ["socket_x1", "switch"]
    bad = {
        "escape.zip": ({"../../evil.txt": b"x"}, ".."),
        "abs.zip": ({"/etc/evil": b"x"}, "leaves the library"),
        "badclass.zip": ({"models/Bad Class/model.json": b"{}"}, "Bad Class"),
    }
    for name, (extra, words) in bad.items():
        r = up(write_library_zip(srv.base / name, extra=extra))
        assert r.status_code == 422, (name, r.text)
        assert words in r.json()["detail"], (name, r.json())
    (srv.base / "notzip.zip").write_bytes(b"PK\x03\x04 not really")
    r = up(srv.base / "notzip.zip")
    assert r.status_code == 422 and "zip" in r.json()["detail"]
    # nothing escaped, only the good library is on disk and in the project
    assert not (srv.data_dir.parent / "evil.txt").exists() and not (srv.data_dir / "evil.txt").exists()
    libs = list((srv.data_dir / "projects" / str(pid) / "models").iterdir())
    assert len(libs) == 1
    p = client.get(f"/api/projects/{pid}", headers=h).json()
    assert p["models"]["classes"] == ["socket_x1", "switch"]
    assert tmp_is_empty(srv)


# --------------------------------------------------------------------------- review


def test_review_concurrency_audit_signoff_and_lock(client, srv):
    pid, doc = project_with_results(client, srv, "review", detections=6)
    rita, rob, boss = auth(srv.tokens["rita"]), auth(srv.tokens["rob"]), auth(srv.tokens["max"])
    dets = doc["detections"]
    assert len(dets) == 6 and len(doc["walls"]) == 2 and doc["openings"][0]["kind"] == "door"
    assert all(d["review"] == {"status": "pending", "by": None, "at": None, "version": 1} for d in dets)
    d0, d1 = dets[0]["id"], dets[1]["id"]
    # thumbnails: PNG crops, colour and depth
    for kind in ("colour", "depth"):
        r = client.get(f"/api/detections/{d0}/thumbnail/{kind}", headers=rita)
        assert r.status_code == 200 and r.content[:4] == b"\x89PNG"
    # accept, then a stale write by another reviewer is refused with the current state
    r = client.patch(f"/api/detections/{d0}", json={"status": "accepted", "version": 1}, headers=rita)
    assert r.status_code == 200 and r.json()["review"]["version"] == 2
    assert r.json()["review"]["by"] == "rita"
    r = client.patch(f"/api/detections/{d0}", json={"status": "rejected", "version": 1}, headers=rob)
    assert r.status_code == 409 and "stale" in r.json()["detail"]
    assert r.json()["current"]["review"]["status"] == "accepted"
    # two reviewers at the same moment on the same version: exactly one wins
    results = []
    barrier = threading.Barrier(2)

    def decide(h, status):  # noqa: ANN001
        with httpx.Client(base_url=srv.url, timeout=30) as c:
            barrier.wait()
            results.append(c.patch(f"/api/detections/{d1}", json={"status": status, "version": 1}, headers=h).status_code)
    threads = [threading.Thread(target=decide, args=a) for a in ((rita, "accepted"), (rob, "rejected"))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(results) == [200, 409]
    # relabel and move
    d2 = client.get(f"/api/detections/{dets[2]['id']}", headers=rita).json()
    classes = client.get(f"/api/projects/{pid}/classes", headers=rita).json()
    assert d2["class"] != "socket_x4" and "socket_x4" in classes
    r = client.patch(f"/api/detections/{d2['id']}", json={"class": "socket_x4", "version": 1}, headers=rita)
    assert r.status_code == 200 and r.json()["class"] == "socket_x4" and r.json()["detected_class"] == d2["class"]
    assert r.json()["width_m"] == pytest.approx(classes["socket_x4"]["width_m"])
    r = client.patch(f"/api/detections/{d2['id']}", json={"u": 1.0, "v": 1.2, "version": 2}, headers=rita)
    assert r.status_code == 200
    wall = next(w for w in doc["walls"] if w["id"] == d2["wall"])
    expect = [o + 1.0 * a + 1.2 * b for o, a, b in zip(wall["origin"], wall["axis_u"], wall["axis_v"], strict=True)]
    assert r.json()["position"] == pytest.approx(expect)
    r = client.patch(f"/api/detections/{d2['id']}", json={"class": "no_such_class", "version": 3}, headers=rita)
    assert r.status_code == 422
    r = client.patch(f"/api/detections/{d2['id']}", json={"u": 99.0, "version": 3}, headers=rita)
    assert r.status_code == 422 and "outside wall" in r.json()["detail"]
    hist = client.get(f"/api/detections/{d2['id']}/history", headers=rita).json()
    assert [h["action"] for h in hist] == ["relabel+accept", "move"]  # relabel: it is a socket_x4, accepted
    assert hist[0]["before"]["class"] == d2["class"] and hist[0]["after"]["class"] == "socket_x4"
    # the audit trail cannot be rewritten, not even in the database itself
    with pytest.raises(sqlite3.DatabaseError, match="append-only"):
        with sqlite3.connect(srv.data_dir / "sbsc.db") as con:
            con.execute("UPDATE review_decisions SET user_name = 'mallory'")
    with pytest.raises(sqlite3.DatabaseError, match="append-only"):
        with sqlite3.connect(srv.data_dir / "sbsc.db") as con:
            con.execute("DELETE FROM review_decisions")
    # sign-off: reviewer 403, pending 409, then the manager signs
    r = client.post(f"/api/projects/{pid}/signoff", json={"comment": "ok"}, headers=rita)
    assert r.status_code == 403
    r = client.post(f"/api/projects/{pid}/signoff", json={"comment": "ok"}, headers=boss)
    assert r.status_code == 409 and "pending" in r.json()["detail"]
    for d in client.get(f"/api/projects/{pid}/detections?status=pending", headers=rita).json()["detections"]:
        r = client.patch(f"/api/detections/{d['id']}", json={"status": "rejected", "version": d["review"]["version"]},
                         headers=rob)
        assert r.status_code == 200
    r = client.post(f"/api/projects/{pid}/signoff", json={"comment": "checked against rev C"}, headers=boss)
    assert r.status_code == 200, r.text
    so = r.json()["signoff"]
    assert so["by"] == "max" and so["comment"] == "checked against rev C" and so["at"]
    final = client.get(f"/api/projects/{pid}/detections", headers=rita).json()["detections"]
    n_acc = sum(d["review"]["status"] == "accepted" for d in final)
    assert so["counts"]["accepted"] == n_acc and so["counts"]["rejected"] == 6 - n_acc
    assert so["counts"]["pending"] == 0
    # locked: every later change answers 423
    r = client.patch(f"/api/detections/{d0}", json={"status": "rejected", "version": 2}, headers=rita)
    assert r.status_code == 423
    assert upload_scan(client, srv.tokens["rita"], pid, srv.base / "review.ply").status_code == 423
    assert client.post(f"/api/projects/{pid}/jobs", json={}, headers=rita).status_code == 423
    assert client.post(f"/api/projects/{pid}/signoff", json={"comment": "again"}, headers=boss).status_code == 423
    assert client.get(f"/api/projects/{pid}", headers=rita).json()["status"] == "signed_off"
    # IFC export: walls, openings and exactly the accepted objects
    r = client.get(f"/api/projects/{pid}/export.ifc", headers=rita)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("application/x-step")
    ifc = srv.base / "review.ifc"
    ifc.write_bytes(r.content)
    import ifcopenshell

    model = ifcopenshell.open(str(ifc))
    refs = {d["ref"]: d["review"]["status"] for d in final}
    tags = sorted(e.Tag for e in model.by_type("IfcElement") if getattr(e, "Tag", None) in refs)
    assert tags == sorted(k for k, v in refs.items() if v == "accepted")
    assert model.by_type("IfcApproval"), "the sign-off is recorded in the IFC"
    # every successful decision is in the audit trail, none lost
    trail = client.get(f"/api/projects/{pid}/decisions", headers=rita).json()
    versions = {d["id"]: d["review"]["version"] for d in final}
    for did, version in versions.items():
        mine = [t for t in trail if t["detection"] == did]
        assert len(mine) == version - 1
        assert [t["version_to"] for t in mine] == list(range(2, version + 1))


def test_job_events_failure_and_retry(client, srv):
    tok = srv.tokens["rita"]
    h = auth(tok)
    pid = new_project(client, tok, "jobs")
    assert client.post(f"/api/projects/{pid}/jobs", json={}, headers=h).status_code == 409  # no scan yet
    assert upload_scan(client, tok, pid, write_small_ply(srv.base / "j.ply")).status_code == 201
    r = client.post(f"/api/projects/{pid}/jobs", json={"expected": {"socket_x1": -1}}, headers=h)
    assert r.status_code == 422 and "expected.socket_x1" in r.json()["detail"]
    fake_control(srv.data_dir, mode="fail")
    jid = client.post(f"/api/projects/{pid}/jobs", json={"expected": {"socket_x1": 2}}, headers=h).json()["id"]
    # server-sent events until the job ends
    events = []
    with client.stream("GET", f"/api/jobs/{jid}/events", headers=h) as resp:
        assert resp.headers["content-type"].startswith("text/event-stream")
        for line in resp.iter_lines():
            if line.startswith("data: "):
                events.append(json.loads(line[6:]))
    assert events[-1]["status"] == "failed"
    assert events[-1]["error"] == "scan.ply: no walls found (fake runner)"
    fake_control(srv.data_dir, mode="ok", delay_s=0.2, detections=4)
    r = client.post(f"/api/jobs/{jid}/retry", headers=h)
    assert r.status_code == 202
    retry = r.json()
    assert retry["retry_of"] == jid and retry["expected"] == {"socket_x1": 2} and retry["id"] != jid
    done = wait_job(client, retry["id"], tok)
    assert done["status"] == "succeeded" and done["progress"] == 1.0
    assert client.post(f"/api/jobs/{done['id']}/retry", headers=h).status_code == 409
    assert len(client.get(f"/api/projects/{pid}/detections", headers=h).json()["detections"]) == 4
    assert "fake runner" in client.get(f"/api/jobs/{done['id']}/log", headers=h).text


def test_killed_worker_fails_the_job_and_keeps_the_database_consistent(client, srv):
    tok = srv.tokens["rita"]
    h = auth(tok)
    pid, doc = project_with_results(client, srv, "kill", detections=3)
    before = client.get(f"/api/projects/{pid}/detections", headers=h).json()
    fake_control(srv.data_dir, mode="ok", delay_s=60, detections=9)
    jid = client.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
    job = wait_job(client, jid, tok, until=("running",))
    deadline = time.monotonic() + 20
    assert "worker_pid" not in job  # no process ids in the API
    while not worker_pid(srv.data_dir, jid) or job["stage"] in ("queued", "starting"):
        assert time.monotonic() < deadline, job
        time.sleep(0.1)
        job = client.get(f"/api/jobs/{jid}", headers=h).json()
    os.kill(worker_pid(srv.data_dir, jid), signal.SIGKILL)
    job = wait_job(client, jid, tok, timeout_s=20)
    assert job["status"] == "failed"
    assert "SIGKILL" in job["error"] and "stage" in job["error"], job["error"]
    # the earlier results are still the project's, unchanged; nothing of the dead job
    assert client.get(f"/api/projects/{pid}/detections", headers=h).json() == before
    assert db_rows(srv, f"SELECT count(*) FROM detections WHERE job_id = {jid}") == [(0,)]
    fake_control(srv.data_dir, mode="ok", delay_s=0.2, detections=9)
    new = client.post(f"/api/jobs/{jid}/retry", headers=h).json()
    assert wait_job(client, new["id"], tok)["status"] == "succeeded"
    assert len(client.get(f"/api/projects/{pid}/detections", headers=h).json()["detections"]) == 9


def test_server_restart_mid_job(tmp_path):
    data = tmp_path / "data"
    tok = add_user(AppSettings(data_dir=data), "rita", "reviewer")
    h = auth(tok)
    env = {"SBSC_JOB_RUNNER": RUNNER, "SBSC_JOB_WORKERS": "1"}
    server = ServerProcess(data, env).start()
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            pid = new_project(c, tok, "restart")
            with open(write_small_ply(tmp_path / "r.ply"), "rb") as fh:
                assert c.post(f"/api/projects/{pid}/scans", files={"file": ("r.ply", fh)}, headers=h).status_code == 201
            fake_control(data, mode="ok", delay_s=60, detections=5)
            a = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
            # a project holds one queued job at a time (409): the second one is posted once the first runs
            job = wait_job(c, a, tok, until=("running",))
            b = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]  # waits in the queue
            while not worker_pid(data, a):
                time.sleep(0.1)
            worker = worker_pid(data, a)
        # the server dies hard: its worker notices and exits by itself
        server.stop(signal.SIGKILL)
        deadline = time.monotonic() + 10
        while pid_alive(worker):
            assert time.monotonic() < deadline, "orphaned worker still running"
            time.sleep(0.2)
        fake_control(data, mode="ok", delay_s=0.2, detections=5)
        server.start()
        with httpx.Client(base_url=server.url, timeout=30) as c:
            job = c.get(f"/api/jobs/{a}", headers=h).json()
            assert job["status"] == "failed" and "server restarted" in job["error"], job
            # the queued job was kept and runs now
            assert wait_job(c, b, tok)["status"] == "succeeded"
            # a graceful stop fails the running job with a reason too
            fake_control(data, mode="ok", delay_s=60, detections=5)
            d = c.post(f"/api/jobs/{a}/retry", headers=h).json()["id"]
            job = wait_job(c, d, tok, until=("running",))
        server.stop(signal.SIGTERM)
        fake_control(data, mode="ok", delay_s=0.2, detections=5)
        server.start()
        with httpx.Client(base_url=server.url, timeout=30) as c:
            job = c.get(f"/api/jobs/{d}", headers=h).json()
            assert job["status"] == "failed" and "server shut down" in job["error"], job
            e = c.post(f"/api/jobs/{d}/retry", headers=h).json()["id"]
            assert wait_job(c, e, tok)["status"] == "succeeded"
            assert len(c.get(f"/api/projects/{pid}/detections", headers=h).json()["detections"]) == 5
        assert db_rows_at(data, "SELECT status, count(*) FROM jobs GROUP BY status") == [("failed", 2), ("succeeded", 2)]
    finally:
        server.stop()






def test_huge_upload_streams_with_flat_server_memory(tmp_path):
    """A multi-GB upload goes to disk in chunks: the server's RSS grows by far less than 100 MB.

    ``SBSC_TEST_BIG_UPLOAD_MB`` sets the size (default 2048 MiB; ~15 s on a 2-core machine).
    The body is a PLY header followed by junk, so the content check refuses it (422) and
    nothing may stay on disk.
    """
    size_mb = int(os.environ.get("SBSC_TEST_BIG_UPLOAD_MB", "2048"))
    data = tmp_path / "data"
    tok = add_user(AppSettings(data_dir=data), "rita", "reviewer")
    server = ServerProcess(data, {"SBSC_MAX_SCAN_BYTES": str((size_mb + 16) << 20)}).start()
    try:
        with httpx.Client(base_url=server.url, timeout=300) as c:
            pid = new_project(c, tok, "big")
            base = server.rss_kib()
            peak = [base]
            done = threading.Event()

            def watch() -> None:
                while not done.is_set():
                    peak[0] = max(peak[0], server.rss_kib())
                    time.sleep(0.05)
            watcher = threading.Thread(target=watch)
            watcher.start()
            block = b"\x07" * (1 << 20)

            def body():
                yield b'--B\r\nContent-Disposition: form-data; name="file"; filename="huge.ply"\r\n\r\n'
                yield b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nend_header\n"
                for _ in range(size_mb):
                    yield block
                yield b"\r\n--B--\r\n"
            r = c.post(f"/api/projects/{pid}/scans", content=body(),
                       headers={**auth(tok), "Content-Type": "multipart/form-data; boundary=B"})
            done.set()
            watcher.join()
            assert r.status_code == 422 and r.json()["detail"].startswith("huge.ply:"), r.text
            growth_mb = (peak[0] - base) / 1024
            print(f"\n{size_mb} MiB upload: server RSS {base / 1024:.0f} MiB -> peak {peak[0] / 1024:.0f} MiB")
            assert growth_mb < 100, growth_mb
            assert c.get(f"/api/projects/{pid}", headers=auth(tok)).json()["scans"] == []
        assert not any((data / "tmp").iterdir())
    finally:
        server.stop()
