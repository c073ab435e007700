"""As-designed IFC model of a project and its comparison with the current detections.

The upload is streamed like the other uploads (:func:`app.storage.receive_file`), read
with :func:`sbsc_core.bim.design.read_as_designed` and only then moved into place and
recorded; the newest design of a project is the one compared. The comparison
(:func:`sbsc_core.bim.compare.compare`) runs on the contract-4 document the API serves
(:func:`app.results.project_document`: rejected detections are left out, pending ones
count) and is served as JSON, as the HTML report and as a BCF file of the findings.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import HTMLResponse, JSONResponse, Response
from sqlalchemy import select
from sqlalchemy.orm import Session

from sbsc_core.errors import InputError, SbscError

from ..auth import Principal
from ..config import AppSettings
from ..db import Database
from ..models import DesignRow, Job, Project
from ..results import project_document
from ..review_service import open_project
from ..storage import ReceivedFile, UploadRefused, move_into_place, project_file, removed_on_failure
from .deps import DB, ReadSession, Reviewer, Settings, get_project
from .export import _library
from .uploads import MULTIPART_FILE, handle_upload

router = APIRouter(prefix="/api", tags=["design"])

IFC_SUFFIXES = (".ifc",)


def _models_id(s: Session, p: Project) -> int | None:
    """The library of the current results (as ``/classes``), else the project's upload."""
    if p.current_job_id is not None:
        return s.get(Job, p.current_job_id).models_id
    return p.models_id


def _read_design(settings: AppSettings, s: Session, p: Project, path: Path, filename: str):  # noqa: ANN202
    """The AsDesigned of ``path``; a bad file -> UploadRefused(422) naming ``filename``."""
    from sbsc_core.bim.design import read_as_designed

    try:
        return read_as_designed(path, _library(settings, s, _models_id(s, p)))
    except InputError as exc:
        raise UploadRefused(422, f"{filename}: {exc.reason}".splitlines()[0]) from None


@router.post("/projects/{pid}/design", status_code=201, openapi_extra=MULTIPART_FILE)
async def upload_design(pid: int, request: Request, user: Reviewer, settings: Settings, db: DB):
    """An as-designed IFC file (IFC2X3, IFC4, IFC4X3) in the multipart field ``file``."""
    return await handle_upload(request, settings, db, pid, settings.max_design_bytes, IFC_SUFFIXES,
                               lambda got: _store_design(db, settings, pid, got, user), user)


def _store_design(db: Database, settings: AppSettings, pid: int, got: ReceivedFile,
                  user: Principal) -> dict:
    with db.read() as s:
        design = _read_design(settings, s, get_project(s, pid), got.path, got.filename)
    counts = design.expected_counts()
    rel = project_file(pid, "design", got.filename)
    with removed_on_failure(settings.data_dir / rel) as dest, db.write() as s:
        open_project(s, pid)
        s.add(DesignRow(project_id=pid, filename=got.filename, path=rel.as_posix(),
                        size_bytes=got.size, sha256=got.sha256, objects=len(design.objects),
                        expected_counts=counts, uploaded_by=user.name))
        s.flush()
        move_into_place(got.path, dest)
    return {"filename": got.filename, "objects": len(design.objects), "expected_counts": counts,
            "bytes": got.size, "sha256": got.sha256}


def _comparison(s: Session, settings: AppSettings, pid: int):  # noqa: ANN202
    """(project, Comparison, orthoimage dir or None) of the newest design and current results."""
    from sbsc_core.bim.compare import compare

    p = get_project(s, pid)
    row = s.scalars(select(DesignRow).where(DesignRow.project_id == pid)
                    .order_by(DesignRow.id.desc()).limit(1)).first()
    if row is None:
        raise HTTPException(404, f"project {pid} has no as-designed model: "
                                 f"upload an IFC file to /api/projects/{pid}/design")
    if p.current_job_id is None:
        raise HTTPException(409, f"project {pid} has no finished detection job to compare with")
    try:
        design = _read_design(settings, s, p, settings.data_dir / row.path, row.filename)
        design.path = row.filename  # not the server's file system path
        comp = compare(design, project_document(s, p, id_is_ref=True))
    except UploadRefused as exc:
        raise HTTPException(422, exc.detail) from None
    except SbscError as exc:
        raise HTTPException(422, str(exc)) from None
    job = s.get(Job, p.current_job_id)
    image_dir = settings.data_dir / job.out_dir / "orthoimages" if job.out_dir else None
    return p, comp, image_dir if image_dir is not None and image_dir.is_dir() else None


def _attachment(p: Project, suffix: str) -> dict[str, str]:
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in p.name)[:60] or "project"
    return {"Content-Disposition": f'attachment; filename="{safe}-{p.id}-{suffix}"'}


@router.get("/projects/{pid}/comparison")
def get_comparison(pid: int, _: Reviewer, s: ReadSession, settings: Settings) -> JSONResponse:
    """The newest as-designed model against the current detections (``sbsc.comparison/1``)."""
    _, comp, _ = _comparison(s, settings, pid)
    return JSONResponse(comp.to_dict())


@router.get("/projects/{pid}/comparison.html", response_class=HTMLResponse)
def get_comparison_report(pid: int, _: Reviewer, s: ReadSession, settings: Settings) -> HTMLResponse:
    """The comparison as a self-contained HTML report (per-wall pictures on the orthoimages)."""
    from sbsc_core.bim.report import render_report

    _, comp, image_dir = _comparison(s, settings, pid)
    return HTMLResponse(render_report(comp, image_dir))


@router.get("/projects/{pid}/comparison.bcf", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}}})
def get_comparison_bcf(pid: int, user: Reviewer, s: ReadSession, settings: Settings) -> Response:
    """The findings (missing, displaced, unexpected) as a BCF 2.1 zip: missing objects select
    their element of the as-designed IFC, unexpected ones theirs of the as-is IFC (the
    project's ``export.ifc``), displaced ones both."""
    from sbsc_core.bim.bcf import AsIs, write_bcf

    from .export import asis_file

    p, comp, image_dir = _comparison(s, settings, pid)
    asis = AsIs(*asis_file(p))
    settings.tmp_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="comparison-", suffix=".bcf", dir=settings.tmp_dir)
    os.close(fd)
    try:
        write_bcf(comp, Path(tmp), image_dir, project_name=p.name, asis=asis, author=user.name)
        data = Path(tmp).read_bytes()
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
    return Response(data, media_type="application/octet-stream", headers=_attachment(p, "findings.bcf"))
