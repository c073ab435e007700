"""Teach and search again (issue 28): create a class, learn from the examples, run again.

Examples are marked with ``POST /api/projects/{pid}/detections`` (an object added on a wall),
which takes a class created here as well as a library class. ``POST .../learn`` learns a
library from the accepted objects a person added or relabelled (:mod:`app.teach`), makes it
the project's library and queues a detection job with it; the job keeps every decision
(``app.review_service.carry_over``) and its new hits come as pending detections. The learnt
library downloads as ``GET .../exemplars.zip``.
"""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, HTTPException, Request
from pydantic import BaseModel, Field
from sqlalchemy import func, select

from sbsc_core.errors import InputError

from ..models import Job, ModelLibraryRow
from ..results import job_dict
from ..review_service import library_classes, models_dir, open_project
from .deps import DB, Jobs, Reviewer, Settings
from .jobs import check_new_job

router = APIRouter(prefix="/api", tags=["review"])

ERRORS = {403: {"description": "role too low"}, 404: {"description": "not found"},
          409: {"description": "exists already, nothing to learn from, or a job is queued or running"},
          422: {"description": "invalid input, or an example that cannot be used"},
          423: {"description": "project signed off"}}


class NewClass(BaseModel):
    """A class the project's library does not have, to be taught from examples."""

    id: str = Field(pattern=r"^[a-z0-9_]+$", min_length=1, max_length=100)
    name: str = Field(min_length=1, max_length=200, pattern=r"\S")
    ifc_class: str = Field(default="IfcBuildingElementProxy", pattern=r"^Ifc[A-Za-z]+$", max_length=100)
    predefined_type: str | None = Field(default=None, pattern=r"^[A-Z0-9_]+$", max_length=100)
    mount: list[Literal["wall", "ceiling", "column"]] | None = Field(default=None, min_length=1, max_length=3)


@router.post("/projects/{pid}/classes", status_code=201, responses=ERRORS)
def create_class(pid: int, body: NewClass, request: Request, _: Reviewer, db: DB, settings: Settings) -> dict:
    """Create a class for the project (409 when its library or the project has it already)."""
    from ..teach import project_classes, save_project_classes, taught_class_fields

    if body.mount is not None and len(set(body.mount)) != len(body.mount):
        raise HTTPException(422, "mount: each kind of surface once")
    with db.write() as s:
        p = open_project(s, pid)
        if body.id in library_classes(s, p.models_id):
            raise HTTPException(409, f"class '{body.id}' is in the project's model library already")
        classes = project_classes(settings.data_dir, pid)
        if body.id in classes:
            raise HTTPException(409, f"class '{body.id}' was created for project {pid} already")
        spec = {"name": body.name.strip(), "ifc_class": body.ifc_class}
        if body.predefined_type:
            spec["predefined_type"] = body.predefined_type
        if body.mount:
            spec["mount"] = list(body.mount)
        classes[body.id] = spec
        save_project_classes(settings.data_dir, pid, classes)
    return {"id": body.id, **taught_class_fields(spec)}


@router.post("/projects/{pid}/learn", status_code=202, responses=ERRORS)
def learn_and_search_again(pid: int, user: Reviewer, db: DB, jobs: Jobs, settings: Settings) -> dict:
    """Learn and search again: learn a library from the examples, make it the project's, and
    queue a detection job with it. Answers ``{"library", "classes", "job"}``."""
    import shutil

    from ..teach import learn

    with db.write() as s:
        p = open_project(s, pid)
        if p.current_job_id is None:
            raise HTTPException(409, f"project {pid} has no results to learn from yet")
        check_new_job(s, p, user, reviewed_ok=True)
        if s.scalar(select(func.count(Job.id)).where(Job.project_id == pid, Job.status == "running")):
            raise HTTPException(409, f"project {pid} has a job running; learn from its results once it has finished")
        current = s.get(Job, p.current_job_id)
        source = models_dir(s, current.models_id, settings.data_dir)
        try:
            rel, taught = learn(s, p, settings.data_dir, source)
        except LookupError as exc:
            raise HTTPException(409, str(exc)) from None
        except InputError as exc:
            raise HTTPException(422, str(exc)) from None
        dest = settings.data_dir / rel
        try:
            out = _store(s, p, user, dest, rel, current, taught)
        except BaseException:  # nothing half-written: the library goes with the transaction
            shutil.rmtree(dest, ignore_errors=True)
            raise
    jobs.wake()
    return out


def _store(s, p, user, dest, rel, current: Job, taught: list) -> dict:  # noqa: ANN001
    """The learnt library as the project's library, and a job queued with it."""
    from sbsc_core.io.models import load_model_library

    from ..storage import library_summary

    row = ModelLibraryRow(project_id=p.id, filename=f"learnt library of project {p.id}", path=rel.as_posix(),
                          size_bytes=sum(f.stat().st_size for f in dest.rglob("*") if f.is_file()),
                          sha256="", classes=library_summary(load_model_library(dest)), uploaded_by=user.name)
    s.add(row)
    s.flush()
    p.models_id = row.id
    job = Job(project_id=p.id, status="queued", stage="queued", progress=0.0, models_id=row.id,
              expected=current.expected, expected_storeys=current.expected_storeys, created_by=user.name)
    s.add(job)
    s.flush()
    return {"library": row.id, "classes": [t.to_dict() for t in taught], "job": job_dict(job)}
