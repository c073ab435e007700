"""The README's main-job command (``scripts/demo.sh``) end to end on the small bundled scene."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(not (ROOT / ".venv" / "bin" / "sbsc").exists() or Path(sys.prefix).resolve()
                    != (ROOT / ".venv").resolve(), reason="demo.sh runs the project's own .venv (scripts/setup.sh)")
def test_demo_runs_simulate_detect_evaluate_into_a_new_runs_folder(tmp_path) -> None:
    runs = tmp_path / "no" / "such" / "runs"  # the script creates the run folder itself
    env = {**os.environ, "SBSC_DATA_DIR": str(tmp_path / "data")}
    res = subprocess.run(["bash", "scripts/demo.sh", "--no-serve", "--scene", "one_room", "--runs", str(runs)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert res.returncode == 0, res.stderr[-2000:]
    run = runs / "one_room"
    assert (run / "scan" / "scan.ply").is_file() and (run / "detect" / "detections.json").is_file()
    table = json.loads((run / "evaluation.json").read_text())
    assert table["total"]["instances"] == 13 and table["total"]["tp"] >= 11, table["total"]
    assert "TOTAL" in res.stdout  # the paper's Table 1 is printed
    lines = res.stdout.splitlines()
    table1 = lines[next(i for i, x in enumerate(lines) if x.startswith("Object")):
                   next(i for i, x in enumerate(lines) if x.startswith("match radius")) + 1]
    assert len(table1) > 15 and max(len(line) for line in table1) <= 100  # Table 1 fits 100 columns
    # --no-serve keeps the review project: a later `sbsc serve` opens on it
    from app.config import AppSettings
    from app.sample import find_sample_project

    settings = AppSettings(data_dir=tmp_path / "data")
    pid = find_sample_project(settings, "Sample: one_room")
    assert pid is not None and list((settings.projects_dir / str(pid) / "viewer").glob("viewer_lod_*.npz"))
    assert f"results in {runs / 'one_room'}/" in res.stdout and "sbsc serve" in res.stdout.splitlines()[-1]


def test_demo_refuses_a_busy_port_before_any_work(tmp_path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        res = subprocess.run(["bash", "scripts/demo.sh", "--port", str(port), "--runs", str(tmp_path / "runs")],
                             cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.strip() == f"demo: port {port} is busy (another program listens on it); choose another with --port P"
    assert not (tmp_path / "runs").exists()  # nothing was done
    res = subprocess.run(["bash", "scripts/demo.sh", "--port", "http"], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "--port" in res.stderr
