"""How the processes that run the method ask the C library for memory (imports no numpy).

The method makes many short-lived arrays of a few to some tens of MB (a wall's or a ceiling
tile's pixels, the points of a band). glibc's malloc serves such a block with a fresh
``mmap`` once it is bigger than its adaptive threshold, and gives it back to the kernel when
it is freed; the next array of that size is mapped again, and every page of it is faulted in
and zeroed by the kernel on first touch. On the shared 2-core machine that was about a tenth
of ``sbsc detect``'s CPU seconds (system time: 17 s of 136 s on Scenario I, 1.0 M minor page
faults; 8 s and 0.18 M with the settings below). With :data:`MALLOC_ENV` the blocks up to
32 MiB (glibc's largest threshold on 64-bit) come from the heap, and up to
``MALLOC_TRIM_THRESHOLD_`` of freed heap is kept for the next ones instead of being handed
back: the same blocks are used again without faults. Larger blocks are still mapped and
unmapped. Only the allocator changes: every value computed is the same.

glibc reads these variables when a process starts: :func:`allocator_environment` is for the
processes to start (the workers), :func:`keep_freed_memory` sets the same in the running
process (``mallopt``) and in its environment (for the processes it starts). Elsewhere than
on glibc both do nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

__all__ = ["MALLOC_ENV", "allocator_environment", "keep_freed_memory"]

_MMAP_THRESHOLD = 32 << 20  # glibc's largest M_MMAP_THRESHOLD on 64-bit (4 MiB x sizeof(long))
_TRIM_THRESHOLD = 256 << 20  # freed heap kept for the next arrays, at most

MALLOC_ENV = {"MALLOC_MMAP_THRESHOLD_": str(_MMAP_THRESHOLD), "MALLOC_TRIM_THRESHOLD_": str(_TRIM_THRESHOLD)}

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameter numbers (malloc.h)


def _glibc() -> ctypes.CDLL | None:
    """The running process's glibc, or None (another C library, another system)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.gnu_get_libc_version.restype = ctypes.c_char_p
        libc.gnu_get_libc_version()
    except (OSError, AttributeError):
        return None
    return libc


def allocator_environment() -> dict[str, str]:
    """The variables of :data:`MALLOC_ENV` that a new process should start with: none set
    already in this environment (the user's choice stays), none off glibc."""
    if any(k in os.environ for k in MALLOC_ENV) or _glibc() is None:
        return {}
    return dict(MALLOC_ENV)


def keep_freed_memory() -> bool:
    """:data:`MALLOC_ENV` in this process (``mallopt``) and in its environment (for the
    processes it starts); True when set, False when the environment already chose or off glibc."""
    env = allocator_environment()
    libc = _glibc() if env else None
    if libc is None:
        return False
    libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)
    libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD)
    os.environ.update(env)
    return True
