"""The command line's conventions: version, options anywhere, progress, JSON, errors, help.

One test (or a few) per convention of ``sbsc_core.cli``'s docstring.
"""

from __future__ import annotations

import argparse
import fcntl
import io
import json
import os
import pty
import re
import struct
import subprocess
import sys
import termios
import tomllib
from pathlib import Path

import numpy as np
import pytest

import sbsc_core
from sbsc_core.cli import Commands, Console, build_parser, main
from sbsc_core.paths import sample_projects_dir
from tests.bim_fixtures import detections_document, truth_document

ROOT = Path(__file__).resolve().parent.parent
COMMANDS = ("simulate", "detect", "evaluate", "export-ifc", "compare")


def _run(*args: str, cwd: Path | None = None, **kw) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "sbsc_core", *args], capture_output=True, text=True,
                          env=env, cwd=cwd, **kw)


def _run_on_tty(args: list[str], cwd: Path) -> tuple[int, str, str]:
    """Run ``sbsc`` with stderr on a pseudo-terminal of 120 columns; (code, stdout, stderr)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "sbsc_core", *args], stdout=subprocess.PIPE,
                            stderr=slave, env=env, cwd=cwd)
    os.close(slave)
    err = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the child closed the terminal
            break
        if not chunk:
            break
        err += chunk
    out = proc.stdout.read().decode()
    proc.wait(timeout=600)
    os.close(master)
    return proc.returncode, out, err.decode(errors="replace")


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def small_room(tmp_path_factory) -> Path:
    """The bundled one-room scene, coarsely scanned (fast)."""
    out = tmp_path_factory.mktemp("cli") / "scan"
    assert main(["-q", "simulate", "--scene", "one_room", "--out", str(out), "--step", "0.3", "--seed", "1"]) == 0
    return out


@pytest.fixture(scope="module")
def detected_on_tty(small_room: Path) -> tuple[int, str, str, Path]:
    """``sbsc detect --json`` with stderr on a terminal (progress bars) and stdout a pipe."""
    out = small_room.parent / "detect"
    code, stdout, stderr = _run_on_tty(
        ["detect", str(small_room / "scan.ply"), "--models", str(small_room / "models"),
         "--expected", str(small_room / "expected.json"), "--out", str(out), "--json"], small_room.parent)
    return code, stdout, stderr, out


@pytest.fixture
def detections(tmp_path) -> Path:
    p = tmp_path / "detections.json"
    p.write_text(json.dumps(detections_document(statuses={1: "pending"})))
    return p


# --------------------------------------------------------------------------- --version, help


def test_version_matches_the_package() -> None:
    res = _run("--version")
    assert res.returncode == 0
    assert res.stdout.strip() == f"sbsc {sbsc_core.__version__}"
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" in project.get("dynamic", []), "the version has one source: sbsc_core.__version__"


def test_help_lists_every_contract_command() -> None:
    res = _run("--help")
    assert res.returncode == 0
    for cmd in COMMANDS:
        assert cmd in res.stdout


def _parsers(p: argparse.ArgumentParser, name: str = "sbsc"):
    yield name, p
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


def test_every_option_and_argument_has_help_text() -> None:
    from app.cli import REGISTRARS

    missing = []
    for name, p in _parsers(build_parser(registrars=REGISTRARS)):
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            if not (action.help or "").strip() or action.help == argparse.SUPPRESS:
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
    assert missing == []
    names = [n for n, _ in _parsers(build_parser(registrars=REGISTRARS))]
    assert {"sbsc serve", "sbsc user add", *(f"sbsc {c}" for c in COMMANDS)} <= set(names)


# --------------------------------------------------------------------------- -q -v --debug anywhere


@pytest.mark.parametrize("argv", [
    ["-q", "-v", "--debug", "evaluate", "--detections", "d", "--truth", "t"],
    ["evaluate", "-q", "--detections", "d", "-v", "--truth", "t", "--debug"],
    ["-q", "evaluate", "--detections", "d", "--truth", "t", "-v", "--debug"],
])
def test_common_options_at_any_position(argv) -> None:
    args = build_parser(registrars=[]).parse_args(argv)
    assert args.quiet is True and args.verbose == 1 and args.debug is True
    assert args.command == "evaluate" and args.detections == "d"


def test_common_options_default_off() -> None:
    args = build_parser(registrars=[]).parse_args(["evaluate", "--detections", "d", "--truth", "t"])
    assert not getattr(args, "quiet", False) and not getattr(args, "verbose", 0)
    assert not getattr(args, "debug", False)


def test_verbose_adds_debug_messages_and_quiet_removes_info() -> None:
    def register(cmds: Commands) -> None:
        def talk(args) -> int:
            import logging

            logging.getLogger("sbsc").debug("a detail")
            logging.getLogger("sbsc_core.x").info("a message")
            return 0
        cmds.add("talk", help="log two lines", func=talk)

    for argv, expect in ((["talk"], ["a message"]), (["talk", "-v"], ["a detail", "a message"]),
                         (["-q", "talk"], [])):
        err = io.StringIO()
        old, sys.stderr = sys.stderr, err
        try:
            assert main(argv, registrars=[register]) == 0
        finally:
            sys.stderr = old
        assert err.getvalue().splitlines() == expect, argv


# --------------------------------------------------------------------------- progress


@pytest.mark.slow
def test_detect_shows_progress_per_stage_and_wall_on_a_terminal(detected_on_tty) -> None:
    code, stdout, stderr, out = detected_on_tty
    assert code == 0, stderr
    stages = set(re.findall(r"(\w+) +\s*\d+%\|", stderr))
    assert {"reading", "segmentation", "walls", "consensus", "writing"} <= stages, stages
    assert re.search(r"walls +100%\|.*\| 4/4 walls", stderr), "a bar counting the 4 walls"
    assert (out / "detections.json").is_file()


@pytest.mark.slow
def test_detect_json_summary_on_stdout(detected_on_tty) -> None:
    code, stdout, _, out = detected_on_tty
    summary = json.loads(stdout)  # stdout holds the JSON only
    assert summary["walls"] == 4 and summary["out"] == str(out)
    assert summary["detections"] == len(json.loads((out / "detections.json").read_text())["detections"])
    assert summary["timings"]["total"] > 0


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("tty,quiet,shown", [(True, False, True), (True, True, False), (False, False, False)])
def test_progress_only_on_a_terminal_and_not_with_quiet(monkeypatch, tty, quiet, shown) -> None:
    err = _Terminal() if tty else io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    con = Console(quiet=quiet)
    for stage, f in (("reading", 0.0), ("walls", 0.5), ("walls", 1.0), ("done", 1.0)):
        con.progress(stage, f)
    con.close()
    assert ("2/2 walls" in err.getvalue()) == shown, err.getvalue()


@pytest.mark.slow
def test_simulate_reports_each_station_and_quiet_silences_it(tmp_path) -> None:
    res = _run("simulate", "--scene", "one_room", "--out", str(tmp_path / "a"), "--step", "0.5")
    assert res.returncode == 0, res.stderr
    # stderr is a pipe: a few plain lines, no bars and no per-station progress
    assert "station 1/2" not in res.stderr and len(res.stderr.splitlines()) <= 4, res.stderr
    assert "%|" not in res.stderr and "\r" not in res.stderr
    res = _run("-v", "simulate", "--scene", "one_room", "--out", str(tmp_path / "v"), "--step", "0.5")
    assert res.returncode == 0, res.stderr
    assert re.search(r"station 1/2 .*\n(.*\n)*.*station 2/2 ", res.stderr), res.stderr  # -v: every station
    res = _run("simulate", "--scene", "one_room", "--out", str(tmp_path / "b"), "--step", "0.5", "-q", "--json")
    assert res.returncode == 0 and res.stderr == ""
    summary = json.loads(res.stdout)
    assert summary["walls"] == 4 and summary["objects"] == 13 and summary["points"] > 0


def test_simulate_names_the_bundled_scenes_when_one_is_unknown(tmp_path, capsys) -> None:
    assert main(["simulate", "--scene", "no_such_room", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "no_such_room" in err and "one_room" in err
    assert not (tmp_path / "x").exists()
    assert (sample_projects_dir() / "one_room.yaml").is_file()


# --------------------------------------------------------------------------- --json, success lines


@pytest.mark.slow
def test_evaluate_json_dash_writes_stdout_not_a_file(small_room, detected_on_tty, tmp_path) -> None:
    out = detected_on_tty[3]
    res = _run("evaluate", "--detections", str(out / "detections.json"),
               "--truth", str(small_room / "ground_truth.json"), "--json", "-", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    table = json.loads(res.stdout)
    assert table["total"]["instances"] == 13
    assert not (tmp_path / "-").exists() and list(tmp_path.iterdir()) == []
    res = _run("evaluate", "--detections", str(out / "detections.json"),
               "--truth", str(small_room / "ground_truth.json"), "--json", "table.json", cwd=tmp_path)
    assert res.returncode == 0 and json.loads((tmp_path / "table.json").read_text()) == table
    assert "Total" in res.stdout or "total" in res.stdout.lower()


def test_export_ifc_prints_a_success_line(tmp_path, detections, capsys) -> None:
    out = tmp_path / "model.ifc"
    assert main(["export-ifc", str(detections), "--out", str(out)]) == 0
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"wrote {out}") and "IFC4" in err and "8 objects" in err, err
    assert main(["export-ifc", str(detections), "--out", str(out), "--json", "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and json.loads(cap.out)["objects"] == 8


def test_compare_prints_a_success_line(tmp_path, detections, capsys) -> None:
    from sbsc_core.bim import bundled_typings
    from sbsc_core.bim.design_writer import write_as_designed_ifc

    design = tmp_path / "design.ifc"
    write_as_designed_ifc(truth_document(), design, seed=2, n_moved=1, n_removed=1, n_added=1,
                          typings=bundled_typings())
    assert main(["compare", "--as-designed", str(design), "--detections", str(detections),
                 "--out", str(tmp_path / "cmp")]) == 0
    err = capsys.readouterr().err.strip()
    assert err.startswith("wrote ") and "1 missing" in err and "1 unexpected" in err, err


# --------------------------------------------------------------------------- missing folders


@pytest.mark.parametrize("command", ["simulate", "detect", "evaluate", "export-ifc", "compare"])
def test_missing_parent_folder_is_an_error_not_created(tmp_path, detections, capsys, command) -> None:
    missing = tmp_path / "no" / "such"
    argv = {
        "simulate": ["simulate", "--scene", "one_room", "--out", str(missing / "scan")],
        "detect": ["detect", str(tmp_path / "x.ply"), "--models", str(tmp_path), "--out", str(missing / "d")],
        "evaluate": ["evaluate", "--detections", str(detections), "--truth", str(detections),
                     "--json", str(missing / "t.json")],
        "export-ifc": ["export-ifc", str(detections), "--out", str(missing / "m.ifc")],
        "compare": ["compare", "--as-designed", str(tmp_path / "d.ifc"), "--detections", str(detections),
                    "--out", str(missing / "cmp")],
    }[command]
    with pytest.raises(SystemExit) as exc:  # a usage error, before any work (issue 30)
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("sbsc: error: argument --") and "does not exist" in err, err
    assert not (tmp_path / "no").exists()


# --------------------------------------------------------------------------- errors


def _failing(exc: BaseException, warn: bool = False):
    def register(cmds: Commands) -> None:
        def boom(args) -> int:
            if warn:
                np.mean(np.array([]))  # RuntimeWarning: Mean of empty slice
                np.array([1.0]) / 0.0  # RuntimeWarning: divide by zero
                return 0
            raise exc
        cmds.add("boom", help="fail", func=boom)
    return [register]


def test_internal_error_is_one_line_with_a_hint(capsys) -> None:
    assert main(["boom"], registrars=_failing(ValueError("bad\nthing"))) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ValueError: bad thing" in err and "--debug" in err, err


def test_debug_shows_the_traceback(capsys) -> None:
    assert main(["boom", "--debug"], registrars=_failing(ValueError("bad"))) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "ValueError: bad" in err


def test_bad_input_and_usage_errors_exit_2_in_one_line(capsys, tmp_path) -> None:
    from sbsc_core.errors import InputError

    assert main(["boom"], registrars=_failing(InputError("scan.ply", "no colour"))) == 2
    assert capsys.readouterr().err == "sbsc: error: scan.ply: no colour\n"
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--scenario", "III", "--out", str(tmp_path)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--scenario" in err and "--help" in err


def test_unreadable_file_is_one_line(capsys, tmp_path) -> None:
    assert main(["boom"], registrars=_failing(PermissionError(13, "Permission denied", "/x/y.ply"))) == 2
    assert capsys.readouterr().err.startswith("sbsc: error: /x/y.ply: Permission denied")


def test_numpy_warnings_are_not_printed(capsys) -> None:
    assert main(["boom"], registrars=_failing(ValueError(), warn=True)) == 0
    assert capsys.readouterr().err == ""
    assert "PYTHONWARNINGS" not in os.environ or os.environ["PYTHONWARNINGS"] != "ignore::RuntimeWarning"


def test_console_script_runs() -> None:
    res = _run("--help")
    assert res.returncode == 0 and "simulate" in res.stdout


def test_bad_settings_file_is_one_line_error(tmp_path) -> None:
    bad = tmp_path / "settings.yaml"
    bad.write_text("depth: {mu_x: 3}\n")
    from sbsc_core.errors import InputError
    from sbsc_core.settings import load_settings

    with pytest.raises(InputError, match=r"settings.yaml.depth.mu_x: unknown setting"):
        load_settings(bad)


# --------------------------------------------------------------------------- library vs web layer


@pytest.mark.slow
def test_the_library_never_imports_the_web_layer() -> None:
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "sbsc_core").rglob("*.py")
                 if re.search(r"^\s*(import app\b|from app\b|from app\.)", p.read_text(), re.M)
                 or re.search(r"import_module\(\s*['\"]app\b", p.read_text())]
    assert offenders == []
    code = ("import pkgutil, importlib, sys, sbsc_core\n"
            "for m in pkgutil.walk_packages(sbsc_core.__path__, 'sbsc_core.'):\n"
            "    if m.name not in ('sbsc_core.__main__',): importlib.import_module(m.name)\n"
            "from sbsc_core.cli import build_parser; build_parser(registrars=[])\n"
            "bad = sorted(n for n in sys.modules if n == 'app' or n.startswith('app.'))\n"
            "assert not bad, bad\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr


def test_web_commands_register_through_the_entry_point_group() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["entry-points"]["sbsc.commands"] == {"serve": "app.cli:register_serve",
                                                         "user": "app.cli:register_user",
                                                         "import": "app.cli:register_import"}
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    res = subprocess.run([sys.executable, "-m", "app", "--help"], capture_output=True, text=True, env=env)
    assert res.returncode == 0 and "serve" in res.stdout and "user" in res.stdout and "import" in res.stdout
    res = subprocess.run([sys.executable, "-m", "app", "user", "add", "x"], capture_output=True, text=True, env=env)
    assert res.returncode == 2 and "--role" in res.stderr


@pytest.mark.parametrize(("text", "message"), [
    ("ceilings: {enabled: 'false'}\n", r"settings.yaml.ceilings.enabled: expected bool, got 'false'"),
    ("workers: 2.5\n", r"settings.yaml.workers: expected int, got 2.5"),
    ("workers: '3x'\n", r"settings.yaml.workers: expected int, got '3x'"),
    ("depth: {rotations: 90}\n", r"settings.yaml.depth.rotations: expected a list"),
    ("depth: {gain_range: [0.5]}\n", r"settings.yaml.depth.gain_range: expected a list like \[0.5, 2.0\]"),
    ("depth: {gain_range: [0.5, yes]}\n", r"settings.yaml.depth.gain_range: expected float, got True"),
])
def test_settings_values_are_checked_not_converted(tmp_path, text, message) -> None:
    from sbsc_core.errors import InputError
    from sbsc_core.settings import load_settings

    bad = tmp_path / "settings.yaml"
    bad.write_text(text)
    with pytest.raises(InputError, match=message):
        load_settings(bad)


def test_settings_values_of_the_right_kind_are_taken(tmp_path) -> None:
    from sbsc_core.settings import load_settings

    good = tmp_path / "settings.yaml"
    good.write_text("ceilings: {enabled: true}\nworkers: 1\ndepth: {gain_range: [1, 3], rotations: [0, 45]}\n")
    s = load_settings(good)
    assert s.ceilings.enabled is True and s.workers == 1
    assert s.depth.gain_range == (1.0, 3.0) and s.depth.rotations == (0.0, 45.0)
    assert all(isinstance(v, float) for v in s.depth.gain_range)
