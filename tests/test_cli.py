"""The command line: help, exit codes and one-line errors."""

import subprocess
import sys

from sbsc_core.cli import build_parser, main


def test_help_lists_every_contract_command() -> None:
    text = build_parser().format_help()
    for cmd in ("simulate", "detect", "evaluate", "serve", "user", "export-ifc", "compare"):
        assert cmd in text


def test_console_script_runs() -> None:
    res = subprocess.run([sys.executable, "-m", "sbsc_core", "--help"], capture_output=True, text=True)
    assert res.returncode == 0
    assert "simulate" in res.stdout


def test_bad_settings_file_is_one_line_error(tmp_path, capsys) -> None:
    bad = tmp_path / "settings.yaml"
    bad.write_text("depth: {mu_x: 3}\n")
    import pytest

    from sbsc_core.errors import InputError
    from sbsc_core.settings import load_settings

    with pytest.raises(InputError, match=r"settings.yaml.depth.mu_x: unknown setting"):
        load_settings(bad)


def test_unknown_scenario_is_rejected_by_the_parser() -> None:
    try:
        main(["simulate", "--scenario", "III", "--out", "/tmp/x"])
    except SystemExit as exc:
        assert exc.code == 2
    else:
        raise AssertionError("expected SystemExit")
