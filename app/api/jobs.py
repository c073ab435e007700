"""Detection jobs: submit, look at, follow (server-sent events), retry, read the log."""

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

from ..jobs import TERMINAL, parse_expected
from ..models import Job, Scan
from ..results import job_dict
from .deps import DB, Jobs, ReadSession, Reviewer, Settings, open_project

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


@router.post("/projects/{pid}/jobs", status_code=202)
def submit_job(pid: int, user: Reviewer, db: DB, jobs: Jobs, body: NewJob | None = None) -> dict:
    """Queue a detection run over all the project's scans with its model library."""
    try:
        expected = parse_expected(body.expected if body else None)
    except InputError as exc:
        raise HTTPException(422, str(exc)) from None
    with db.write() as s:
        project = open_project(s, pid)
        if not s.scalar(select(func.count(Scan.id)).where(Scan.project_id == pid)):
            raise HTTPException(409, f"project {pid} has no scan yet; upload one first")
        job = Job(project_id=pid, status="queued", stage="queued", progress=0.0, expected=expected,
                  models_id=project.models_id, created_by=user.name)
        s.add(job)
        s.flush()
        out = job_dict(job)
    jobs.wake()
    return out


@router.get("/jobs/{jid}")
def get_job(jid: int, _: Reviewer, s: ReadSession) -> dict:
    return job_dict(_get_job(s, jid))


@router.post("/jobs/{jid}/retry", status_code=202)
def retry_job(jid: int, user: Reviewer, db: DB, jobs: Jobs) -> dict:
    """Queue a new run with the same inputs as a failed job (answers the new job)."""
    with db.write() as s:
        old = _get_job(s, jid)
        open_project(s, old.project_id)
        if old.status != "failed":
            raise HTTPException(409, f"job {jid} is {old.status}; only failed jobs can be retried")
        job = Job(project_id=old.project_id, status="queued", stage="queued", progress=0.0,
                  expected=old.expected, models_id=old.models_id, retry_of=old.id,
                  created_by=user.name)
        s.add(job)
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
