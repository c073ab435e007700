"""The review service under attack (issue 10): schemathesis against a live server, request
bounds, streamed upload checks, and processes that die with their job, also after the
server is killed."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import httpx
import pytest

from app.config import AppSettings
from app.users import add_user

from .app_support import (
    ServerProcess,
    auth,
    fake_control,
    fake_detect_to_dir,
    pid_alive,
    wait_job,
    write_small_ply,
)

RUNNER = "tests.test_app_hardening:pool_runner"
ST = Path(sys.executable).with_name("st")


def pool_runner(scans: Sequence[Path], models: Path, *, expected=None, out: Path,  # noqa: ANN001
                settings_file=None, log=None, progress=None) -> dict:  # noqa: ANN001
    """The fake runner with two pool processes, like the pipeline's per-wall workers; their
    pids (and the worker's) go to ``<job dir>/pids`` for the test to watch."""
    control = json.loads((Path(os.environ["SBSC_DATA_DIR"]) / "fake_control.json").read_text())
    import multiprocessing

    pool = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn"))
    try:
        for _ in range(2):
            pool.submit(time.sleep, float(control.get("delay_s", 0.3)) + 1.0)
        pids = [os.getpid(), *[p.pid for p in pool._processes.values()]]
        while len(pids) < 3:
            time.sleep(0.05)
            pids = [os.getpid(), *[p.pid for p in pool._processes.values()]]
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        (Path(out).parent / "pids").write_text(" ".join(map(str, pids)))
        return fake_detect_to_dir(scans, models, expected=expected, out=out, log=log, progress=progress)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _job_pids(data: Path, pid: int, jid: int, timeout_s: float = 30.0) -> list[int]:
    f = data / "projects" / str(pid) / "jobs" / str(jid) / "pids"
    deadline = time.monotonic() + timeout_s
    while not f.is_file() or len(f.read_text().split()) < 3:
        assert time.monotonic() < deadline, "the job's processes never started"
        time.sleep(0.1)
    return [int(x) for x in f.read_text().split()]


def _wait_dead(pids: list[int], timeout_s: float = 15.0) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while any(pid_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return [p for p in pids if pid_alive(p)]


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """A server with the pool runner, an admin and a reviewer, a project with results."""
    data = tmp_path_factory.mktemp("hardening") / "data"
    settings = AppSettings(data_dir=data)
    tokens = {"admin": add_user(settings, "ada", "admin"), "rita": add_user(settings, "rita", "reviewer")}
    server = ServerProcess(data, {"SBSC_VIEWER": "false", "SBSC_JOB_RUNNER": RUNNER,
                                  "SBSC_JOB_WORKERS": "1", "SBSC_UPLOADS_PER_USER": "1"}).start()
    server.tokens = tokens
    fake_control(data, mode="ok", delay_s=0.2, detections=4)
    with httpx.Client(base_url=server.url, timeout=60) as c:
        h = auth(tokens["admin"])
        pid = c.post("/api/projects", json={"name": "fuzz"}, headers=h).json()["id"]
        assert c.post(f"/api/projects/{pid}/members", json={"user": "rita", "role": "reviewer"},
                      headers=h).status_code == 201
        with open(write_small_ply(data.parent / "s.ply"), "rb") as fh:
            assert c.post(f"/api/projects/{pid}/scans", files={"file": ("s.ply", fh)}, headers=h).status_code == 201
        jid = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
        assert wait_job(c, jid, tokens["admin"])["status"] == "succeeded"
        server.ids = {"pid": pid, "jid": jid,
                      "did": c.get(f"/api/projects/{pid}/detections", headers=h).json()["detections"][0]["id"]}
    try:
        yield server
    finally:
        server.stop()


# --------------------------------------------------------------------------- bounds


@pytest.mark.slow
def test_bounds_ids_bodies_names_and_methods(live):
    h = auth(live.tokens["rita"])
    big = str(2**63)
    with httpx.Client(base_url=live.url, timeout=30) as c:
        for path in (f"/api/projects/{big}", f"/api/jobs/{big}", f"/api/detections/{big}/history",
                     f"/api/projects/{2**64 + 5}/detections"):
            r = c.get(path, headers=h)
            assert r.status_code == 404 and isinstance(r.json()["detail"], str), (path, r.text)
        r = c.patch(f"/api/detections/{big}", json={"version": 1, "status": "accepted"}, headers=h)
        assert r.status_code == 404
        r = c.get(f"/api/projects/{live.ids['pid']}/decisions?after={big}", headers=h)
        assert r.status_code == 422
        r = c.patch(f"/api/detections/{live.ids['did']}", json={"version": 2**70, "status": "accepted"}, headers=h)
        assert r.status_code == 422 and "out of range" in r.json()["detail"]
        # a body too large, deep JSON, huge key counts: refused before they are parsed
        r = c.post("/api/projects", content=b'{"name": "' + b"x" * 2_000_000 + b'"}',
                   headers={**h, "content-type": "application/json"})
        assert r.status_code == 413
        r = c.post("/api/projects", content=b'{"name": "a", "x": ' + b"[" * 5000 + b"]" * 5000 + b"}",
                   headers={**h, "content-type": "application/json"})
        assert r.status_code == 422 and "nested" in r.json()["detail"]
        pid = live.ids["pid"]
        r = c.post(f"/api/projects/{pid}/jobs", json={"expected": {f"c{i}": 1 for i in range(300)}}, headers=h)
        assert r.status_code == 422 and "at most 200" in r.json()["detail"], r.text
        r = c.post(f"/api/projects/{pid}/jobs", json={"expected": {f"c{i}": 1 for i in range(3000)}}, headers=h)
        assert r.status_code == 422
        # NUL and bidi controls in names
        for name in ("a\u0000b", "invoice\u202egpj.exe", "\u2066x"):
            r = c.post("/api/projects", json={"name": name}, headers=h)
            assert r.status_code == 422 and "U+" in r.json()["detail"], (name, r.text)
        assert c.post("/api/projects", json={"name": "   "}, headers=h).status_code == 422
        # 405 where the path exists, 404 where it does not
        r = c.put("/api/projects", headers=h)
        assert r.status_code == 405 and "GET" in r.headers["allow"] and "POST" in r.headers["allow"]
        assert c.delete(f"/api/projects/{pid}", headers=h).status_code == 405
        assert c.get("/api/nothing/here", headers=h).status_code == 404
        # the job JSON shows no process id
        job = c.get(f"/api/jobs/{live.ids['jid']}", headers=h).json()
        assert "worker_pid" not in job


@pytest.mark.slow
def test_openapi_declares_bearer_and_the_error_body(live):
    doc = httpx.get(live.url + "/openapi.json", timeout=30).json()
    assert doc["components"]["securitySchemes"]["bearerAuth"] == {
        "type": "http", "scheme": "bearer", "description": doc["components"]["securitySchemes"]["bearerAuth"]["description"]}
    assert "HTTPValidationError" not in doc["components"]["schemas"]
    err = doc["components"]["schemas"]["Error"]
    assert err["properties"]["detail"]["type"] == "string"
    for path, ops in doc["paths"].items():
        for method, op in ops.items():
            assert op["security"] == ([] if path == "/api/health" else [{"bearerAuth": []}]), path
            codes = {int(c) for c in op["responses"] if c[0] in "45"}
            assert 422 in codes and (path == "/api/health" or {401, 403} <= codes), (method, path)
            for code in codes:
                schema = op["responses"][str(code)]["content"]["application/json"]["schema"]
                assert schema == {"$ref": "#/components/schemas/Error"}


@pytest.mark.slow
def test_schemathesis_finds_no_server_error_and_no_schema_violation(live, tmp_path):
    """Property-based fuzzing from /openapi.json, with ids of real resources; bounded."""
    if not ST.is_file():
        pytest.skip("schemathesis is not installed (pip install -e .[test])")
    cfg = tmp_path / "schemathesis.toml"
    cfg.write_text("[parameters]\n" + "".join(f"{k} = {v}\n" for k, v in live.ids.items()))
    fake_control(live.data_dir, mode="ok", delay_s=0.1, detections=4)
    t0 = time.monotonic()
    res = subprocess.run(
        [str(ST), "--config-file", str(cfg), "run", live.url + "/openapi.json",
         "-H", f"Authorization: Bearer {live.tokens['admin']}", "--max-examples", "5",
         "--checks", "not_a_server_error,status_code_conformance,content_type_conformance,"
                     "response_schema_conformance",
         "--generation-deterministic", "--request-timeout", "60", "--no-color"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path)  # its cache stays out of the tree
    out = res.stdout + res.stderr
    m = re.search(r"(\d+) generated, (\d+) passed", out)
    print(f"schemathesis: {m.group(0) if m else '?'} in {time.monotonic() - t0:.0f} s")
    assert res.returncode == 0 and m, out[-6000:]
    assert int(m.group(1)) == int(m.group(2)) >= 300, out[-3000:]


# --------------------------------------------------------------------------- uploads


def _ply(n_header: int, n_body: int) -> bytes:
    import numpy as np

    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {n_header}\nproperty float x\n"
            "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
            "property uchar blue\nend_header\n").encode()
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    arr = np.zeros(n_body, dt)
    arr["x"] = np.arange(n_body)
    arr["r"] = 200
    return head + arr.tobytes()


@pytest.mark.slow
def test_upload_point_count_comes_from_the_header_and_must_match_the_size(live):
    h = auth(live.tokens["rita"])
    pid = live.ids["pid"]
    with httpx.Client(base_url=live.url, timeout=60) as c:
        def up(name: str, data: bytes) -> httpx.Response:
            return c.post(f"/api/projects/{pid}/scans", files={"file": (name, data)}, headers=h)

        r = up("ok.ply", _ply(1000, 1000))
        assert r.status_code == 201 and r.json()["points"] == 1000, r.text
        r = up("lies_low.ply", _ply(10, 1000))
        assert r.status_code == 422 and "10 points" in r.json()["detail"], r.text
        r = up("lies_high.ply", _ply(1000, 10))
        assert r.status_code == 422 and "truncated" in r.json()["detail"], r.text
        r = up("ok.xyz", b"".join(b"%d 0 1 10 20 30\n" % i for i in range(500)))
        assert r.status_code == 201 and r.json()["points"] == 500, r.text
        r = up("bad.pts", b"1000\n" + b"1 2 3 50 4 5 6\n" * 10)
        assert r.status_code == 422 and "announces 1,000 points" in r.json()["detail"], r.text
        for name in ("lies_low.ply", "lies_high.ply", "bad.pts"):
            assert "/" not in r.json()["detail"].replace(name, "")


# --------------------------------------------------------------------------- faults


@pytest.mark.slow
def test_job_processes_die_with_the_job_and_with_the_server(tmp_path):
    """Each job's processes are one process group: a killed worker takes its pool along; after
    a SIGKILL of the server (its worker frozen, so only the restart can clean up) the new
    server reaps them; no acknowledged review decision is lost; errors show no server path."""
    data = tmp_path / "data"
    settings = AppSettings(data_dir=data)
    tok = add_user(settings, "ada", "admin")
    h = auth(tok)
    server = ServerProcess(data, {"SBSC_VIEWER": "false", "SBSC_JOB_RUNNER": RUNNER,
                                  "SBSC_JOB_WORKERS": "1"}).start()
    frozen: list[int] = []
    try:
        fake_control(data, mode="ok", delay_s=0.2, detections=4)
        with httpx.Client(base_url=server.url, timeout=60) as c:
            pid = c.post("/api/projects", json={"name": "faults"}, headers=h).json()["id"]
            with open(write_small_ply(tmp_path / "s.ply"), "rb") as fh:
                assert c.post(f"/api/projects/{pid}/scans", files={"file": ("s.ply", fh)},
                              headers=h).status_code == 201
            j1 = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
            assert wait_job(c, j1, tok)["status"] == "succeeded"
            assert _wait_dead(_job_pids(data, pid, j1)) == []  # a finished job leaves nothing
            dets = c.get(f"/api/projects/{pid}/detections", headers=h).json()["detections"]
            decided = {}
            for d, status in zip(dets, ("accepted", "rejected", "accepted"), strict=False):
                r = c.patch(f"/api/detections/{d['id']}", json={"version": 1, "status": status}, headers=h)
                assert r.status_code == 200
                decided[d["id"]] = status
            # 1) the worker is killed: its pool processes go with it
            fake_control(data, mode="ok", delay_s=120, detections=4)
            j2 = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
            pids = _job_pids(data, pid, j2)
            os.kill(pids[0], signal.SIGKILL)
            job = wait_job(c, j2, tok, timeout_s=30)
            assert job["status"] == "failed" and "SIGKILL" in job["error"]
            assert _wait_dead(pids) == [], "orphaned pool processes after the worker was killed"
            # 2) the server is killed while a job runs and its worker cannot react (stopped)
            j3 = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
            frozen = _job_pids(data, pid, j3)
            os.kill(frozen[0], signal.SIGSTOP)
        server.stop(signal.SIGKILL)
        time.sleep(1.0)
        assert all(pid_alive(p) for p in frozen)  # nobody has cleaned up yet
        fake_control(data, mode="ok", delay_s=0.2, detections=4)
        server.start()
        assert _wait_dead(frozen) == [], "orphaned processes after the server was killed and restarted"
        frozen = []
        with httpx.Client(base_url=server.url, timeout=60) as c:
            job = c.get(f"/api/jobs/{j3}", headers=h).json()
            assert job["status"] == "failed" and "server restarted" in job["error"]
            now = {d["id"]: d["review"]["status"] for d in
                   c.get(f"/api/projects/{pid}/detections", headers=h).json()["detections"]}
            assert {k: now[k] for k in decided} == decided  # no decision lost
            # a job that fails shows no server path; the admin log has the details
            fake_control(data, mode="fail")
            j4 = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
            job = wait_job(c, j4, tok)
            assert job["status"] == "failed" and str(data) not in job["error"]
            log = c.get(f"/api/jobs/{j4}/log", headers=h).text
            assert str(data) not in log and str(tmp_path) not in log, log
            admin = c.get(f"/api/admin/jobs/{j4}/log", headers=h)
            assert admin.status_code == 200 and str(data) in admin.text
    finally:
        for p in frozen:
            with __import__("contextlib").suppress(ProcessLookupError):
                os.killpg(p, signal.SIGKILL)
        server.stop()
        shutil.rmtree(data / "projects", ignore_errors=True)


@pytest.mark.slow
def test_concurrent_uploads_per_user_are_limited(live):
    """A second upload of the same user while the first still streams: 429 (limit 1 here)."""
    import threading

    h = auth(live.tokens["rita"])
    pid = live.ids["pid"]
    boundary = "sbscboundary"
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"file\"; filename=\"slow.xyz\"\r\n"
            "Content-Type: application/octet-stream\r\n\r\n").encode()
    release = threading.Event()

    def body():
        yield head
        for _ in range(20):
            yield b"0 0 0 1 2 3\n" * 100
            if release.wait(0.1):
                break
        yield f"\r\n--{boundary}--\r\n".encode()

    first: dict = {}

    def slow() -> None:
        with httpx.Client(base_url=live.url, timeout=60) as c:
            first["r"] = c.post(f"/api/projects/{pid}/scans", content=body(),
                                headers={**h, "content-type": f"multipart/form-data; boundary={boundary}"})

    t = threading.Thread(target=slow)
    t.start()
    time.sleep(0.8)
    with httpx.Client(base_url=live.url, timeout=60) as c:
        r = c.post(f"/api/projects/{pid}/scans", files={"file": ("b.xyz", b"0 0 0 1 2 3\n")}, headers=h)
        other = c.post(f"/api/projects/{pid}/scans", files={"file": ("c.xyz", b"0 0 0 1 2 3\n")},
                       headers=auth(live.tokens["admin"]))
    release.set()
    t.join(30)
    assert r.status_code == 429 and "in progress" in r.json()["detail"], r.text
    assert other.status_code == 201  # another user is not held up
    assert first["r"].status_code == 201, first["r"].text


def test_text_scan_lines_are_counted_in_blocks_like_line_by_line(tmp_path, monkeypatch):
    import random

    from sbsc_core.io import scan_check

    monkeypatch.setattr(scan_check, "CHUNK", 7)  # many block boundaries
    monkeypatch.setattr(scan_check, "_sample_read", lambda *a: None)
    rng = random.Random(1)
    for _ in range(200):
        parts = [rng.choice(["1 2 3 4 5 6\n", "\n", "# c\n", "1 2 3 4 5 6\r\n", "\r\n", "7 8 9 1 1 1"])
                 for _ in range(rng.randint(1, 30))]
        p = tmp_path / "t.xyz"
        p.write_bytes("".join(parts).encode())
        slow = scan_check._count_text_lines_slow(p)
        if slow:
            assert scan_check.text_points(p) == slow, parts
