"""CPU-specific settings of the processes that run the method (imports no numpy).

On AMD Zen 4 (family 19h with AVX-512), numpy's AVX-512 sort (x86-simd-sort) is several
times slower than its AVX2 one: the memory-destination compress stores it relies on are
microcoded there (numpy/x86-simd-sort#6; OpenJDK turns its AVX-512 sort off on that family
for the same reason). The orthoimage medians and much of segmentation are sorts, so there
numpy is started with its AVX-512 kernels off - unless ``NPY_DISABLE_CPU_FEATURES`` is set.
numpy reads that variable when it is imported: :func:`prefer_fast_sort` works before the
first import of numpy in a process, :func:`numpy_environment` is for processes to start.
"""

from __future__ import annotations

import os
import re
import sys

__all__ = ["is_amd_zen4", "numpy_environment", "prefer_fast_sort"]

_AVX512_DISPATCH = "X86_V4 AVX512_ICL AVX512_SPR"  # numpy 2's AVX-512 dispatch targets


def is_amd_zen4(cpuinfo: str | None = None) -> bool:
    """True on an AMD family 19h CPU with AVX-512 (Zen 4), from /proc/cpuinfo (Linux)."""
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
                cpuinfo = fh.read(1 << 14)
        except OSError:
            return False
    family = re.search(r"^cpu family\s*:\s*(\d+)", cpuinfo, re.M)
    return ("AuthenticAMD" in cpuinfo and family is not None and int(family.group(1)) == 0x19
            and re.search(r"^flags\s*:.*\bavx512f\b", cpuinfo, re.M) is not None)


def numpy_environment() -> dict[str, str]:
    """Environment variables that a new process should start with (empty when none)."""
    if "NPY_DISABLE_CPU_FEATURES" in os.environ or not is_amd_zen4():
        return {}
    return {"NPY_DISABLE_CPU_FEATURES": _AVX512_DISPATCH}


def prefer_fast_sort() -> bool:
    """Set :func:`numpy_environment` in this process if numpy is not imported yet (and so
    for every process it starts); True when it did."""
    env = numpy_environment()
    if not env or "numpy" in sys.modules:
        return False
    os.environ.update(env)
    return True
