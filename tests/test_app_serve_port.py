"""``sbsc serve`` on a busy port: refused in one line before any work (issue 29), exit 2."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

import pytest

from .app_support import ROOT


@pytest.mark.slow
def test_a_busy_port_is_refused_in_one_line_before_any_work(tmp_path):
    data = tmp_path / "data"
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        env = {**os.environ, "SBSC_DATA_DIR": str(data), "PYTHONPATH": str(ROOT)}
        res = subprocess.run([sys.executable, "-m", "app", "serve", "--host", "127.0.0.1", "--port", str(port)],
                             env=env, capture_output=True, text=True, timeout=60, cwd=str(ROOT))
    assert res.returncode == 2, res.stderr
    assert res.stdout == ""  # nothing printed as if the app ran: no URL, no first-run token
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert f"port {port} on 127.0.0.1 is busy" in lines[0] and "--port" in lines[0]
    assert not data.exists()  # no data folder, database nor admin user made


def test_a_free_port_is_not_refused():
    from app.server import refuse_busy_port

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    refuse_busy_port("127.0.0.1", port)  # free again: no error
    refuse_busy_port("127.0.0.1", 0)
