"""The linter is part of the tests: ruff must pass on the whole tree."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_ruff_clean() -> None:
    res = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", str(ROOT)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_import_contracts_hold() -> None:
    """The import-linter contracts of pyproject.toml (docs/architecture.md): the web app above the
    CLI above the pipeline above BIM above the stages above io and the base; the stages never
    import the pipeline, BIM, the simulator or the app; no import cycles in any package."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this tree's packages, whatever is installed
    res = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
                          "sys.argv = ['lint-imports', '--no-cache']; sys.exit(lint_imports_command())"],
                         capture_output=True, text=True, cwd=ROOT, env=env)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-2000:]
    assert "Contracts: 3 kept, 0 broken." in res.stdout, res.stdout[-2000:]
