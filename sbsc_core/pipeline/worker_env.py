"""The environment of the worker processes: numpy's CPU features, set before numpy
is imported (see ``cpu_features``), and the C library's allocator (see ``allocator``); and
the readiness check of a worker."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from ..settings import DetectionSettings
from .allocator import allocator_environment
from .cpu_features import numpy_environment


def _worker_count(settings: DetectionSettings) -> int:
    return settings.workers or min(2, os.cpu_count() or 1)


def _ready() -> bool:
    """A no-op run in a worker: it has imported the whole method (this module)."""
    return True


def _environ(name: str) -> str | None:
    """An environment variable as a worker sees it."""
    return os.environ.get(name)


def worker_environment() -> dict[str, str]:
    """Environment variables for new worker processes (see :mod:`sbsc_core.pipeline.cpu_features`
    and :mod:`sbsc_core.pipeline.allocator`)."""
    return {**numpy_environment(), **allocator_environment()}


@contextlib.contextmanager
def _environment(extra: dict[str, str]) -> Iterator[None]:
    """``extra`` in os.environ while processes are started (they copy it), then as before."""
    saved = {k: os.environ.get(k) for k in extra}
    os.environ.update(extra)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
