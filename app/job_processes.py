"""A job's processes seen through /proc: its process group, whose members are the
worker's (start times, so a recycled pid is never killed), how a worker ended."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import time
from pathlib import Path

log = logging.getLogger("sbsc.jobs")


def describe_exit(code: int | None) -> str:
    if code is None:
        return "worker process did not exit"
    if code == -signal.SIGKILL:  # the kernel's out-of-memory killer sends SIGKILL
        return "a worker ran out of memory or was killed (signal SIGKILL)"
    if code < 0:
        try:
            return f"worker process died (killed by signal {signal.Signals(-code).name})"
        except ValueError:
            return f"worker process died (signal {-code})"
    return f"worker process exited with code {code} before finishing"


def _proc_stat(pid: int) -> list[str] | None:
    """Fields of /proc/<pid>/stat after the command name (state is [0], pgid [2], start [19])."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return raw[raw.rindex(")") + 2:].split()


def start_time(pid: int) -> str | None:
    stat = _proc_stat(pid)
    return stat[19] if stat else None


def group_members(pgid: int) -> list[int]:
    """Live processes of process group ``pgid`` (Linux /proc; empty elsewhere)."""
    out = []
    proc = Path("/proc")
    if not proc.is_dir():
        return out
    for d in proc.iterdir():
        if d.name.isdigit():
            stat = _proc_stat(int(d.name))
            if stat and stat[2] == str(pgid) and stat[0] != "Z":
                out.append(int(d.name))
    return out


def _is_worker(pid: int) -> bool:
    """A process started by multiprocessing (a job worker or one of its pool processes)."""
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False
    return b"multiprocessing" in cmd or b"sbsc" in cmd


def kill_group(pgid: int, leader_start: str | None = None) -> int:
    """SIGKILL the job process group ``pgid``; returns how many processes it had.

    The group is only killed while it is ours: its leader (the worker) still has the start
    time we recorded, or the leader is gone and every member is a multiprocessing child.
    """
    if not hasattr(os, "killpg") or pgid <= 1 or pgid == os.getpgid(0):
        return 0
    members = group_members(pgid)
    if not members:
        return 0
    if pgid in members:
        if leader_start is not None and start_time(pgid) != leader_start:
            return 0  # the pid was reused by something else
    elif not all(_is_worker(p) for p in members):
        return 0
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signal.SIGKILL)
    return len(members)


class GroupFiles:
    """One file per running job's process group under ``<data>/run/``: ``<job>.pgid`` holding
    ``pgid start-time``. Written when a worker starts, removed once its group is gone, read at
    start-up to reap the groups a crashed server left behind."""

    def __init__(self, data_dir: Path) -> None:
        self.dir = Path(data_dir) / "run"

    def write(self, jid: int, pgid: int) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        tmp = self.dir / f"{jid}.pgid.tmp"
        tmp.write_text(f"{pgid} {start_time(pgid) or '-'}\n")
        os.replace(tmp, self.dir / f"{jid}.pgid")

    def remove(self, jid: int) -> None:
        with contextlib.suppress(FileNotFoundError):
            (self.dir / f"{jid}.pgid").unlink()

    def reap_all(self) -> int:
        """Kill every recorded group that is still alive; returns the processes killed."""
        killed = 0
        if not self.dir.is_dir():
            return 0
        for f in sorted(self.dir.glob("*.pgid")):
            try:
                pgid_s, start = f.read_text().split()[:2]
                killed += kill_group(int(pgid_s), None if start == "-" else start)
            except (OSError, ValueError):
                pass
            with contextlib.suppress(FileNotFoundError):
                f.unlink()
        return killed


def _watch_parent(parent_pid: int, interval_s: float = 0.5) -> None:
    """End this worker and its process group (its pool processes) when the server has gone."""
    def loop() -> None:
        while True:
            time.sleep(interval_s)
            if os.getppid() != parent_pid:
                with contextlib.suppress(OSError):
                    if hasattr(os, "killpg") and os.getpgid(0) == os.getpid():
                        os.killpg(0, signal.SIGKILL)  # this process is in the group too
                os._exit(70)
    threading.Thread(target=loop, name="sbsc-parent-watch", daemon=True).start()
