"""Where the bundled sample projects and the default model library live."""

from __future__ import annotations

import os
from pathlib import Path


def sample_projects_dir() -> Path:
    """``sample_projects/`` of the source tree, or ``$SBSC_SAMPLE_PROJECTS``."""
    env = os.environ.get("SBSC_SAMPLE_PROJECTS")
    if env:
        return Path(env)
    return Path(__file__).resolve().parent.parent / "sample_projects"


def bundled_models_dir() -> Path:
    """The bundled model library of the 13 classes (contract 2)."""
    return sample_projects_dir() / "models"
