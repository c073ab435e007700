"""What a user can act on when something fails for want of resources: a full disk, a worker
that ran out of memory or was killed.

:func:`disk_full` recognises a full disk in any layer (``OSError`` ENOSPC / EDQUOT, SQLite's
"database or disk is full", PostgreSQL's ``DiskFull``), also when wrapped in another exception;
the app answers it with 507 (:data:`DISK_FULL`). :func:`reason` words a job's failure.
"""

from __future__ import annotations

import errno

DISK_FULL = "no space left on the data disk; free some space (or ask an administrator) and try again"
WORKER_LOST = "a worker ran out of memory or was killed"
_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
_FULL_TEXT = ("database or disk is full", "no space left on device", "could not extend file",
              "disk quota exceeded")


def _chain(exc: BaseException):  # noqa: ANN202 - the exception and what caused it
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        yield exc
        exc = exc.__cause__ or exc.__context__ or getattr(exc, "orig", None)


def disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or its cause) says the disk or the database is full."""
    for e in _chain(exc):
        if isinstance(e, OSError) and e.errno in _FULL_ERRNOS:
            return True
        if type(e).__name__ == "DiskFull" or any(t in str(e).lower() for t in _FULL_TEXT):
            return True
    return False


def worker_lost(exc: BaseException) -> bool:
    """Whether ``exc`` says a worker process died under the job (a broken pool, no memory)."""
    names = {type(e).__name__ for e in _chain(exc)}
    return bool(names & {"BrokenProcessPool", "MemoryError", "KilledWorker", "BrokenPipeError"})


def reason(exc: BaseException) -> str | None:
    """A job's error a user can act on, or None when it is an internal error."""
    if disk_full(exc):
        return DISK_FULL
    if worker_lost(exc):
        return f"{WORKER_LOST}; retry the job, with fewer scans at once or on a machine with more memory"
    return None
