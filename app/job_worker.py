"""The worker process of one job: loads the runner, runs it into the job's folder,
imports the results and prepares the 3D scene, or fails the job with a reason."""

from __future__ import annotations

import contextlib
import importlib
import os
import re
import shutil
import time
import traceback
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sqlalchemy import select, update

from sbsc_core.errors import InputError, SbscError
from sbsc_core.stages import Stage

from .config import AppSettings
from .db import Database
from .failures import reason as failure_reason
from .job_processes import _watch_parent, log
from .job_progress import JobAbandoned, ProgressWriter
from .libraries import models_dir
from .models import Job, Project, Scan, utcnow
from .results import import_results


def job_dir(settings: AppSettings, project_id: int, job_id: int) -> Path:
    return settings.projects_dir / str(project_id) / "jobs" / str(job_id)


def load_runner(spec: str) -> Callable:
    module, _, name = spec.partition(":")
    return getattr(importlib.import_module(module), name or "detect_to_dir")


ADMIN_LOG = "job.admin.log"


_ABS_PATH = re.compile(r"(?<![\w.:/])(?:/[^\s/'\"`:;,()\[\]]+)+/([^\s/'\"`:;,()\[\]]+)")


def redact(text: str, data_dir: Path | str | None = None) -> str:
    """``text`` without server paths: the data dir prefix goes, other absolute paths keep
    only their last component (``/srv/sbsc/projects/3/scans/ab_x.ply`` -> ``ab_x.ply``)."""
    if data_dir:
        text = text.replace(str(Path(data_dir)) + os.sep, "").replace(str(Path(data_dir)), "<data>")
    return _ABS_PATH.sub(lambda m: m.group(1), text)


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
        models = models_dir(s, job.models_id, settings.data_dir)
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


def runner_expected(counts: dict | None, storeys: dict | None) -> object:
    """What the runner gets as ``expected``: the counts, with the storeys' counts when given."""
    if counts is None or not storeys:
        return counts
    from sbsc_core.io.documents import ExpectedCounts

    return ExpectedCounts(dict(counts), {sid: dict(c) for sid, c in storeys.items()})
