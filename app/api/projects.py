"""Health, the caller, users (admin) and projects."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import PlainTextResponse
from pydantic import AfterValidator, BaseModel, Field
from sqlalchemy import func, select

from sbsc_core.io.detections_model import bad_text

from ..auth import create_user
from ..libraries import library_classes
from ..membership import add_creator, member_ids
from ..models import DesignRow, Job, ModelLibraryRow, Project, Scan, User, iso
from ..results import job_dict, review_counts
from ..review_service import current_signoff, signoff_dict
from .deps import DB, Admin, ReadSession, Reviewer, Settings, get_project

router = APIRouter(prefix="/api")


@router.get("/health", tags=["meta"])
async def health() -> dict:
    """Liveness; answered on the event loop, without a worker thread or the database."""
    return {"status": "ok"}


@router.get("/me", tags=["users"])
def me(user: Reviewer) -> dict:
    return {"id": user.id, "name": user.name, "role": user.role}


def _printable(value: str) -> str:
    """A name: no control, format (bidi) or separator characters but spaces."""
    why = bad_text(value)
    if why:
        raise ValueError(why)
    return value


Name = Annotated[str, AfterValidator(_printable)]


class NewUser(BaseModel):
    name: Name = Field(min_length=1, max_length=100, pattern=r"\S")
    role: str = Field(pattern="^(reviewer|manager|admin)$")


@router.get("/users", tags=["users"])
def list_users(_: Admin, s: ReadSession) -> list[dict]:
    return [{"id": u.id, "name": u.name, "role": u.role, "created_at": iso(u.created_at),
             "disabled": u.disabled} for u in s.scalars(select(User).order_by(User.id))]


@router.post("/users", status_code=201, tags=["users"])
def add_user(body: NewUser, _: Admin, db: DB) -> dict:
    """Create a user; the answer holds its token, shown this once."""
    with db.write() as s:
        try:
            user, token = create_user(s, body.name, body.role)
        except ValueError as exc:
            raise HTTPException(409 if "exists" in str(exc) else 422, str(exc)) from None
        return {"id": user.id, "name": user.name, "role": user.role, "token": token}


class NewProject(BaseModel):
    name: Name = Field(min_length=1, max_length=200, pattern=r"\S")


def project_summary(s, p: Project) -> dict:  # noqa: ANN001
    return {"id": p.id, "name": p.name, "status": p.status, "created_at": iso(p.created_at),
            "created_by": p.created_by, "current_job": p.current_job_id}


@router.get("/projects", tags=["projects"])
def list_projects(user: Reviewer, s: ReadSession) -> list[dict]:
    """The projects the caller is a member of (an admin: all)."""
    out = []
    n_scans = dict(s.execute(select(Scan.project_id, func.count(Scan.id)).group_by(Scan.project_id)).all())
    mine = member_ids(s, user)
    query = select(Project) if mine is None else select(Project).where(Project.id.in_(mine))
    for p in s.scalars(query.order_by(Project.id.desc())):
        last = s.scalars(select(Job).where(Job.project_id == p.id).order_by(Job.id.desc()).limit(1)).first()
        out.append({**project_summary(s, p), "scans": n_scans.get(p.id, 0),
                    "last_job": job_dict(last) if last else None, "counts": review_counts(s, p)})
    return out


@router.post("/projects", status_code=201, tags=["projects"])
def create_project(body: NewProject, user: Reviewer, db: DB) -> dict:
    name = " ".join(body.name.split())
    if not name:
        raise HTTPException(422, "name: must not be blank")
    with db.write() as s:
        p = Project(name=name, status="open", created_by=user.name)
        s.add(p)
        s.flush()
        add_creator(s, p, user)
        return project_summary(s, p)


@router.get("/projects/{pid}", tags=["projects"])
def get_project_detail(pid: int, _: Reviewer, s: ReadSession) -> dict:
    """The project with its scans, model library, jobs, review counts, sign-off and design."""
    p = get_project(s, pid)
    scans = [{"id": sc.id, "filename": sc.filename, "points": sc.points, "bytes": sc.size_bytes,
              "sha256": sc.sha256, "uploaded_by": sc.uploaded_by, "created_at": iso(sc.created_at)}
             for sc in s.scalars(select(Scan).where(Scan.project_id == pid).order_by(Scan.id))]
    models = s.get(ModelLibraryRow, p.models_id) if p.models_id else None
    jobs = [job_dict(j) for j in s.scalars(select(Job).where(Job.project_id == pid).order_by(Job.id.desc()))]
    so = current_signoff(s, pid) if p.status != "open" else None
    design = s.scalars(select(DesignRow).where(DesignRow.project_id == pid)
                       .order_by(DesignRow.id.desc()).limit(1)).first()
    return {
        **project_summary(s, p), "scans": scans,
        "models": None if models is None else {
            "id": models.id, "filename": models.filename, "sha256": models.sha256,
            "classes": sorted(models.classes)},
        "jobs": jobs, "counts": review_counts(s, p), "signoff": signoff_dict(so),
        "design": None if design is None else {
            "filename": design.filename, "objects": design.objects,
            "expected_counts": design.expected_counts, "sha256": design.sha256,
            "uploaded_by": design.uploaded_by, "created_at": iso(design.created_at)},
    }


@router.get("/projects/{pid}/classes", tags=["review"])
def project_classes(pid: int, request: Request, _: Reviewer, s: ReadSession) -> dict:
    """The classes a detection of this project may be relabelled to (its model library), and
    the classes created for it that are not learnt yet (``"taught": true``, no size)."""
    from ..teach import project_classes, taught_class_fields

    p = get_project(s, pid)
    models_id = p.models_id
    if p.current_job_id is not None:
        models_id = s.get(Job, p.current_job_id).models_id
    classes = library_classes(s, models_id)
    created = project_classes(request.app.state.settings.data_dir, pid)
    return {**{cid: taught_class_fields(spec) for cid, spec in created.items() if cid not in classes}, **classes}


@router.get("/admin/jobs/{jid}/log", tags=["users"], response_class=PlainTextResponse)
def job_admin_log(jid: int, _: Admin, s: ReadSession, settings: Settings) -> str:
    """The admin-only log of a job: full tracebacks and server paths (the reviewers' log,
    ``/api/jobs/{jid}/log``, and the job's ``error`` carry neither)."""
    from ..job_worker import ADMIN_LOG

    job = s.get(Job, jid)
    if job is None:
        raise HTTPException(404, f"job {jid} not found")
    if not job.out_dir:
        return ""
    path = (settings.data_dir / job.out_dir).parent / ADMIN_LOG
    return path.read_text(encoding="utf-8", errors="replace")[-500_000:] if path.is_file() else ""
