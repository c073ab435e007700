"""The review app on PostgreSQL (``SBSC_DATABASE_URL``): migrations, review, lock, audit trail.

Uses ``SBSC_TEST_POSTGRES_URL`` when set; otherwise starts a throw-away cluster with the
Debian ``postgresql`` binaries (as the ``postgres`` user when run as root). Skipped when
neither PostgreSQL nor the ``psycopg`` driver is there.
"""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import text

from app.auth import create_user
from app.config import AppSettings
from app.membership import set_member
from app.sample import ensure_sample_project
from app.server import create_app

from .app_support import _fake_output, free_port, write_small_ply


def _run_as_postgres(cmd: list[str]) -> subprocess.CompletedProcess:
    if os.geteuid() == 0:
        cmd = ["runuser", "-u", "postgres", "--", *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def pg_url():
    pytest.importorskip("psycopg", reason="the psycopg driver is not installed")
    url = os.environ.get("SBSC_TEST_POSTGRES_URL")
    if url:
        yield url
        return
    bins = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    if not bins:
        pytest.skip("no PostgreSQL server binaries (apt-get install postgresql) and no SBSC_TEST_POSTGRES_URL")
    bindir = os.path.dirname(bins[-1])
    base = Path(tempfile.mkdtemp(prefix="sbsc-pg-"))  # outside pytest's 0700 tree: postgres must enter it
    pgdata, sock = base / "data", base / "sock"
    sock.mkdir()
    if os.geteuid() == 0:
        shutil.chown(base, "postgres")
        shutil.chown(sock, "postgres")
    r = _run_as_postgres([f"{bindir}/initdb", "-D", str(pgdata), "-U", "postgres", "-A", "trust"])
    if r.returncode != 0:
        pytest.skip(f"initdb failed: {r.stderr.strip()[:300]}")
    port = free_port()
    r = _run_as_postgres([f"{bindir}/pg_ctl", "-D", str(pgdata), "-w", "-l", str(base / "log"), "-o",
                          f"-p {port} -k {sock} -c listen_addresses=''", "start"])
    if r.returncode != 0:
        pytest.skip(f"PostgreSQL did not start: {r.stderr.strip()[:300]}")
    try:
        yield f"postgresql+psycopg://postgres@/postgres?host={sock}&port={port}"
    finally:
        _run_as_postgres([f"{bindir}/pg_ctl", "-D", str(pgdata), "-m", "immediate", "stop"])
        shutil.rmtree(base, ignore_errors=True)


@pytest.mark.slow
def test_review_flow_on_postgresql(pg_url, tmp_path):
    settings = AppSettings(data_dir=tmp_path / "d", database_url=pg_url)
    out = tmp_path / "out"
    _fake_output(out, 4, lambda s, f: None, 0.0)
    pid = ensure_sample_project(write_small_ply(tmp_path / "s.ply"), out, settings=settings, name=f"pg {time.time()}")
    with TestClient(create_app(settings, start_jobs=False)) as c:
        db = c.app.state.db
        assert db.engine.dialect.name == "postgresql"
        with db.write() as s:
            _, rita = create_user(s, f"rita{pid}", "reviewer")
            _, boss = create_user(s, f"max{pid}", "manager")
            set_member(s, pid, f"rita{pid}", "reviewer", None)  # projects belong to their members
            set_member(s, pid, f"max{pid}", "manager", None)
        h, hb = {"Authorization": f"Bearer {rita}"}, {"Authorization": f"Bearer {boss}"}
        dets = c.get(f"/api/projects/{pid}/detections", headers=h).json()["detections"]
        assert len(dets) == 4
        # the same version from two threads at once: one 200, one 409 (row locks on PostgreSQL)
        codes: list[int] = []
        barrier = threading.Barrier(2)

        def decide(status: str) -> None:
            barrier.wait()
            codes.append(c.patch(f"/api/detections/{dets[0]['id']}", json={"status": status, "version": 1},
                                 headers=h).status_code)
        ts = [threading.Thread(target=decide, args=(s,)) for s in ("accepted", "rejected")]
        for t in ts:
            t.start()
        for t in ts:
            t.join()
        assert sorted(codes) == [200, 409]
        for d in dets[1:]:
            assert c.patch(f"/api/detections/{d['id']}", json={"status": "rejected", "version": 1},
                           headers=h).status_code == 200
        r = c.post(f"/api/projects/{pid}/signoff", json={"comment": "pg"}, headers=hb)
        assert r.status_code == 200 and r.json()["counts"]["pending"] == 0
        assert c.patch(f"/api/detections/{dets[1]['id']}", json={"status": "accepted", "version": 2},
                       headers=h).status_code == 423
        with pytest.raises(Exception, match="append-only"), db.engine.begin() as conn:
            conn.execute(text("UPDATE review_decisions SET user_name = 'mallory'"))
        assert len(c.get(f"/api/projects/{pid}/decisions", headers=h).json()) == 4
