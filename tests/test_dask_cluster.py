"""`sbsc detect --scheduler` on a real Dask cluster: a `dask scheduler` and two `dask worker`
processes on 127.0.0.1; the detections are those of the local run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sbsc_core.cli import main
from sbsc_core.imaging import partition
from sbsc_core.paths import sample_projects_dir
from sbsc_core.simulate.scenarios import simulate_scene

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
DASK = Path(sys.executable).with_name("dask")


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=15)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """The scheduler's address; every process is in its own group, killed at the end."""
    if not DASK.exists():
        pytest.skip("the dask command is not installed")
    tmp = tmp_path_factory.mktemp("dask")
    info = tmp / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    procs: list[subprocess.Popen] = []
    log = open(tmp / "cluster.log", "w")
    try:
        procs.append(subprocess.Popen(
            [str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
             "--scheduler-file", str(info)], env=env, stdout=log, stderr=subprocess.STDOUT,
            start_new_session=True, cwd=tmp))
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert info.exists(), (tmp / "cluster.log").read_text()
        address = json.loads(info.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen(
                [str(DASK), "worker", address, "--host", "127.0.0.1", "--nworkers", "1", "--nthreads", "1",
                 "--no-dashboard", "--memory-limit", "0"], env=env, stdout=log, stderr=subprocess.STDOUT,
                start_new_session=True, cwd=tmp))
        from distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=120)
        yield address
    finally:
        _stop(procs)
        log.close()
    assert all(p.poll() is not None for p in procs)


@pytest.fixture(scope="module")
def room(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("room") / "scan"
    simulate_scene(sample_projects_dir() / "one_room.yaml", out, seed=3, angular_step_deg=0.15)
    return out


def _detect(room: Path, out: Path, *extra: str) -> dict:
    rc = main(["-q", "detect", str(room / "scan.ply"), "--models", str(room / "models"),
               "--expected", str(room / "expected.json"), "--out", str(out), *extra])
    assert rc == 0
    return json.loads((out / "detections.json").read_text())


def test_detect_on_a_dask_cluster_equals_the_local_run(cluster, room, tmp_path, monkeypatch):
    local = _detect(room, tmp_path / "local")
    monkeypatch.setattr(partition, "PART_POINTS", 1 << 20)  # the file is read by several tasks
    remote = _detect(room, tmp_path / "cluster", "--scheduler", cluster)
    assert len(local["detections"]) >= 10
    assert remote == local
    assert not list(tmp_path.glob(".sbsc-partitions-*")), "scratch partitions left behind"
    for name in ("rois.json",):
        assert (tmp_path / "cluster" / name).read_text() == (tmp_path / "local" / name).read_text()


def test_unreachable_scheduler_is_a_one_line_error(room, tmp_path, capsys):
    rc = main(["-q", "detect", str(room / "scan.ply"), "--models", str(room / "models"),
               "--out", str(tmp_path / "x"), "--scheduler", "tcp://127.0.0.1:9"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "--scheduler" in err and "\n" not in err
    assert not (tmp_path / "x").exists()
