"""Teach and search again (issue 28): create a class, learn from the examples, run again.

Examples are marked with ``POST /api/projects/{pid}/detections`` (an object added on a wall),
which takes a class created here as well as a library class. ``POST .../learn`` learns a
library from the accepted objects a person added or relabelled (:mod:`app.teach`), makes it
the project's library and queues a detection job with it; the job keeps every decision
(``app.review_service.carry_over``) and its new hits come as pending detections. The learnt
library downloads as ``GET .../exemplars.zip``.

It must not make things worse: ``GET .../learnt`` lists what the project's library learnt
(a class, or designs of a known class) with its hits' review counts; ``DELETE
.../learnt/{class}`` removes it (the project's library without it, its untouched pending
suggestions gone, its examples skipped by the next learning); ``POST .../learn`` with
``{"reteach": [class, ...]}`` teaches those classes afresh from their current examples.
"""

from __future__ import annotations

import re
import shutil
from typing import Literal

from fastapi import APIRouter, HTTPException, Request
from pydantic import BaseModel, Field
from sqlalchemy import func, select

from sbsc_core.errors import InputError

from ..libraries import library_classes, models_dir
from ..models import Job, ModelLibraryRow
from ..results import job_dict
from ..review_service import open_project
from .deps import DB, Jobs, Reviewer, Settings
from .jobs import check_new_job

router = APIRouter(prefix="/api", tags=["review"])
CLASS_ID = re.compile(r"^[a-z0-9_]{1,100}$")

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


class Learn(BaseModel):
    """Options of learn and search again."""

    reteach: list[str] = Field(default_factory=list, max_length=100,
                               description="classes to teach afresh: what was learnt for them is dropped first")


def _no_job_in_the_way(s, p, user, what: str) -> None:  # noqa: ANN001
    """409 while the project has a job queued or running (see ``check_new_job``)."""
    check_new_job(s, p, user, reviewed_ok=True)
    if s.scalar(select(func.count(Job.id)).where(Job.project_id == p.id, Job.status == "running")):
        raise HTTPException(409, f"project {p.id} has a job running; {what} once it has finished")


@router.post("/projects/{pid}/learn", status_code=202, responses=ERRORS)
def learn_and_search_again(pid: int, user: Reviewer, db: DB, jobs: Jobs, settings: Settings,
                           body: Learn | None = None) -> dict:
    """Learn and search again: learn a library from the examples, make it the project's, and
    queue a detection job with it. Answers ``{"library", "classes", "job"}``.

    ``{"reteach": [class, ...]}``: those classes (learnt before, or removed) are taught afresh
    from their current examples."""
    from sbsc_core.recognition.learning.forget import learnt_part

    from ..teach import learn, save_unlearnt, unlearnt

    reteach = frozenset(body.reteach if body else ())
    dest, removed = None, None
    try:
        with db.write() as s:
            p = open_project(s, pid)
            if p.current_job_id is None:
                raise HTTPException(409, f"project {pid} has no results to learn from yet")
            _no_job_in_the_way(s, p, user, "learn from its results")
            current = s.get(Job, p.current_job_id)
            source = models_dir(s, p.models_id, settings.data_dir)  # the project's library, less what was removed
            removed = unlearnt(settings.data_dir, pid)
            for cid in sorted(reteach):
                if cid not in removed and not ((source / cid).is_dir() and learnt_part(source / cid)):
                    raise HTTPException(422, f"reteach: class '{cid}' has nothing learnt or removed to re-teach")
            try:
                rel, taught = learn(s, p, settings.data_dir, source, reteach)
            except LookupError as exc:
                raise HTTPException(409, str(exc)) from None
            except InputError as exc:
                raise HTTPException(422, str(exc)) from None
            dest = settings.data_dir / rel
            out = _store(s, p, user, dest, rel, taught, current)
            if reteach & removed:
                save_unlearnt(settings.data_dir, pid, removed - reteach)
    except BaseException:  # nothing half-written: the library and the list go with the transaction
        if dest is not None:
            shutil.rmtree(dest, ignore_errors=True)
            if reteach & removed:
                save_unlearnt(settings.data_dir, pid, removed)
        raise
    jobs.wake()
    return out


@router.get("/projects/{pid}/learnt", responses=ERRORS)
def learnt(pid: int, _: Reviewer, db: DB, settings: Settings) -> dict:
    """What the project's library learnt from examples: ``{"classes": [{"class", "part":
    "class"|"designs", "hits": {"pending", "accepted", "rejected"}}], "removed": [class, ...]}``;
    ``hits`` counts the current results' found objects of that class by review status."""
    from sbsc_core.recognition.learning.forget import learnt_parts

    from ..models import DetectionRow
    from ..teach import unlearnt
    from .deps import get_project

    with db.read() as s:
        p = get_project(s, pid)
        parts = learnt_parts(models_dir(s, p.models_id, settings.data_dir))
        counts: dict[str, dict[str, int]] = {c: {"pending": 0, "accepted": 0, "rejected": 0} for c in parts}
        if p.current_job_id is not None and parts:
            rows = s.execute(select(DetectionRow.detected_class, DetectionRow.status, func.count(DetectionRow.id))
                             .where(DetectionRow.job_id == p.current_job_id, DetectionRow.source != "reviewer",
                                    DetectionRow.detected_class.in_(list(parts)))
                             .group_by(DetectionRow.detected_class, DetectionRow.status))
            for cls, status, n in rows:
                counts[cls][status] = n
    return {"classes": [{"class": c, "part": part, "hits": counts[c]} for c, part in parts.items()],
            "removed": sorted(unlearnt(settings.data_dir, pid) - set(parts))}


@router.delete("/projects/{pid}/learnt/{class_id}", responses=ERRORS)
def remove_learnt(pid: int, class_id: str, user: Reviewer, db: DB, settings: Settings) -> dict:
    """Remove what was learnt for a class (a learnt class, or a known class's learnt designs):
    the project's library without it, its untouched pending suggestions gone, and its examples
    skipped by the next learning until it is re-taught. Answers ``{"class", "part", "library",
    "suggestions_removed"}``."""
    from sbsc_core.recognition.learning.forget import learnt_part

    from ..teach import brought_by, forget, save_unlearnt, unlearnt

    if not CLASS_ID.match(class_id):
        raise HTTPException(422, f"class: {class_id!r} is not a class id (lower case letters, digits and '_')")
    dest, removed = None, None
    try:
        with db.write() as s:
            p = open_project(s, pid)
            _no_job_in_the_way(s, p, user, "remove a learnt class")
            source = models_dir(s, p.models_id, settings.data_dir)
            if not (source / class_id / "model.json").is_file():
                raise HTTPException(404, f"class '{class_id}' is not in project {pid}'s model library")
            if learnt_part(source / class_id) is None:
                raise HTTPException(409, f"class '{class_id}': nothing in project {pid}'s model library was "
                                         "learnt from examples")
            try:
                rel, part = forget(p, settings.data_dir, source, class_id)
            except InputError as exc:
                raise HTTPException(422, str(exc)) from None
            dest = settings.data_dir / rel
            row = _store(s, p, user, dest, rel, [])
            gone = brought_by(s, p, settings.data_dir, class_id, part)
            for d in gone:
                s.delete(d)
            s.flush()
            removed = unlearnt(settings.data_dir, pid)
            save_unlearnt(settings.data_dir, pid, removed | {class_id})
    except BaseException:  # nothing half-written: the library and the list go with the transaction
        if dest is not None:
            shutil.rmtree(dest, ignore_errors=True)
        if removed is not None:
            save_unlearnt(settings.data_dir, pid, removed)
        raise
    return {"class": class_id, "part": part, "library": row["library"], "suggestions_removed": len(gone)}


def _store(s, p, user, dest, rel, taught: list, current: Job | None = None) -> dict:  # noqa: ANN001
    """The learnt library as the project's library, and (with ``current``) a job queued with it."""
    from sbsc_core.io.models import load_model_library

    from ..storage import library_summary

    row = ModelLibraryRow(project_id=p.id, filename=f"learnt library of project {p.id}", path=rel.as_posix(),
                          size_bytes=sum(f.stat().st_size for f in dest.rglob("*") if f.is_file()),
                          sha256="", classes=library_summary(load_model_library(dest)), uploaded_by=user.name)
    s.add(row)
    s.flush()
    p.models_id = row.id
    if current is None:
        return {"library": row.id}
    job = Job(project_id=p.id, status="queued", stage="queued", progress=0.0, models_id=row.id,
              expected=current.expected, expected_storeys=current.expected_storeys, created_by=user.name)
    s.add(job)
    s.flush()
    return {"library": row.id, "classes": [t.to_dict() for t in taught], "job": job_dict(job)}
