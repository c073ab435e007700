"""The small ones of issue 30: the wrong multipart field, a 1,000-character file name, and no
scratch (partition) folder left after a SIGKILL of the server and a restart."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Sequence
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from app.auth import create_user
from app.config import AppSettings
from app.server import create_app
from app.storage import safe_filename
from app.users import add_user

from .app_support import ServerProcess, auth, write_small_ply


def scratch_runner(scans: Sequence[Path], models: Path, *, expected=None, out: Path,  # noqa: ANN001
                   settings_file=None, log=None, progress=None) -> dict:  # noqa: ANN001
    """A job that makes its partitions where the pipeline does (``scratch_dir``), then hangs."""
    from sbsc_core.imaging.partition import scratch_dir

    work = scratch_dir(Path(out))
    (work / "wall_W01.bin").write_bytes(b"\0" * 1000)
    (Path(out).parent / "scratch_at").write_text(str(work))
    time.sleep(600)
    return {}


@pytest.fixture()
def client(tmp_path):
    settings = AppSettings(data_dir=tmp_path / "d", viewer=False)
    with TestClient(create_app(settings, start_jobs=False)) as c:
        with c.app.state.db.write() as s:
            c.h = auth(create_user(s, "ada", "admin")[1])
        c.pid = c.post("/api/projects", json={"name": "p"}, headers=c.h).json()["id"]
        yield c


def test_a_file_under_another_field_is_named_as_such(client, tmp_path):
    ply = write_small_ply(tmp_path / "s.ply")
    with open(ply, "rb") as fh:
        r = client.post(f"/api/projects/{client.pid}/scans", files={"scan": ("s.ply", fh)}, headers=client.h)
    assert r.status_code == 400 and r.json()["detail"].startswith("no `file` field"), r.text
    # the file's bytes as a plain field (no file name), as curl -F 'scan=<s.ply' sends them
    r = client.post(f"/api/projects/{client.pid}/scans", files={"scan": (None, b"x" * 100_000)}, headers=client.h)
    assert r.status_code == 400 and r.json()["detail"].startswith("no `file` field"), r.text
    r = client.post(f"/api/projects/{client.pid}/scans", files={"other": ("x.txt", b"x" * 200_000)},
                    headers=client.h)
    assert r.status_code == 400 and r.json()["detail"].startswith("no `file` field"), r.text
    assert list(client.app.state.settings.tmp_dir.iterdir()) == []


def test_a_long_file_name_keeps_its_extension(client, tmp_path):
    assert safe_filename("a" * 1000 + ".ply") == "a" * 116 + ".ply"
    assert safe_filename("b" * 300 + ".e57") .endswith(".e57") and len(safe_filename("b" * 300 + ".e57")) == 120
    assert len(safe_filename("c" * 300 + "." + "x" * 40)) == 120  # no extension to speak of: cut
    ply = write_small_ply(tmp_path / "s.ply")
    with open(ply, "rb") as fh:
        r = client.post(f"/api/projects/{client.pid}/scans", files={"file": ("é" * 500 + ".ply", fh)},
                        headers=client.h)
    assert r.status_code == 201 and r.json()["filename"].endswith(".ply"), r.text


@pytest.mark.slow
def test_no_partition_folder_after_sigkill_and_restart(tmp_path):
    data = tmp_path / "data"
    token = add_user(AppSettings(data_dir=data), "ada", "admin")
    env = {"SBSC_VIEWER": "false", "SBSC_JOB_RUNNER": "tests.test_app_small_ones:scratch_runner"}
    server = ServerProcess(data, env).start()
    try:
        with httpx.Client(base_url=server.url, timeout=60, headers=auth(token)) as c:
            pid = c.post("/api/projects", json={"name": "p"}).json()["id"]
            with open(write_small_ply(tmp_path / "s.ply"), "rb") as fh:
                assert c.post(f"/api/projects/{pid}/scans", files={"file": ("s.ply", fh)}).status_code == 201
            jid = c.post(f"/api/projects/{pid}/jobs", json={}).json()["id"]
            marker = data / "projects" / str(pid) / "jobs" / str(jid) / "scratch_at"
            deadline = time.monotonic() + 60
            while not marker.is_file():
                assert time.monotonic() < deadline, "the job never started"
                time.sleep(0.1)
            work = Path(marker.read_text())
            assert work.is_dir()
        server.stop(signal.SIGKILL)
        time.sleep(2.0)  # the worker notices its server is gone and ends its group
        server.start()
        with httpx.Client(base_url=server.url, timeout=60, headers=auth(token)) as c:
            assert c.get(f"/api/jobs/{jid}").json()["status"] == "failed"
    finally:
        server.stop()
    left = [p for p in data.rglob("*") if p.is_dir() and p.name.startswith(".sbsc-")]
    assert left == [] and not work.exists(), left
    assert [p for p in (data / "tmp").iterdir()] == [] if (data / "tmp").is_dir() else True
    assert os.environ.get("SBSC_SCRATCH_DIR") is None  # the server's workers set it, never this process
