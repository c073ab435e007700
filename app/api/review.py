"""Review: detections with thumbnails, decisions, bulk decisions, added objects, suggestions,
sign-off and reopening.

The routes are thin: every operation is a function of :mod:`app.review_service` run in one
write transaction, the same functions the 3D scene calls. Every change of a detection names
the ``version`` it was made against, so a stale version answers 409 with the current state,
and a signed-off project answers 423: two reviewers never overwrite each other silently,
and nothing is changed after sign-off.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy import select

from .. import bulk
from .. import review_service as svc
from ..libraries import models_dir
from ..models import DetectionRow, Job, ReviewDecision, WallRow, iso
from ..results import detection_dict, project_document, review_counts
from ..review_rules import review_score, sort_score
from ..thumbnails import thumbnail
from .deps import (
    DB,
    Admin,
    Images,
    Manager,
    ReadSession,
    Reviewer,
    Settings,
    get_project,
)

router = APIRouter(prefix="/api", tags=["review"])


class Change(BaseModel):
    """A review decision: any of status, class (relabel), u / v (move), against ``version``."""

    version: int = Field(ge=1)
    status: Literal["accepted", "rejected", "pending"] | None = None
    class_: str | None = Field(default=None, alias="class", pattern=r"^[a-z0-9_]+$")
    u: float | None = None
    v: float | None = None
    comment: str | None = Field(default=None, max_length=2000)


class SignOffBody(BaseModel):
    comment: str = Field(max_length=5000)


class ReopenBody(BaseModel):
    reason: str = Field(min_length=1, max_length=5000)


class NewObject(BaseModel):
    """An object recognition missed: its class and where on which wall (metres)."""

    model_config = ConfigDict(populate_by_name=True)
    class_: str = Field(alias="class", pattern=r"^[a-z0-9_]+$", max_length=100)
    wall: str = Field(min_length=1, max_length=50)
    u: float = Field(allow_inf_nan=False)
    v: float = Field(allow_inf_nan=False)
    note: str | None = Field(default=None, max_length=2000)
    snap: bool = True  # move to where the class's depth model matches nearby
    status: Literal["accepted", "pending"] = "accepted"  # pending: until a reviewer confirms it (the pages)


class BulkFilter(BaseModel):
    model_config = ConfigDict(populate_by_name=True)
    class_: str | None = Field(default=None, alias="class", pattern=r"^[a-z0-9_]+$", max_length=100)
    min_confidence: float | None = Field(default=None, ge=0.0, le=1.0, allow_inf_nan=False)
    review: Literal["pending", "accepted", "rejected"] = "pending"


class BulkDecision(BaseModel):
    """One decision for many detections: ``ids`` or ``filter``.

    ``dry_run`` only counts; ``expect`` is the count the reviewer confirmed (409 when the
    selection has changed since).
    """

    status: Literal["accepted", "rejected", "pending"]
    ids: list[str | int] | None = Field(default=None, max_length=svc.BULK_MAX)
    filter: BulkFilter | None = None
    dry_run: bool = False
    expect: int | None = Field(default=None, ge=0)
    comment: str | None = Field(default=None, max_length=2000)


ERRORS: dict[int | str, dict[str, Any]] = {
    403: {"description": "role too low"}, 404: {"description": "not found"},
    409: {"description": "stale version or conflicting state"},
    422: {"description": "invalid input"}, 423: {"description": "project signed off"}}


def run(db: Any, op: Callable[[Any], Any]) -> Any:
    """Run a service operation in one write transaction; its errors (:mod:`app.errors`) become
    JSON 4xx answers in the app's one handler of them (``app.server``)."""
    with db.write() as s:
        return op(s)


def _get_detection(s, did: int, *, for_update: bool = False) -> DetectionRow:  # noqa: ANN001
    d = s.get(DetectionRow, did, with_for_update=True if for_update else None)
    if d is None:
        raise HTTPException(404, f"detection {did} not found")
    return d


def _score(d: dict) -> float | None:
    return review_score(d.get("confidence"), d.get("alpha"))


@router.get("/projects/{pid}/detections")
def list_detections(pid: int, _: Reviewer, s: ReadSession,
                    status: Literal["pending", "accepted", "rejected"] | None = None,
                    class_: str | None = Query(default=None, alias="class"),
                    min_confidence: float | None = Query(default=None, ge=0.0, le=1.0),
                    order: Literal["id", "uncertain", "surest"] = "id") -> dict:
    """The project's current results as a contract-4 document, each detection with ``review``.

    ``?status=``, ``?class=`` and ``?min_confidence=`` (on confidence, else alpha) filter the
    detections (walls and openings stay whole); ``?order=uncertain`` lists the least sure first
    (``surest``: the surest first).
    """
    doc = project_document(s, get_project(s, pid))
    if status or class_ or min_confidence is not None:
        doc["detections"] = [d for d in doc["detections"]
                             if (not status or d["review"]["status"] == status)
                             and (not class_ or d["class"] == class_)
                             and (min_confidence is None or (_score(d) or 0.0) >= min_confidence)]
    if order != "id":
        sign = 1.0 if order == "uncertain" else -1.0
        doc["detections"].sort(key=lambda d: sign * sort_score(d))
    return doc


@router.get("/detections/{did}")
def get_detection(did: int, _: Reviewer, s: ReadSession) -> dict:
    return detection_dict(_get_detection(s, did))


@router.patch("/detections/{did}", responses=ERRORS)
def review_detection(did: int, body: Change, user: Reviewer, db: DB):
    """Accept, reject, relabel (``class``) or move (``u``, ``v``) one detection."""
    change = svc.Change(version=body.version, status=body.status, class_=body.class_, u=body.u,
                        v=body.v, comment=body.comment)
    return run(db, lambda s: svc.decide(s, did, change, user))


@router.post("/projects/{pid}/detections", status_code=201, responses=ERRORS)
def add_detection(pid: int, body: NewObject, user: Reviewer, db: DB, settings: Settings):
    """Add an object recognition missed: ``source: reviewer``, accepted by the caller (or, with
    ``"status": "pending"``, as the pages add it: pending until confirmed), audited.

    The object snaps to where its class's depth model matches the wall's relief within a
    few centimetres of (u, v) (``"snap": false`` keeps the click).
    """
    return run(db, lambda s: svc.add_object(s, pid, body.class_, body.wall, body.u, body.v, user,
                                            settings.data_dir, note=body.note, snap=body.snap,
                                            status=body.status))


@router.post("/projects/{pid}/decisions", responses=ERRORS)
def bulk_decisions(pid: int, body: BulkDecision, user: Reviewer, db: DB):
    """One decision for many detections, each audited like a single one (same ``batch``).

    Answers ``{"changed", "matched", "skipped": [{"id", "reason"}], "ids", "batch"}``.
    """
    flt = None
    if body.filter is not None:
        flt = svc.Filter(class_=body.filter.class_, min_confidence=body.filter.min_confidence,
                         review=body.filter.review)
    if (body.ids is None) == (flt is None):
        raise HTTPException(422, "give either ids or filter")
    # in bounded batches, each its own short transaction (app.bulk)
    out = bulk.bulk_decide(db, pid, body.status, user, ids=body.ids, flt=flt, dry_run=body.dry_run,
                           expect=body.expect, comment=body.comment)
    # rendered here, in the worker thread: FastAPI's encoder would spend ~0.4 s of the event
    # loop on 100,000 ids, holding up every other request
    return JSONResponse(out)


@router.get("/projects/{pid}/suggestions")
def list_suggestions(pid: int, _: Reviewer, s: ReadSession, promoted: bool = False) -> list[dict]:
    """Possible misses: candidates recognition found but did not keep, per wall, strongest first."""
    return svc.suggestions(s, get_project(s, pid), include_promoted=promoted)


@router.post("/suggestions/{sid}/promote", status_code=201, responses=ERRORS)
def promote_suggestion(sid: int, user: Reviewer, db: DB, settings: Settings):
    """Make a suggestion an accepted object (``source: reviewer``), audited."""
    return run(db, lambda s: svc.promote(s, sid, user, settings.data_dir))


@router.get("/projects/{pid}/summary")
def review_summary(pid: int, _: Reviewer, s: ReadSession) -> dict:
    """Decisions per minute, how many in bulk, objects added: in all and per reviewer."""
    return svc.review_summary(s, pid)


@router.get("/projects/{pid}/events")
def project_events(pid: int, _: Reviewer, s: ReadSession) -> list[dict]:
    """Sign-offs, reopenings, cancelled jobs and carried-over decisions, oldest first."""
    get_project(s, pid)
    return svc.events(s, pid)


@router.get("/detections/{did}/history")
def detection_history(did: int, _: Reviewer, s: ReadSession) -> list[dict]:
    _get_detection(s, did)
    rows = s.scalars(select(ReviewDecision).where(ReviewDecision.detection_id == did)
                     .order_by(ReviewDecision.id))
    return [_decision_dict(r) for r in rows]


def _decision_dict(r: ReviewDecision) -> dict:
    return {"id": r.id, "detection": str(r.detection_id), "by": r.user_name, "at": iso(r.at),
            "action": r.action, "version_from": r.version_from, "version_to": r.version_to,
            "before": r.before, "after": r.after, "comment": r.comment}


@router.get("/projects/{pid}/decisions")
def project_decisions(pid: int, _: Reviewer, s: ReadSession, after: int = 0,
                      limit: int = Query(default=1000, ge=1, le=10000)) -> list[dict]:
    """The audit trail of the project, oldest first (page with ``after`` = last id seen)."""
    get_project(s, pid)
    rows = s.scalars(select(ReviewDecision).where(ReviewDecision.project_id == pid,
                                                  ReviewDecision.id > after)
                     .order_by(ReviewDecision.id).limit(limit))
    return [_decision_dict(r) for r in rows]


@router.get("/detections/{did}/thumbnail/{kind}", response_class=Response,
            responses={200: {"content": {"image/png": {}}}})
def detection_thumbnail(did: int, kind: Literal["colour", "depth"], _: Reviewer, s: ReadSession,
                        settings: Settings, images: Images) -> Response:
    """A PNG crop of the wall's colour or depth orthoimage around the detection."""
    d = _get_detection(s, did)
    wall = s.scalars(select(WallRow).where(WallRow.job_id == d.job_id, WallRow.key == d.wall_key)).first()
    meta = (wall.images or {}).get("depth" if kind == "depth" else "colour") if wall else None
    if meta is None:
        raise HTTPException(404, f"no {kind} orthoimage for wall {d.wall_key}")
    path = settings.data_dir / Path(meta["path"])
    depth_meta = (wall.images or {}).get("depth")
    try:
        png = thumbnail(images, path, kind, wall_height_m=wall.height_m, pixel_m=wall.pixel_m,
                        u=d.u, v=d.v, width_m=d.width_m, height_m=d.height_m,
                        size_px=settings.thumbnail_px, context=settings.thumbnail_context,
                        min_side_m=settings.thumbnail_min_m,
                        depth_path=settings.data_dir / depth_meta["path"] if depth_meta else None)
    except FileNotFoundError:
        raise HTTPException(404, f"{kind} orthoimage of wall {d.wall_key} is missing on disk") from None
    return Response(png, media_type="image/png",
                    headers={"Cache-Control": "private, max-age=86400"})


@router.get("/projects/{pid}/walls/{wall}/image/{kind}", response_class=Response,
            responses={200: {"content": {"image/png": {}}}})
def wall_image(pid: int, wall: str, kind: Literal["colour", "depth"], _: Reviewer, s: ReadSession,
               settings: Settings) -> Response:
    """A wall's whole colour (or depth) orthoimage as PNG: where a reviewer clicks to add an object."""
    p = get_project(s, pid)
    row = s.scalars(select(WallRow).where(WallRow.job_id == p.current_job_id, WallRow.key == wall)).first() \
        if p.current_job_id is not None else None
    meta = (row.images or {}).get("colour" if kind == "colour" else "depth_png") if row else None
    if meta is None:
        raise HTTPException(404, f"no {kind} orthoimage for wall {wall} in project {pid}")
    try:
        data = (settings.data_dir / Path(meta["path"])).read_bytes()
    except OSError:
        raise HTTPException(404, f"{kind} orthoimage of wall {wall} is missing on disk") from None
    return Response(data, media_type="image/png", headers={"Cache-Control": "private, max-age=86400"})


@router.post("/projects/{pid}/exemplars", status_code=201, responses=ERRORS)
def learn_exemplars(pid: int, user: Manager, db: DB, settings: Settings) -> dict:
    """Learn from decisions (manager): the accepted objects' crops become a model library.

    The library (contract 2: the project's classes with the crops as extra front views) is
    stored and made the project's library, so the next job uses it; download it with
    ``GET /api/projects/{pid}/exemplars.zip`` to run another floor of the building with it.
    """
    import uuid

    from sbsc_core.io.models import load_model_library

    from ..exemplars import build_exemplar_library
    from ..models import ModelLibraryRow
    from ..storage import library_summary

    with db.write() as s:
        p = svc.open_project(s, pid)
        if p.current_job_id is None:
            raise HTTPException(409, f"project {pid} has no reviewed results yet")
        job = s.get(Job, p.current_job_id)
        source = models_dir(s, job.models_id, settings.data_dir)
        rel = Path("projects", str(pid), "models", f"exemplars_{uuid.uuid4().hex[:12]}")
        dest = settings.data_dir / rel
        added = build_exemplar_library(s, p, settings.data_dir, source, dest)
        if not added:
            shutil.rmtree(dest, ignore_errors=True)
            raise HTTPException(409, f"project {pid} has no accepted object to learn from")
        row = ModelLibraryRow(project_id=pid, filename=f"exemplars of project {pid}", path=rel.as_posix(),
                              size_bytes=0, sha256="", classes=library_summary(load_model_library(dest)),
                              uploaded_by=user.name)
        s.add(row)
        s.flush()
        p.models_id = row.id
        return {"library": row.id, "views_added": added, "classes": sorted(row.classes)}


@router.get("/projects/{pid}/exemplars.zip", response_class=Response,
            responses={200: {"content": {"application/zip": {}}}})
def exemplars_zip(pid: int, _: Reviewer, s: ReadSession, settings: Settings) -> Response:
    """The project's current model library (its exemplars once learnt) as a zip (contract 2)."""
    import io
    import zipfile

    p = get_project(s, pid)
    root = models_dir(s, p.models_id, settings.data_dir)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for f in sorted(root.rglob("*")):
            if f.is_file():
                zf.write(f, Path("models") / f.relative_to(root))
    return Response(buf.getvalue(), media_type="application/zip",
                    headers={"Content-Disposition": f'attachment; filename="models-{pid}.zip"'})


@router.get("/projects/{pid}/signoff")
def get_signoff(pid: int, _: Reviewer, s: ReadSession) -> dict:
    p = get_project(s, pid)
    so = svc.current_signoff(s, pid) if p.status != "open" else None
    return {"project": pid, "status": p.status, "counts": review_counts(s, p),
            "signoff": svc.signoff_dict(so)}


@router.post("/projects/{pid}/signoff", responses=ERRORS)
def sign_off(pid: int, body: SignOffBody, user: Manager, db: DB):
    """Sign the reviewed results off (manager): the project is locked from then on."""
    return run(db, lambda s: svc.sign_off(s, pid, body.comment, user))


@router.post("/projects/{pid}/reopen", responses=ERRORS)
def reopen(pid: int, body: ReopenBody, user: Admin, db: DB):
    """Open a signed-off project again (admin), with a reason; audited in the project's events."""
    return run(db, lambda s: svc.reopen(s, pid, body.reason, user))
