"""Where the bundled scene descriptions and the default model library live.

They are package data of ``sbsc_core`` (``sbsc_core/data/``), so they are found the same way
in a source checkout, an editable install and a plain ``pip install`` of the wheel.
``$SBSC_SAMPLE_PROJECTS`` points at another folder of the same layout.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from .errors import InputError


def data_dir() -> Path:
    """The package's data folder: scene descriptions ``*.yaml`` and ``models/``."""
    env = os.environ.get("SBSC_SAMPLE_PROJECTS")
    if env:
        return Path(env)
    return Path(str(resources.files("sbsc_core") / "data"))


def sample_projects_dir() -> Path:
    """The folder of the bundled scenes (kept under its old name; see :func:`data_dir`)."""
    return data_dir()


def bundled_models_dir() -> Path:
    """The bundled model library of the 13 classes (contract 2)."""
    return data_dir() / "models"


def scene_names() -> list[str]:
    """Names of the bundled scene descriptions, e.g. ``one_room``, ``scenario_I``."""
    return sorted(p.stem for p in data_dir().glob("*.yaml"))


def scene_path(name: str) -> Path:
    """The description of a bundled scene by name, or ``name`` itself when it is a ``.yaml`` file."""
    if name.endswith((".yaml", ".yml")):
        return Path(name)
    path = data_dir() / f"{name}.yaml"
    if not path.is_file():
        raise InputError("--scene", f"unknown scene {name!r} (bundled: {', '.join(scene_names())};"
                         " or a path to a .yaml description)")
    return path
