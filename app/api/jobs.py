"""Detection jobs: submit, look at, follow (server-sent events), retry, cancel, read the log.

A project has at most one job queued (409 for a second one). A job on a project that has
been reviewed needs a manager: the new results replace the reviewed ones (the decisions on
the objects the new run finds again carry over, see ``app.review_service.carry_over``).
"""

from __future__ import annotations

import asyncio
import json
import time

from fastapi import APIRouter, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import PlainTextResponse, StreamingResponse
from pydantic import BaseModel
from sqlalchemy import func, select

from sbsc_core.errors import InputError

from ..auth import Principal
from ..jobs import TERMINAL, parse_expected, parse_expected_storeys
from ..models import Job, Project, ProjectEvent, Scan, utcnow
from ..results import job_dict
from ..review_service import is_reviewed, open_project
from .deps import DB, Jobs, Manager, ReadSession, Reviewer, Settings, get_project

router = APIRouter(prefix="/api", tags=["jobs"])

SSE_POLL_S = 0.5
SSE_KEEPALIVE_S = 15.0


class NewJob(BaseModel):
    expected: dict | None = None  # contract 3 counts, or the whole expected.json document


def _get_job(s, jid: int) -> Job:  # noqa: ANN001
    job = s.get(Job, jid)
    if job is None:
        raise HTTPException(404, f"job {jid} not found")
    return job


def check_new_job(s, project: Project, user: Principal, *, reviewed_ok: bool = False) -> None:  # noqa: ANN001
    """409 while the project has a job queued; 403 for a reviewer on a reviewed project (unless
    ``reviewed_ok``: learning and searching again keeps every decision)."""
    queued = s.scalar(select(func.count(Job.id)).where(Job.project_id == project.id,
                                                       Job.status == "queued"))
    if queued:
        raise HTTPException(409, f"project {project.id} already has a job queued; wait for it or "
                                 "cancel it")
    if not reviewed_ok and not user.may("manager") and is_reviewed(s, project):
        raise HTTPException(403, f"project {project.id} has review decisions; a new job on it "
                                 f"needs a manager (user '{user.name}' is {user.role})")


JOB_ERRORS = {403: {"description": "reviewed project: needs a manager"},
              409: {"description": "a job is already queued"}, 423: {"description": "signed off"}}


@router.post("/projects/{pid}/jobs", status_code=202, responses=JOB_ERRORS)
def submit_job(pid: int, user: Reviewer, db: DB, jobs: Jobs, body: NewJob | None = None) -> dict:
    """Queue a detection run over all the project's scans with its model library."""
    try:
        expected = parse_expected(body.expected if body else None)
        per_storey = parse_expected_storeys(body.expected if body else None)  # contract 3's storeys
    except InputError as exc:
        raise HTTPException(422, str(exc)) from None
    with db.write() as s:
        project = open_project(s, pid)
        if not s.scalar(select(func.count(Scan.id)).where(Scan.project_id == pid)):
            raise HTTPException(409, f"project {pid} has no scan yet; upload one first")
        check_new_job(s, project, user)
        job = Job(project_id=pid, status="queued", stage="queued", progress=0.0, expected=expected,
                  expected_storeys=per_storey, models_id=project.models_id, created_by=user.name)
        s.add(job)
        s.flush()
        out = job_dict(job)
    jobs.wake()
    return out


@router.get("/jobs/{jid}")
def get_job(jid: int, _: Reviewer, s: ReadSession) -> dict:
    return job_dict(_get_job(s, jid))


@router.post("/jobs/{jid}/retry", status_code=202, responses=JOB_ERRORS)
def retry_job(jid: int, user: Reviewer, db: DB, jobs: Jobs) -> dict:
    """Queue a new run with the same inputs as a failed job (answers the new job)."""
    with db.write() as s:
        old = _get_job(s, jid)
        project = open_project(s, old.project_id)
        if old.status not in ("failed", "cancelled"):
            raise HTTPException(409, f"job {jid} is {old.status}; only failed or cancelled jobs "
                                     "can be retried")
        check_new_job(s, project, user)
        job = Job(project_id=old.project_id, status="queued", stage="queued", progress=0.0,
                  expected=old.expected, expected_storeys=old.expected_storeys,
                  models_id=old.models_id, retry_of=old.id,
                  created_by=user.name)
        s.add(job)
        s.flush()
        out = job_dict(job)
    jobs.wake()
    return out


@router.delete("/jobs/{jid}", responses={403: {"description": "needs a manager"},
                                         409: {"description": "the job has already ended"}})
def cancel_job(jid: int, user: Manager, db: DB, jobs: Jobs) -> dict:
    """Cancel a queued or running job (manager); its worker is stopped, its results never used."""
    with db.write() as s:
        job = s.get(Job, jid, with_for_update=True)
        if job is None:
            raise HTTPException(404, f"job {jid} not found")
        get_project(s, job.project_id, for_update=True)
        if job.status not in ("queued", "running"):
            raise HTTPException(409, f"job {jid} is {job.status}; only a queued or running job "
                                     "can be cancelled")
        was = job.status
        now = utcnow()
        job.status, job.error, job.cancelled_by = "cancelled", f"cancelled by {user.name}", user.name
        job.finished_at = job.updated_at = now
        s.add(ProjectEvent(project_id=job.project_id, user_id=user.id, user_name=user.name, at=now,
                           kind="job_cancelled", data={"job": jid, "was": was, "stage": job.stage}))
        s.flush()
        out = job_dict(job)
    jobs.wake()
    return out


@router.get("/jobs/{jid}/log", response_class=PlainTextResponse)
def job_log(jid: int, _: Reviewer, s: ReadSession, settings: Settings) -> str:
    job = _get_job(s, jid)
    if not job.out_dir:
        return ""
    path = settings.data_dir / job.out_dir
    logf = path.parent / "job.log"
    return logf.read_text(encoding="utf-8", errors="replace")[-200_000:] if logf.is_file() else ""


@router.get("/jobs/{jid}/events", response_class=StreamingResponse,
            responses={200: {"content": {"text/event-stream": {}}}})
async def job_events(jid: int, request: Request, _: Reviewer, db: DB) -> StreamingResponse:
    """Server-sent events: a ``job`` event with the job's JSON whenever it changes, until it ends."""

    def snapshot() -> dict | None:
        with db.read() as s:
            job = s.get(Job, jid)
            return None if job is None else job_dict(job)

    first = await run_in_threadpool(snapshot)
    if first is None:
        raise HTTPException(404, f"job {jid} not found")

    async def stream():
        last, last_sent = None, time.monotonic()
        state = first
        while True:
            if state != last:
                yield f"event: job\ndata: {json.dumps(state)}\n\n"
                last, last_sent = state, time.monotonic()
                if state["status"] in TERMINAL:
                    return
            elif time.monotonic() - last_sent > SSE_KEEPALIVE_S:
                yield ": keep-alive\n\n"
                last_sent = time.monotonic()
            await asyncio.sleep(SSE_POLL_S)
            if await request.is_disconnected():
                return
            state = await run_in_threadpool(snapshot)

    return StreamingResponse(stream(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})
