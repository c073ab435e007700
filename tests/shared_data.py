"""Third-party files the tests read but the repository does not hold (they belong to other projects).

They live in a ``shared/data/`` folder beside the project: ``../shared/data`` of the project's
root, or of a folder above it (a git worktree under ``wt/``), or ``$SBSC_SHARED_DATA``.
A test that needs one skips, saying which folder is missing, where it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def find_shared_data(name: str) -> Path | None:
    """``shared/data/<name>`` of the nearest ``shared`` folder beside the project or above it."""
    env = os.environ.get("SBSC_SHARED_DATA")
    candidates = [Path(env) / name] if env else []
    candidates += [parent / "shared" / "data" / name for parent in ROOT.parents]
    return next((c for c in candidates if c.is_dir()), None)


def shared_data(name: str) -> Path:
    """The folder ``shared/data/<name>``, or skip the calling test with the reason."""
    path = find_shared_data(name)
    if path is None:
        pytest.skip(f"shared/data/{name} not found beside {ROOT} or above it (set SBSC_SHARED_DATA): "
                    "these third-party files are not part of the repository")
    return path
