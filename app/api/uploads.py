"""Uploads: scans (contract 1) and zipped model libraries (contract 2), streamed to disk.

Both endpoints are ``async``: the body is parsed chunk by chunk as it arrives (see
:func:`app.storage.receive_file`); checking and storing run in the thread pool. A file
is moved into its place only after it passed the checks, and its row is committed right
after; if the commit fails the file is removed again.
"""

from __future__ import annotations

import contextlib
import shutil
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import anyio
from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse

from sbsc_core.io.scans import scan_extensions

from ..auth import Principal
from ..config import AppSettings
from ..db import Database
from ..models import ModelLibraryRow, Scan
from ..review_service import open_project
from ..storage import (
    ZIP_SUFFIXES,
    ReceivedFile,
    UploadRefused,
    check_scan,
    check_zip,
    move_into_place,
    project_file,
    receive_file,
    removed_on_failure,
    unpack_library,
)
from .deps import DB, Reviewer, Settings

router = APIRouter(prefix="/api", tags=["uploads"])


@router.get("/scan-formats")
def scan_formats(user: Reviewer) -> dict:
    """The scan formats an upload may be (contract 1): the extensions of the library's readers."""
    return {"extensions": list(scan_extensions())}


def _refusal(exc: UploadRefused) -> JSONResponse:
    return JSONResponse({"detail": exc.detail}, status_code=exc.status)


def _check_open(db: Database, pid: int) -> None:
    with db.read() as s:
        open_project(s, pid, lock=False)


async def _receive(request: Request, settings: AppSettings, max_bytes: int,
                   suffixes: tuple[str, ...]) -> ReceivedFile:
    return await receive_file(request, tmp_dir=settings.tmp_dir, max_bytes=max_bytes,
                              drain_bytes=settings.upload_drain_bytes, suffixes=suffixes)

MULTIPART_FILE = {"requestBody": {"content": {"multipart/form-data": {"schema": {
    "type": "object", "required": ["file"],
    "properties": {"file": {"type": "string", "format": "binary"}}}}}}}


class UploadSlots:
    """Concurrent uploads per user (429 beyond ``per_user``) and the bounded pool of checks.

    The checks of uploaded files run in at most ``checks`` worker threads of their own
    (each waits on a child process), never in the pool that serves ordinary requests, so
    many large uploads at once cannot starve ``/api/health`` or the review calls.
    """

    def __init__(self, per_user: int, checks: int) -> None:
        import anyio

        self.per_user = per_user
        self.active: dict[int, int] = {}
        self.limiter = anyio.CapacityLimiter(max(1, checks))

    @contextlib.contextmanager
    def slot(self, user: Principal) -> Iterator[None]:
        n = self.active.get(user.id, 0)
        if n >= self.per_user:
            raise UploadRefused(429, f"user '{user.name}' already has {n} upload(s) in progress "
                                     f"(at most {self.per_user}); try again when one has finished")
        self.active[user.id] = n + 1
        try:
            yield
        finally:
            left = self.active.get(user.id, 1) - 1
            if left > 0:
                self.active[user.id] = left
            else:
                self.active.pop(user.id, None)


def upload_slots(request: Request) -> UploadSlots:
    state = request.app.state
    if getattr(state, "upload_slots", None) is None:
        s = state.settings
        state.upload_slots = UploadSlots(s.uploads_per_user, s.upload_check_workers)
    return state.upload_slots


async def handle_upload(request: Request, settings: AppSettings, db: Database, pid: int,
                        max_bytes: int, suffixes: tuple[str, ...],
                        store: Callable[[ReceivedFile], dict],
                        user: Principal | None = None) -> dict | JSONResponse:
    """The shape every upload shares: the project must be open (423), the caller may have a
    few uploads in progress (429), the body is streamed to a temporary file (4xx refusals),
    ``store`` checks and stores it in the bounded check pool, and the temporary file is
    always removed."""
    await run_in_threadpool(_check_open, db, pid)
    slots = upload_slots(request)
    try:
        with slots.slot(user) if user is not None else contextlib.nullcontext():
            got = await _receive(request, settings, max_bytes, suffixes)
            try:
                return await anyio.to_thread.run_sync(store, got, limiter=slots.limiter)
            finally:
                got.discard()
    except UploadRefused as exc:
        return _refusal(exc)


@router.post("/projects/{pid}/scans", status_code=201, openapi_extra=MULTIPART_FILE)
async def upload_scan(pid: int, request: Request, user: Reviewer, settings: Settings, db: DB):
    """One scan file (PLY, E57, LAS/LAZ, PCD, XYZ/PTS/TXT) in the multipart field ``file``."""

    def store(got: ReceivedFile) -> dict:
        points = check_scan(got.path, got.filename, settings.scan_check_timeout_s)
        return _store_scan(db, settings, pid, got, points, user)

    return await handle_upload(request, settings, db, pid, settings.max_scan_bytes, scan_extensions(), store,
                               user)


def _store_scan(db: Database, settings: AppSettings, pid: int, got: ReceivedFile, points: int,
                user: Principal) -> dict:
    rel = project_file(pid, "scans", got.filename)
    with removed_on_failure(settings.data_dir / rel) as dest, db.write() as s:
        open_project(s, pid)
        scan = Scan(project_id=pid, filename=got.filename, path=rel.as_posix(),
                    size_bytes=got.size, sha256=got.sha256, points=points, uploaded_by=user.name)
        s.add(scan)
        s.flush()
        move_into_place(got.path, dest)
        return {"id": scan.id, "filename": scan.filename, "points": points, "bytes": got.size,
                "sha256": got.sha256}


@router.post("/projects/{pid}/models", status_code=201, openapi_extra=MULTIPART_FILE)
async def upload_models(pid: int, request: Request, user: Reviewer, settings: Settings, db: DB):
    """A zipped model library (contract 2) in the multipart field ``file``; used by later jobs."""
    return await handle_upload(request, settings, db, pid, settings.max_models_zip_bytes, ZIP_SUFFIXES,
                               lambda got: _store_models(db, settings, pid, got, user), user)


def _store_models(db: Database, settings: AppSettings, pid: int, got: ReceivedFile,
                  user: Principal) -> dict:
    s_ = settings
    check_zip(got.path, got.filename, max_entries=s_.zip_max_entries,
              max_entry_bytes=s_.zip_max_entry_bytes, max_total_bytes=s_.zip_max_total_bytes,
              max_ratio=s_.zip_max_ratio)
    rel_dir = Path("projects", str(pid), "models", uuid.uuid4().hex[:12])
    dest = settings.data_dir / rel_dir
    root, classes = unpack_library(got.path, got.filename, dest)
    try:
        with db.write() as s:
            project = open_project(s, pid)
            row = ModelLibraryRow(project_id=pid, filename=got.filename,
                                  path=root.relative_to(settings.data_dir).as_posix(),
                                  size_bytes=got.size, sha256=got.sha256, classes=classes,
                                  uploaded_by=user.name)
            s.add(row)
            s.flush()
            project.models_id = row.id
            out = {"id": row.id, "filename": row.filename, "bytes": got.size, "sha256": got.sha256,
                   "classes": sorted(classes)}
    except BaseException:
        shutil.rmtree(dest, ignore_errors=True)
        raise
    return out
