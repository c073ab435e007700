"""Detection jobs: queued in the database, run in worker processes, watched by a supervisor.

The ``jobs`` table is the queue. A supervisor thread in the server claims queued jobs
(``queued`` -> ``running``, stamped with this server's ``owner`` id) while fewer than
``job_workers`` run, and starts one spawned process per job. The worker runs the
library's ``detect_to_dir`` (or the runner named by ``SBSC_JOB_RUNNER``), writes its stage
and progress to the database as it goes and imports the results in one transaction.

Every way a job can end leaves it ``succeeded`` or ``failed`` with a reason:

- the runner raises: ``failed`` with its one-line message;
- the worker process dies (killed, crashed): the supervisor sees its exit code and fails it;
- it runs longer than ``job_timeout_s``: killed and failed;
- the server stops: its workers are stopped and their jobs failed; after a crash of the
  server, start-up fails every job still ``running`` ("server restarted") while ``queued``
  jobs simply run; a worker whose server died notices (its parent changes) and exits.

A worker only writes while its job is still ``running`` under its owner, so a job that the
supervisor has given up can never be overwritten by a late worker.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import multiprocessing as mp
import os
import re
import shutil
import signal
import threading
import time
import traceback
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sqlalchemy import select, update

from sbsc_core.errors import InputError, SbscError
from sbsc_core.io.documents import CountLimits, parse_expected_field
from sbsc_core.stages import Stage, stage_spans

from .config import AppSettings
from .db import Database
from .failures import reason as failure_reason
from .models import Job, ModelLibraryRow, Project, Scan, utcnow
from .results import import_results

log = logging.getLogger("sbsc.jobs")

# Overall progress: the span of 0..1 each stage covers: the worker's start, the pipeline's stages
# (sbsc_core.stages, every one of them), then importing the results.
STAGE_SPANS: dict[str, tuple[float, float]] = {
    "starting": (0.0, 0.02), **stage_spans(0.02, 0.96), "importing": (0.96, 1.0),
}
TERMINAL = ("succeeded", "failed", "cancelled")
MAX_EXPECTED_CLASSES = 200  # keys of a job's ``expected`` counts
MAX_EXPECTED_COUNT = 100_000  # instances of one class on one floor
MAX_EXPECTED_STOREYS = 500  # storeys of a job's per-storey expected counts


class JobAbandoned(Exception):
    """The job is no longer ours to run (failed by the supervisor, or the server restarted)."""


def overall_progress(stage: str, fraction: float, previous: float) -> float:
    span = STAGE_SPANS.get(stage)
    if span is None:
        return previous
    lo, hi = span
    return max(previous, lo + (hi - lo) * min(1.0, max(0.0, float(fraction))))


def job_dir(settings: AppSettings, project_id: int, job_id: int) -> Path:
    return settings.projects_dir / str(project_id) / "jobs" / str(job_id)


def load_runner(spec: str) -> Callable:
    module, _, name = spec.partition(":")
    return getattr(importlib.import_module(module), name or "detect_to_dir")


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


ADMIN_LOG = "job.admin.log"
_ABS_PATH = re.compile(r"(?<![\w.:/])(?:/[^\s/'\"`:;,()\[\]]+)+/([^\s/'\"`:;,()\[\]]+)")


def redact(text: str, data_dir: Path | str | None = None) -> str:
    """``text`` without server paths: the data dir prefix goes, other absolute paths keep
    only their last component (``/srv/sbsc/projects/3/scans/ab_x.ply`` -> ``ab_x.ply``)."""
    if data_dir:
        text = text.replace(str(Path(data_dir)) + os.sep, "").replace(str(Path(data_dir)), "<data>")
    return _ABS_PATH.sub(lambda m: m.group(1), text)


# --------------------------------------------------------------------------- process groups


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


# --------------------------------------------------------------------------- worker side


class ProgressWriter:
    """The ``progress(stage, fraction)`` callback: throttled writes, checks the job is ours."""

    def __init__(self, db: Database, job_id: int, owner: str, min_interval_s: float) -> None:
        self.db, self.job_id, self.owner, self.min_interval_s = db, job_id, owner, min_interval_s
        self.stage = ""
        self.progress = 0.0
        self.last = 0.0

    def __call__(self, stage: str, fraction: float, *, force: bool = False) -> None:
        progress = overall_progress(stage, fraction, self.progress)
        now = time.monotonic()
        if not force and stage == self.stage and now - self.last < self.min_interval_s:
            return
        self.stage, self.progress, self.last = stage, progress, now
        with self.db.write() as s:
            n = s.execute(update(Job).where(Job.id == self.job_id, Job.status == "running",
                                            Job.owner == self.owner)
                          .values(stage=stage[:100], progress=progress, updated_at=utcnow())).rowcount
        if n == 0:
            raise JobAbandoned(f"job {self.job_id} is no longer running here")


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


def run_job(job_id: int, owner: str, settings_data: dict, parent_pid: int) -> None:
    """Entry point of a worker process: its own session and process group, so that the
    supervisor ends it with every process it started (``killpg``)."""
    if hasattr(os, "setsid"):
        with contextlib.suppress(OSError):
            os.setsid()
    settings = AppSettings(**settings_data)
    _watch_parent(parent_pid)
    # the pipeline's scratch (partitions) under <data>/tmp, which start-up empties: a killed
    # job leaves no scratch folder behind in its job folder
    scratch = settings.tmp_dir / f"job-{job_id}-{uuid.uuid4().hex[:8]}"
    with contextlib.suppress(OSError):
        scratch.mkdir(parents=True, exist_ok=True)
        os.environ["SBSC_SCRATCH_DIR"] = str(scratch)
    db = Database(settings.db_url)
    try:
        _run(db, settings, job_id, owner)
    finally:
        db.dispose()
        shutil.rmtree(scratch, ignore_errors=True)


def _run(db: Database, settings: AppSettings, job_id: int, owner: str) -> None:
    with db.read() as s:
        job = s.get(Job, job_id)
        if job is None or job.status != "running" or job.owner != owner:
            return
        scans = [settings.data_dir / p for p in s.scalars(
            select(Scan.path).where(Scan.project_id == job.project_id).order_by(Scan.id))]
        models_rel = s.scalar(select(ModelLibraryRow.path).where(ModelLibraryRow.id == job.models_id)) \
            if job.models_id else None
        expected = runner_expected(dict(job.expected) if job.expected else None, job.expected_storeys)
        out = settings.data_dir / job.out_dir
        project_id = job.project_id
    out.parent.mkdir(parents=True, exist_ok=True)
    progress = ProgressWriter(db, job_id, owner, settings.progress_min_interval_s)
    with open(out.parent / "job.log", "a", encoding="utf-8") as logf:
        def say(msg: str) -> None:
            """A line of the job's log (shown to reviewers): without server paths."""
            logf.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {redact(msg, settings.data_dir)}\n")
            logf.flush()

        def admin(text: str) -> None:
            """The admin-only log (full tracebacks, paths): ``job.admin.log``."""
            with open(out.parent / ADMIN_LOG, "a", encoding="utf-8") as fh:
                fh.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {text}\n")

        try:
            progress("starting", 1.0, force=True)
            if not scans:
                raise InputError("project", "no scan uploaded yet")
            from sbsc_core.paths import bundled_models_dir

            models = settings.data_dir / models_rel if models_rel else bundled_models_dir()
            say(f"job {job_id}: {len(scans)} scan(s), models {models.name}")
            admin(f"job {job_id}: scans {[str(p) for p in scans]}, models {models}, pid {os.getpid()}")
            runner = load_runner(settings.job_runner)
            cluster = os.environ.get("SBSC_DASK_SCHEDULER")  # run on a Dask cluster (sbsc detect --scheduler)
            summary = runner(scans, models, expected=expected, out=out, log=say, progress=progress,
                             **({"scheduler": cluster} if cluster else {}))
            say(f"finished: {summary}")
            progress("importing", 0.0, force=True)
            _prepare_viewer(settings, project_id, scans, say)
            _finish_succeeded(db, settings, job_id, owner, out)
            say("results stored")
        except JobAbandoned as exc:
            say(f"stopped: {exc}")
        except SbscError as exc:
            say(f"failed: {exc}")
            admin(f"failed: {exc}")
            _finish_failed(db, job_id, owner, redact(str(exc), settings.data_dir))
        except Exception as exc:  # noqa: BLE001 - the job must end failed with a reason
            with contextlib.suppress(OSError):
                admin(traceback.format_exc())
            log.error("job %d: internal error\n%s", job_id, traceback.format_exc())
            known = failure_reason(exc)  # a full disk, a lost worker: what the user can act on
            with contextlib.suppress(OSError):  # the log itself may be on the full disk
                say(f"failed: {known}" if known else
                    f"failed: internal error ({type(exc).__name__}); the details are in the administrator's log")
            _finish_failed(db, job_id, owner, known or f"internal error ({type(exc).__name__}); "
                                              "an administrator can read the details in the job's admin log")


def _prepare_viewer(settings: AppSettings, project_id: int, scans: list[Path],
                    say: Callable[[str], None]) -> Any:
    """Compute the 3D scene's scan level of detail now (reading the scans in chunks), so the
    first view opens in seconds; returns it (a ``ScanLod``), or None when not prepared."""
    if not settings.viewer:
        return None
    t = time.monotonic()
    try:
        from .viewer.lod import scan_lod
        from .viewer.scene import SceneSettings

        ss = SceneSettings()
        lod = scan_lod(scans, ss.max_points, settings.projects_dir / str(project_id) / "viewer",
                       ss.overview_points)
    except ImportError as exc:
        say(f"3D view not prepared ({exc})")
        return None
    except (SbscError, OSError, ValueError) as exc:  # the results matter more than the 3D view
        say(f"3D view not prepared: {exc}")
        return None
    say(f"3D view prepared in {time.monotonic() - t:.1f} s")
    return lod


def _finish_succeeded(db: Database, settings: AppSettings, job_id: int, owner: str, out: Path) -> None:
    """Import the results and mark the job succeeded, all in one transaction."""
    with db.write() as s:
        job = s.get(Job, job_id, with_for_update=True)
        if job is None or job.status != "running" or job.owner != owner:
            raise JobAbandoned(f"job {job_id} is no longer running here")
        project = s.get(Project, job.project_id, with_for_update=True)
        if project.status != "open":
            job.status, job.error = "failed", "the project was signed off while the job ran"
            job.finished_at = job.updated_at = utcnow()
            return
        import_results(s, job, out, settings.data_dir)
        job.status, job.stage, job.progress = "succeeded", Stage.DONE.value, 1.0
        job.finished_at = job.updated_at = utcnow()
        s.flush()
        from .review_service import carry_over

        carry_over(s, project.current_job_id, job)  # decisions on what is found again carry over
        project.current_job_id = job.id


def _finish_failed(db: Database, job_id: int, owner: str, reason: str) -> None:
    with db.write() as s:
        s.execute(update(Job).where(Job.id == job_id, Job.status == "running", Job.owner == owner)
                  .values(status="failed", error=reason[:2000], finished_at=utcnow(),
                          updated_at=utcnow()))


# --------------------------------------------------------------------------- server side


class JobManager:
    """The supervisor: claims queued jobs, starts and reaps workers, fails lost jobs."""

    def __init__(self, settings: AppSettings, db: Database) -> None:
        self.settings, self.db = settings, db
        self.owner = uuid.uuid4().hex
        self.procs: dict[int, mp.process.BaseProcess] = {}
        self.started: dict[int, float] = {}
        self.groups = GroupFiles(settings.data_dir)
        self._leaders: dict[int, str | None] = {}
        self._ctx = mp.get_context("spawn")
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._thread: threading.Thread | None = None

    # lifecycle ---------------------------------------------------------------------
    def start(self) -> None:
        self.recover()
        self._thread = threading.Thread(target=self._loop, name="sbsc-job-supervisor", daemon=True)
        self._thread.start()

    def recover(self) -> int:
        """Reap the worker processes a crashed server left behind, fail the jobs it left
        running; queued ones will simply run."""
        killed = self.groups.reap_all()
        if killed:
            log.warning("killed %d orphaned worker process(es) of a previous server", killed)
        with self.db.write() as s:
            jobs = s.scalars(select(Job).where(Job.status == "running", Job.owner != self.owner)).all()
            for job in jobs:
                job.status = "failed"
                job.error = f"server restarted while the job was running (stage '{job.stage}')"
                job.finished_at = job.updated_at = utcnow()
        if jobs:
            log.warning("marked %d job(s) left running by a previous server as failed", len(jobs))
        return len(jobs)

    def wake(self) -> None:
        self._wake.set()

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
        for jid, proc in list(self.procs.items()):
            self._end_group(jid, proc)
            self._fail(jid, "server shut down while the job was running (stage '{stage}')")
        self.procs.clear()

    # loop --------------------------------------------------------------------------
    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                self.tick()
            except Exception:  # noqa: BLE001 - keep supervising whatever happened
                log.exception("job supervisor tick failed")
            self._wake.wait(self.settings.job_poll_s)
            self._wake.clear()

    def tick(self) -> None:
        self._reap()
        while not self._stop.is_set() and len(self.procs) < max(1, self.settings.job_workers):
            jid = self._claim_next()
            if jid is None:
                break
            self._spawn(jid)

    def _reap(self) -> None:
        self._stop_cancelled()
        for jid, proc in list(self.procs.items()):
            if proc.is_alive():
                if time.monotonic() - self.started[jid] > self.settings.job_timeout_s:
                    self._end_group(jid, proc)
                    self._fail(jid, f"timed out after {self.settings.job_timeout_s:.0f} s "
                                    "(stage '{stage}')")
                    self._forget(jid)
                continue
            proc.join(1)
            self._end_group(jid, proc)  # pool processes of a worker that died or finished
            self._fail(jid, describe_exit(proc.exitcode) + " during stage '{stage}'")
            self._forget(jid)

    def _stop_cancelled(self) -> None:
        """Stop the workers of jobs cancelled meanwhile (``DELETE /api/jobs/{jid}``)."""
        if not self.procs:
            return
        with self.db.read() as s:
            gone = set(s.scalars(select(Job.id).where(Job.id.in_(list(self.procs)),
                                                      Job.status == "cancelled")))
        for jid in gone:
            self._end_group(jid, self.procs[jid], grace_s=5.0)
            log.info("job %d cancelled: worker stopped", jid)
            self._forget(jid)

    def _end_group(self, jid: int, proc: mp.process.BaseProcess, grace_s: float = 0.0) -> None:
        """Kill the job's whole process group (the worker and every process it started)."""
        if grace_s and proc.is_alive():
            proc.terminate()
            proc.join(grace_s)
        if proc.pid is not None:
            kill_group(proc.pid, self._leaders.get(jid))
        if proc.is_alive():
            proc.kill()
        proc.join(5)
        if proc.pid is None or not group_members(proc.pid):
            self.groups.remove(jid)

    def _forget(self, jid: int) -> None:
        self.procs.pop(jid, None)
        self.started.pop(jid, None)
        self._leaders.pop(jid, None)

    def _claim_next(self) -> int | None:
        with self.db.write() as s:
            job = s.scalars(select(Job).where(Job.status == "queued").order_by(Job.id).limit(1)
                            .with_for_update(skip_locked=True)).first()
            if job is None:
                return None
            job.status, job.stage, job.progress = "running", "starting", 0.0
            job.owner, job.error = self.owner, None
            job.started_at = job.updated_at = utcnow()
            job.out_dir = (job_dir(self.settings, job.project_id, job.id) / "out") \
                .relative_to(self.settings.data_dir).as_posix()
            return job.id

    def _spawn(self, jid: int) -> None:
        data = self.settings.model_dump(mode="json")
        proc = self._ctx.Process(target=run_job, args=(jid, self.owner, data, os.getpid()),
                                 name=f"sbsc-job-{jid}")
        try:
            proc.start()
        except OSError as exc:
            self._fail(jid, f"could not start a worker process ({exc})")
            return
        self.procs[jid], self.started[jid] = proc, time.monotonic()
        self._leaders[jid] = start_time(proc.pid)
        self.groups.write(jid, proc.pid)  # the worker makes its pid its process group id
        with self.db.write() as s:
            s.execute(update(Job).where(Job.id == jid, Job.owner == self.owner)
                      .values(worker_pid=proc.pid))
        log.info("job %d started in process %d", jid, proc.pid)

    def _fail(self, jid: int, reason: str) -> None:
        """Fail the job if it is still running here; ``{stage}`` in reason is filled in."""
        with self.db.write() as s:
            job = s.get(Job, jid, with_for_update=True)
            if job is None or job.status != "running" or job.owner != self.owner:
                return
            job.status, job.error = "failed", reason.replace("{stage}", job.stage)
            job.finished_at = job.updated_at = utcnow()
        log.warning("job %d failed: %s", jid, reason)

    def running(self) -> list[int]:
        return [jid for jid, p in self.procs.items() if p.is_alive()]


EXPECTED_LIMITS = CountLimits(classes=MAX_EXPECTED_CLASSES, count=MAX_EXPECTED_COUNT, storeys=MAX_EXPECTED_STOREYS)


def parse_expected(value: object) -> dict[str, int] | None:
    """``{"socket_x1": 20}`` or a whole contract-3 document ``{"schema", "counts"}``."""
    parsed = parse_expected_field(value, "expected", limits=EXPECTED_LIMITS)
    return None if parsed is None else parsed.counts


def parse_expected_storeys(value: object) -> dict[str, dict[str, int]] | None:
    """The per-storey counts of a whole contract-3 document (``storeys``: ``{"S1": {...}, ...}``).

    As ``sbsc detect --expected`` reads them (the same parser): storey ids ``S1``, ``S2``, ...
    whose counts add up to ``counts`` class by class. None when the document has no ``storeys``.
    """
    parsed = parse_expected_field(value, "expected", limits=EXPECTED_LIMITS)
    return None if parsed is None else parsed.storeys


def runner_expected(counts: dict | None, storeys: dict | None) -> object:
    """What the runner gets as ``expected``: the counts, with the storeys' counts when given."""
    if counts is None or not storeys:
        return counts
    from sbsc_core.io.documents import ExpectedCounts

    return ExpectedCounts(dict(counts), {sid: dict(c) for sid, c in storeys.items()})

