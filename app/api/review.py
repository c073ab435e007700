"""Review: detections with thumbnails, decisions with optimistic concurrency, sign-off.

Every change of a detection names the ``version`` it was made against. The change and
its audit row (who, when, from what to what) are written in one transaction that holds
the detection and its project locked, so a stale version answers 409 with the current
state, and a signed-off project answers 423: two reviewers never overwrite each other
silently, and nothing is changed after sign-off.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field
from sqlalchemy import func, select

from ..models import DetectionRow, Job, ReviewDecision, SignOff, WallRow, iso, utcnow
from ..results import detection_dict, project_document, review_counts
from ..thumbnails import thumbnail
from .deps import (
    DB,
    Images,
    Manager,
    ReadSession,
    Reviewer,
    Settings,
    get_project,
    library_classes,
    open_project,
)
from .projects import signoff_dict

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


def _get_detection(s, did: int, *, for_update: bool = False) -> DetectionRow:  # noqa: ANN001
    d = s.get(DetectionRow, did, with_for_update=True if for_update else None)
    if d is None:
        raise HTTPException(404, f"detection {did} not found")
    return d


@router.get("/projects/{pid}/detections")
def list_detections(pid: int, _: Reviewer, s: ReadSession,
                    status: Literal["pending", "accepted", "rejected"] | None = None,
                    class_: str | None = Query(default=None, alias="class")) -> dict:
    """The project's current results as a contract-4 document, each detection with ``review``.

    ``?status=`` and ``?class=`` filter the detections (walls and openings stay whole).
    """
    doc = project_document(s, get_project(s, pid))
    if status or class_:
        doc["detections"] = [d for d in doc["detections"]
                             if (not status or d["review"]["status"] == status)
                             and (not class_ or d["class"] == class_)]
    return doc


@router.get("/detections/{did}")
def get_detection(did: int, _: Reviewer, s: ReadSession) -> dict:
    return detection_dict(_get_detection(s, did))


def _state(d: DetectionRow) -> dict:
    return {"status": d.status, "class": d.class_id, "u": d.u, "v": d.v}


@router.patch("/detections/{did}", responses={409: {"description": "stale version"},
                                               423: {"description": "project signed off"}})
def review_detection(did: int, body: Change, request: Request, user: Reviewer, db: DB):
    """Accept, reject, relabel (``class``) or move (``u``, ``v``) one detection."""
    if body.status is None and body.class_ is None and body.u is None and body.v is None:
        raise HTTPException(422, "nothing to change: give status, class, u or v")
    with db.write() as s:
        d = _get_detection(s, did, for_update=True)
        project = open_project(s, d.project_id)
        if d.job_id != project.current_job_id:
            raise HTTPException(409, f"detection {did} belongs to results replaced by job "
                                     f"{project.current_job_id}")
        if d.version != body.version:
            return JSONResponse(status_code=409, content={
                "detail": f"stale version {body.version}: detection {did} is at version {d.version} "
                          f"(last changed by {d.reviewed_by or 'nobody'}); reload and decide again",
                "current": detection_dict(d)})
        before = _state(d)
        actions = []
        if body.status is not None and body.status != d.status:
            actions.append({"accepted": "accept", "rejected": "reject", "pending": "reset"}[body.status])
            d.status = body.status
        if body.class_ is not None and body.class_ != d.class_id:
            classes = library_classes(request, s, s.get(Job, d.job_id).models_id)
            if body.class_ not in classes:
                raise HTTPException(422, f"class: '{body.class_}' is not in the project's model library")
            d.class_id = body.class_
            d.width_m = float(classes[body.class_]["width_m"])
            d.height_m = float(classes[body.class_]["height_m"])
            actions.append("relabel")
        if body.u is not None or body.v is not None:
            wall = s.scalars(select(WallRow).where(WallRow.job_id == d.job_id,
                                                   WallRow.key == d.wall_key)).one()
            u = d.u if body.u is None else float(body.u)
            v = d.v if body.v is None else float(body.v)
            if not (0.0 <= u <= wall.width_m and 0.0 <= v <= wall.height_m):
                raise HTTPException(422, f"u, v: ({u:.3f}, {v:.3f}) is outside wall {wall.key} "
                                         f"({wall.width_m:.2f} x {wall.height_m:.2f} m)")
            if (u, v) != (d.u, d.v):
                d.u, d.v = u, v
                d.position = [round(o + u * a + v * b, 5)
                              for o, a, b in zip(wall.origin, wall.axis_u, wall.axis_v, strict=True)]
                actions.append("move")
        if not actions:
            return detection_dict(d)  # no change, no new version, no audit row
        now = utcnow()
        d.version += 1
        d.reviewed_by, d.reviewed_at = user.name, now
        s.add(ReviewDecision(detection_id=d.id, project_id=d.project_id, user_id=user.id,
                             user_name=user.name, at=now, action="+".join(actions),
                             version_from=body.version, version_to=d.version, before=before,
                             after=_state(d), comment=body.comment))
        s.flush()
        return detection_dict(d)


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


@router.get("/projects/{pid}/signoff")
def get_signoff(pid: int, _: Reviewer, s: ReadSession) -> dict:
    p = get_project(s, pid)
    so = s.scalars(select(SignOff).where(SignOff.project_id == pid)).first()
    return {"project": pid, "status": p.status, "counts": review_counts(s, p), "signoff": signoff_dict(so)}


@router.post("/projects/{pid}/signoff")
def sign_off(pid: int, body: SignOffBody, user: Manager, db: DB) -> dict:
    """Sign the reviewed results off (manager): the project is locked from then on."""
    with db.write() as s:
        p = open_project(s, pid)
        if p.current_job_id is None:
            raise HTTPException(409, f"project {pid} has no finished detection job to sign off")
        busy = s.scalar(select(func.count(Job.id)).where(Job.project_id == pid,
                                                         Job.status.in_(("queued", "running"))))
        if busy:
            raise HTTPException(409, f"project {pid} has {busy} job(s) queued or running")
        counts = review_counts(s, p)
        if counts["pending"]:
            raise HTTPException(409, f"{counts['pending']} detection(s) are still pending review")
        so = SignOff(project_id=pid, job_id=p.current_job_id, user_id=user.id, user_name=user.name,
                     at=utcnow(), comment=body.comment, counts=counts)
        s.add(so)
        p.status = "signed_off"
        s.flush()
        return {"project": pid, "status": p.status, "counts": counts, "signoff": signoff_dict(so)}
