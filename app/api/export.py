"""Exports: the accepted objects as IFC4 (via ``sbsc_core.bim.export``), the document as JSON."""

from __future__ import annotations

import os
import tempfile

from fastapi import APIRouter, HTTPException
from fastapi.responses import JSONResponse, Response

from sbsc_core.errors import SbscError

from ..libraries import models_dir
from ..models import Job, Project
from ..results import project_document
from ..review_service import current_signoff, signoff_dict
from .deps import ReadSession, Reviewer, Settings, get_project

router = APIRouter(prefix="/api", tags=["export"])


def _library(settings, s, models_id):  # noqa: ANN001, ANN202
    """The ModelLibrary the results were computed with (uploaded or bundled)."""
    from sbsc_core.io.models import load_model_library

    try:
        return load_model_library(models_dir(s, models_id, settings.data_dir))
    except SbscError:
        return None  # the export falls back to its own class table


def asis_file(p: Project) -> tuple[str, str]:
    """(file name, GlobalId seed) of the project's as-is IFC: what its export writes and what
    the comparison's BCF names and selects in. The seed is the project's own (id and creation
    time): the same object keeps its GlobalId across exports and re-runs."""
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in p.name)[:60] or "project"
    created = p.created_at.replace(tzinfo=None).isoformat(timespec="seconds") if p.created_at else ""
    return f"{safe}-{p.id}.ifc", f"sbsc-project/{p.id}/{created}"


@router.get("/projects/{pid}/export.ifc", response_class=Response,
            responses={200: {"content": {"application/x-step": {}}}})
def export_ifc_file(pid: int, user: Reviewer, s: ReadSession, settings: Settings) -> Response:
    """IFC4: the walls, openings and the accepted objects of the project's current results."""
    p = get_project(s, pid)
    if p.current_job_id is None:
        raise HTTPException(409, f"project {pid} has no finished detection job to export")
    try:
        from sbsc_core.bim.export import export_ifc
    except ImportError:
        raise HTTPException(501, "IFC export is not available in this installation "
                                 "(sbsc_core.bim.export is missing)") from None
    doc = project_document(s, p, id_is_ref=True)
    doc["project_name"] = p.name
    so = current_signoff(s, pid) if p.status != "open" else None
    library = _library(settings, s, s.get(Job, p.current_job_id).models_id)
    name, seed = asis_file(p)
    try:
        model = export_ifc(doc, library=library, schema="IFC4", accepted_only=True,
                           signoff=signoff_dict(so), project_name=p.name, author=user.name,
                           organisation=settings.organisation, file_name=name, guid_seed=seed)
    except SbscError as exc:
        raise HTTPException(422, str(exc)) from None
    settings.tmp_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="export-", suffix=".ifc", dir=settings.tmp_dir)
    os.close(fd)
    try:
        model.write(tmp)
        with open(tmp, "rb") as fh:
            data = fh.read()
    finally:
        os.unlink(tmp)
    return Response(data, media_type="application/x-step",
                    headers={"Content-Disposition": f'attachment; filename="{name}"'})


@router.get("/projects/{pid}/export.json")
def export_json(pid: int, _: Reviewer, s: ReadSession) -> JSONResponse:
    """The detections document (contract 4, ids as the pipeline wrote them) as a download."""
    p = get_project(s, pid)
    doc = project_document(s, p, id_is_ref=True)
    so = current_signoff(s, pid) if p.status != "open" else None
    doc["signoff"] = signoff_dict(so)
    return JSONResponse(doc, headers={"Content-Disposition": f'attachment; filename="detections-{pid}.json"'})
