"""The command line under hostile use (issue 30): argument errors exit 2 through argparse,
outputs are checked before any work, messages name the user's paths only, and SIGTERM stops
the whole ``sbsc detect`` (workers, resource tracker, scratch folder)."""

from __future__ import annotations

import contextlib
import io
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sbsc_core.cli import main
from sbsc_core.paths import bundled_models_dir

ROOT = Path(__file__).resolve().parent.parent
TEMP_NAME = re.compile(r"/\.[^/\s]+\.(partial-)?[a-z0-9_]{6,}")  # .name.XXXXXXXX: a temporary file or folder


def _run(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    return code, err.getvalue()


@pytest.mark.parametrize("extra", [["--seed", "-1"], ["--seed", "x"], ["--seed", str(2**40)], ["--storeys", "0"],
                                   ["--step", "nan"], ["--step", "-1"], ["--step", "inf"]])
def test_argument_errors_exit_2_through_argparse(tmp_path, extra):
    code, err = _run(["simulate", "--scenario", "I", "--out", str(tmp_path / "o"), *extra])
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("sbsc: error: argument "), err
    assert extra[0] in lines[0] and "internal error" not in err
    assert not (tmp_path / "o").exists()


def test_outputs_are_checked_before_any_work(tmp_path):
    afile, adir = tmp_path / "afile", tmp_path / "adir"
    afile.write_text("x")
    adir.mkdir()
    missing_scan = tmp_path / "never_read.ply"  # the error comes before any input is read
    t = time.perf_counter()
    for argv, named in [
        (["detect", str(missing_scan), "--models", str(bundled_models_dir()), "--out", str(afile)], afile),
        (["detect", str(missing_scan), "--models", "x", "--out", str(tmp_path / "no" / "out")], tmp_path / "no"),
        (["simulate", "--scenario", "I", "--out", str(afile / "sub")], afile),
        (["evaluate", "--detections", "d", "--truth", "t", "--json", str(adir)], adir),
        (["export-ifc", "d.json", "--out", str(adir)], adir),
        (["compare", "--as-designed", "a", "--detections", "d", "--out", str(afile)], afile),
    ]:
        code, err = _run(argv)
        assert code == 2 and err.startswith("sbsc: error: argument --") and str(named) in err, (argv, err)
        assert not TEMP_NAME.search(err), err
    assert time.perf_counter() - t < 5.0  # nothing was read or computed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "afile"]


def test_messages_never_name_temporary_files(tmp_path):
    from sbsc_core.errors import InputError
    from sbsc_core.io.atomic import atomic_output_dir, write_json_atomic

    (tmp_path / "emptydir").mkdir()
    with pytest.raises(InputError) as exc:
        write_json_atomic(tmp_path / "emptydir", {"a": 1})
    assert "emptydir" in str(exc.value) and not TEMP_NAME.search(str(exc.value))
    out = tmp_path / "out"
    out.mkdir()
    (out / "x").mkdir()
    (out / "x" / "keep").write_text("busy")  # a folder in the way that cannot be replaced by a file
    os.chmod(out, 0o500)
    try:
        if os.geteuid() != 0:
            with pytest.raises(InputError) as exc, atomic_output_dir(out) as tmp:
                (tmp / "y").write_text("new")
            assert str(out) in str(exc.value) and not TEMP_NAME.search(str(exc.value))
    finally:
        os.chmod(out, 0o700)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _group(pgid: int) -> list[int]:
    """The live processes of process group ``pgid`` (zombies are gone)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if fields[0] != "Z" and int(fields[2]) == pgid:
            out.append(int(d.name))
    return out


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc")
def test_sigterm_stops_the_whole_detect(tmp_path):
    from .app_support import simulate_one_room

    scan = simulate_one_room(tmp_path / "sim", step_deg=0.3) / "scan.ply"
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "SBSC_SCRATCH_DIR": str(scratch), "SBSC_NO_PROGRESS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "sbsc_core.cli", "-q", "detect", str(scan), "--models",
                             str(bundled_models_dir()), "--out", str(tmp_path / "out")], env=env,
                            start_new_session=True, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        # running: its pool workers (and the resource tracker) are up and the scratch folder is in use
        while not (len(_group(proc.pid)) >= 3 and any(scratch.iterdir())):
            assert proc.poll() is None and time.monotonic() < deadline, "detect never got going"
            time.sleep(0.1)
        assert len(_group(proc.pid)) >= 3
        proc.send_signal(signal.SIGTERM)  # the main process only, as timeout(1) or a scheduler does
        code = proc.wait(30)
        time.sleep(5.0)
        left = _group(proc.pid)
        err = proc.stderr.read()
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert code == 128 + signal.SIGTERM and "stopped by SIGTERM" in err, (code, err[-500:])
    assert left == [], f"processes left in the group: {left}"
    assert list(scratch.iterdir()) == [] and not (tmp_path / "out").exists()
    assert "Traceback" not in err
