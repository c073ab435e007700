"""The allocator settings of the processes that run the method (``sbsc_core.pipeline.allocator``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from sbsc_core.pipeline.allocator import MALLOC_ENV, _glibc, allocator_environment
from sbsc_core.pipeline.worker_env import worker_environment

glibc = pytest.mark.skipif(_glibc() is None, reason="glibc only")


@glibc
def test_workers_start_with_the_allocator_settings_unless_the_user_chose(monkeypatch):
    for k in MALLOC_ENV:
        monkeypatch.delenv(k, raising=False)
    assert allocator_environment() == MALLOC_ENV
    assert MALLOC_ENV.items() <= worker_environment().items()
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "0")  # the user's choice stays
    assert allocator_environment() == {}
    assert not MALLOC_ENV.keys() & worker_environment().keys()


@glibc
def test_keep_freed_memory_sets_this_process_and_the_ones_it_starts():
    """In a fresh process: True, and its environment (that of the processes it starts) holds
    the settings; a second call, or a process whose environment chose, leaves them."""
    code = ("import json, os, sys; from sbsc_core.pipeline.allocator import keep_freed_memory as k; "
            "print(json.dumps([k(), k(), {v: os.environ.get(v) for v in sys.argv[1:]}]))")
    env = {k: v for k, v in os.environ.items() if k not in MALLOC_ENV}
    env["PYTHONPATH"] = os.pathsep.join(sys.path)
    out = subprocess.run([sys.executable, "-c", code, *MALLOC_ENV], env=env, capture_output=True, text=True,
                         check=True).stdout
    assert json.loads(out) == [True, False, MALLOC_ENV]
    env["MALLOC_MMAP_THRESHOLD_"] = "65536"
    out = subprocess.run([sys.executable, "-c", code, *MALLOC_ENV], env=env, capture_output=True, text=True,
                         check=True).stdout
    assert json.loads(out) == [False, False, {"MALLOC_MMAP_THRESHOLD_": "65536", "MALLOC_TRIM_THRESHOLD_": None}]
