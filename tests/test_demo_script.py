"""The README's main-job command (``scripts/demo.sh``) end to end on the small bundled scene."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(not (ROOT / ".venv" / "bin" / "sbsc").exists() or Path(sys.prefix).resolve()
                    != (ROOT / ".venv").resolve(), reason="demo.sh runs the project's own .venv (scripts/setup.sh)")
def test_demo_runs_simulate_detect_evaluate_into_a_new_runs_folder(tmp_path) -> None:
    runs = tmp_path / "no" / "such" / "runs"  # the script creates the run folder itself
    res = subprocess.run(["bash", "scripts/demo.sh", "--no-serve", "--scene", "one_room", "--runs", str(runs)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    run = runs / "one_room"
    assert (run / "scan" / "scan.ply").is_file() and (run / "detect" / "detections.json").is_file()
    table = json.loads((run / "evaluation.json").read_text())
    assert table["total"]["instances"] == 13 and table["total"]["tp"] >= 11, table["total"]
    assert "TOTAL" in res.stdout  # the paper's Table 1 is printed
