"""A full data disk (issue 30): a clear 507 for uploads and database writes, no partial file
left, and the service works again as soon as space is freed, with no restart. Runs on a small
tmpfs (skipped where mounting one is not permitted)."""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import signal
import subprocess
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.exc import OperationalError

from app.auth import create_user
from app.config import AppSettings
from app.failures import DISK_FULL, WORKER_LOST, disk_full, reason
from app.job_processes import describe_exit
from app.server import create_app
from app.storage import _FilePart

from .app_support import write_small_ply


@pytest.fixture()
def small_disk(tmp_path):
    """A 6 MiB tmpfs, unmounted at the end."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if shutil.which("mount") is None or os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=6m", "tmpfs", str(mnt)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(path: Path) -> None:
    """Write ``path`` until the disk is full."""
    with open(path, "wb", buffering=0) as fh:
        block = b"\0" * 65536
        with contextlib.suppress(OSError):
            while True:
                fh.write(block)
        with contextlib.suppress(OSError):  # the last few bytes
            while True:
                fh.write(b"\0" * 512)


@pytest.mark.slow
def test_full_disk_is_507_leaves_nothing_and_recovers_without_restart(small_disk, tmp_path):
    settings = AppSettings(data_dir=small_disk / "data", viewer=False)
    small = write_small_ply(tmp_path / "small.ply", n=2000)
    with TestClient(create_app(settings, start_jobs=False)) as c:
        with c.app.state.db.write() as s:
            h = {"Authorization": f"Bearer {create_user(s, 'ada', 'admin')[1]}"}
        pid = c.post("/api/projects", json={"name": "P"}, headers=h).json()["id"]
        # an upload larger than the disk: 507, and its partial file is gone at once
        big = tmp_path / "big.ply"
        big.write_bytes(small.read_bytes()[:200] + os.urandom(8 * 1024 * 1024))
        with open(big, "rb") as fh:
            r = c.post(f"/api/projects/{pid}/scans", files={"file": ("big.ply", fh)}, headers=h)
        assert r.status_code == 507 and r.json() == {"detail": DISK_FULL}
        assert list(settings.tmp_dir.iterdir()) == []
        # the disk is filled by something else: uploads and database writes are 507, never 500
        _fill(small_disk / "ballast")
        with open(small, "rb") as fh:
            r = c.post(f"/api/projects/{pid}/scans", files={"file": ("small.ply", fh)}, headers=h)
        assert r.status_code == 507 and r.json()["detail"] == DISK_FULL, r.text
        assert list(settings.tmp_dir.iterdir()) == []
        codes = set()
        for i in range(300):
            r = c.post("/api/projects", json={"name": f"project {i} " + "x" * 150}, headers=h)
            codes.add(r.status_code)
            if r.status_code == 507:
                assert r.json() == {"detail": DISK_FULL}
                break
        assert codes <= {201, 507} and 507 in codes, codes
        # space freed: everything works again, same server
        (small_disk / "ballast").unlink()
        r = c.post("/api/projects", json={"name": "after"}, headers=h)
        assert r.status_code == 201, r.text
        with open(small, "rb") as fh:
            r = c.post(f"/api/projects/{pid}/scans", files={"file": ("small.ply", fh)}, headers=h)
        assert r.status_code == 201 and r.json()["points"] == 2000, r.text
        assert c.get(f"/api/projects/{pid}", headers=h).json()["scans"][0]["points"] == 2000


def test_a_partial_upload_goes_even_when_its_last_flush_fails(tmp_path):
    part = _FilePart("file", tmp_path, 10**9, (".ply",))
    part.path = tmp_path / "upload.partial.ply"

    class Full:
        def close(self) -> None:
            raise OSError(errno.ENOSPC, "No space left on device")

    part.path.write_bytes(b"x" * 100)
    part.fh = Full()
    with pytest.raises(OSError):
        part.close(keep=True)
    assert not part.path.exists()


def test_job_errors_say_what_a_user_can_act_on():
    assert reason(OSError(errno.ENOSPC, "No space left on device")) == DISK_FULL
    wrapped = RuntimeError("writing failed")
    wrapped.__cause__ = OSError(errno.EDQUOT, "Disk quota exceeded")
    assert reason(wrapped) == DISK_FULL
    assert disk_full(OperationalError("INSERT", {}, Exception("database or disk is full")))
    assert reason(BrokenProcessPool("A process in the process pool was terminated abruptly")).startswith(WORKER_LOST)
    assert reason(MemoryError()).startswith(WORKER_LOST)
    assert reason(ValueError("bug")) is None and not disk_full(OSError(errno.EACCES, "denied"))
    assert describe_exit(-signal.SIGKILL).startswith(WORKER_LOST)
