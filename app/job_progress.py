"""A job's progress: the span each stage covers (from sbsc_core.stages) and the throttled
writer of stage and progress, which also notices a job that is no longer ours."""

from __future__ import annotations

import time

from sqlalchemy import update

from sbsc_core.stages import stage_spans

from .db import Database
from .models import Job, utcnow

STAGE_SPANS: dict[str, tuple[float, float]] = {
    "starting": (0.0, 0.02), **stage_spans(0.02, 0.96), "importing": (0.96, 1.0),
}


class JobAbandoned(Exception):
    """The job is no longer ours to run (failed by the supervisor, or the server restarted)."""


def overall_progress(stage: str, fraction: float, previous: float) -> float:
    span = STAGE_SPANS.get(stage)
    if span is None:
        return previous
    lo, hi = span
    return max(previous, lo + (hi - lo) * min(1.0, max(0.0, float(fraction))))


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
