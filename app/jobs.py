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

import multiprocessing as mp
import os
import threading
import time
import uuid

from sqlalchemy import select, update

from sbsc_core.io.documents import CountLimits, parse_expected_field

from .config import AppSettings
from .db import Database
from .job_processes import GroupFiles, describe_exit, group_members, kill_group, log, start_time
from .job_worker import job_dir, run_job
from .models import Job, utcnow

# Overall progress: the span of 0..1 each stage covers: the worker's start, the pipeline's stages
# (sbsc_core.stages, every one of them), then importing the results.
TERMINAL = ("succeeded", "failed", "cancelled")
MAX_EXPECTED_CLASSES = 200  # keys of a job's ``expected`` counts
MAX_EXPECTED_COUNT = 100_000  # instances of one class on one floor
MAX_EXPECTED_STOREYS = 500  # storeys of a job's per-storey expected counts


# --------------------------------------------------------------------------- process groups


# --------------------------------------------------------------------------- worker side


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


