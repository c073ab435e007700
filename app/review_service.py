"""The review operations, one place for all of them: decide, bulk-decide, add, promote, sign off, reopen.

The REST routes (``app.api.review``) and the 3D scene (``app.viewer.db_backend``) both call
these functions inside one write transaction (``with db.write() as s``), so a decision is
checked, recorded and audited the same way whichever side it comes from:

- every change of a detection names the ``version`` it was made against (409 when stale) and
  writes one append-only ``review_decisions`` row (who, when, from what to what);
- a bulk decision is many single decisions sharing a ``batch`` id;
- nothing changes after sign-off (423) until an admin reopens the project, with a reason
  (``project_events``);
- a new job carries the decisions over to the objects it finds again (:func:`carry_over`).

Errors are :mod:`app.errors` classes (``ServiceError`` here) carrying the HTTP status the API answers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from .auth import Principal
from .errors import Conflict, Forbidden, Invalid, NotFound, ReviewError
from .libraries import check_mount, library_classes, models_dir
from .models import (
    DetectionRow,
    Job,
    Project,
    ProjectEvent,
    ReviewDecision,
    SignOff,
    SuggestionRow,
    WallRow,
    iso,
    utcnow,
)
from .results import detection_dict, review_counts, wall_dict
from .review_rules import CARRY_TOLERANCE_M, check_open, check_status, check_version, review_score
from .snap import Snap, depth_template, snap_to_relief
from .surfaces import point_on

ACTIONS = {"accepted": "accept", "rejected": "reject", "pending": "reset"}
BULK_MAX = 100_000
RELABELLED = "relabelled by a reviewer: decided one by one, never in bulk"


ServiceError = ReviewError  # the name the REST routes use


# --------------------------------------------------------------------------- look-ups


def score(d: DetectionRow) -> float | None:
    """:func:`review_score` of a stored detection."""
    return review_score(d.confidence, d.alpha)


def open_project(s: Session, pid: int, *, lock: bool = True) -> Project:
    """The project, locked for this transaction (unless ``lock`` is false); 423 once it is signed off.

    The one place of the rule "nothing changes after sign-off": every change of a project's
    review, scans, models, design or jobs goes through here.
    """
    p = s.get(Project, pid, with_for_update=True if lock else None)
    if p is None:
        raise NotFound(f"project {pid} not found")
    check_open(pid, p.status != "open")
    return p


def current_signoff(s: Session, pid: int) -> SignOff | None:
    """The newest sign-off of a project (a reopened project may have several)."""
    return s.scalars(select(SignOff).where(SignOff.project_id == pid)
                     .order_by(SignOff.id.desc()).limit(1)).first()


def _wall(s: Session, job_id: int, key: str) -> WallRow | None:
    return s.scalars(select(WallRow).where(WallRow.job_id == job_id, WallRow.key == key)).first()


def _state(d: DetectionRow) -> dict:
    return {"status": d.status, "class": d.class_id, "u": d.u, "v": d.v}


def _audit(s: Session, d: DetectionRow, user: Principal | None, action: str, version_from: int,
           before: dict, comment: str | None = None, batch: str | None = None,
           user_name: str | None = None) -> None:
    s.add(ReviewDecision(detection_id=d.id, project_id=d.project_id,
                         user_id=user.id if user else None,
                         user_name=user_name or (user.name if user else "system"),
                         at=d.reviewed_at or utcnow(), action=action, version_from=version_from,
                         version_to=d.version, before=before, after=_state(d), comment=comment,
                         batch=batch))


# --------------------------------------------------------------------------- single decisions


@dataclass
class Change:
    """A review decision: any of status, class (relabel), u / v (move), against ``version``."""

    version: int
    status: str | None = None
    class_: str | None = None
    u: float | None = None
    v: float | None = None
    comment: str | None = None


def _current_detection(s: Session, did: int, *, pid: int | None = None) -> tuple[DetectionRow, Project]:
    d = s.get(DetectionRow, did, with_for_update=True)
    if d is None or (pid is not None and d.project_id != pid):
        raise NotFound(f"detection {did} not found" + (f" in project {pid}" if pid is not None else ""))
    p = open_project(s, d.project_id)
    if d.job_id != p.current_job_id:
        raise Conflict(f"detection {did} belongs to results replaced by job {p.current_job_id}")
    return d, p


def decide(s: Session, did: int, change: Change, user: Principal, *, pid: int | None = None) -> dict:
    """Accept, reject, reset, relabel or move one detection; answers the detection as it stands."""
    if change.status is None and change.class_ is None and change.u is None and change.v is None:
        raise Invalid("nothing to change: give status, class, u or v")
    if change.status is not None:
        check_status(change.status)
    d, _ = _current_detection(s, did, pid=pid)
    if d.version != change.version:
        check_version(did, change.version, d.version, d.reviewed_by, detection_dict(d))
    before = _state(d)
    actions = []
    if change.status is not None and change.status != d.status:
        actions.append(ACTIONS[change.status])
        d.status = change.status
    if change.class_ is not None and change.class_ != d.class_id:
        classes = library_classes(s, s.get(Job, d.job_id).models_id)
        if change.class_ not in classes:
            raise Invalid(f"class: '{change.class_}' is not in the project's model library")
        if (on := _wall(s, d.job_id, d.wall_key)) is not None:
            check_mount(classes, change.class_, on)
        d.class_id = change.class_
        d.width_m = float(classes[change.class_]["width_m"])
        d.height_m = float(classes[change.class_]["height_m"])
        actions.append("relabel")
        if change.status is None and d.status == "pending":  # relabel = "it is a <class>": accepted as that
            d.status = "accepted"
            actions.append(ACTIONS["accepted"])
    if change.u is not None or change.v is not None:
        wall = _wall(s, d.job_id, d.wall_key)
        u = d.u if change.u is None else float(change.u)
        v = d.v if change.v is None else float(change.v)
        _check_on_wall(wall, u, v)
        if (u, v) != (d.u, d.v):
            d.u, d.v = u, v
            d.position = _position(wall, u, v)
            actions.append("move")
    if not actions:
        return detection_dict(d)  # no change, no new version, no audit row
    d.version += 1
    d.reviewed_by, d.reviewed_at = user.name, utcnow()
    _audit(s, d, user, "+".join(actions), change.version, before, change.comment)
    s.flush()
    return detection_dict(d)


def _check_on_wall(wall: WallRow | None, u: float, v: float) -> None:
    if wall is None:
        raise Invalid("wall: not a wall or surface of the project's current results")
    if not (np.isfinite(u) and np.isfinite(v)):
        raise Invalid("u, v: must be finite numbers")
    if not (0.0 <= u <= wall.width_m and 0.0 <= v <= wall.height_m):
        raise Invalid(f"u, v: ({u:.3f}, {v:.3f}) is outside {wall.kind or 'wall'} {wall.key} "
                      f"({wall.width_m:.2f} x {wall.height_m:.2f} m)")


def _position(wall: WallRow, u: float, v: float) -> list[float]:
    """The world point (u, v) of a wall or surface (on the cylinder of a round column)."""
    return point_on(wall_dict(wall), u, v)


# --------------------------------------------------------------------------- bulk decisions


@dataclass
class Filter:
    """Which detections a bulk decision covers (all given conditions hold)."""

    class_: str | None = None
    min_confidence: float | None = None  # on :func:`score`: confidence, else alpha
    review: str = "pending"


def select_detections(s: Session, p: Project, flt: Filter) -> list[DetectionRow]:
    """The current detections of ``p`` matching ``flt``, surest first."""
    if p.current_job_id is None:
        return []
    q = select(DetectionRow).where(DetectionRow.job_id == p.current_job_id,
                                   DetectionRow.status == flt.review)
    if flt.class_:
        q = q.where(DetectionRow.class_id == flt.class_)
    rows = list(s.scalars(q.order_by(DetectionRow.id)))
    if flt.min_confidence is not None:
        rows = [d for d in rows if score(d) is not None and score(d) >= flt.min_confidence]
    return sorted(rows, key=lambda d: -(score(d) or 0.0))


# --------------------------------------------------------------------------- adding objects


def add_object(s: Session, pid: int, class_id: str, wall_key: str, u: float, v: float,
               user: Principal, data_dir: Path, *, note: str | None = None, snap: bool = True,
               action: str = "add", extra: dict | None = None, status: str = "pending") -> dict:
    """An object recognition missed, placed by a reviewer (``source: reviewer``).

    It is ``pending`` until someone confirms it (accept; rejecting it undoes the addition),
    except when ``status`` says otherwise (a promoted suggestion is accepted at once). Its
    reference continues the series of the job's detections (``D0121`` after ``D0120``).
    With ``snap`` the click moves to where the class's depth model matches the wall's
    relief within a few centimetres (:mod:`app.snap`).
    """
    p = open_project(s, pid)
    if p.current_job_id is None:
        raise Conflict(f"project {pid} has no detection results to add to yet")
    job = s.get(Job, p.current_job_id)
    classes = library_classes(s, job.models_id)
    taught = None  # a class created for the project (app.teach): no model yet
    if class_id not in classes:
        from .teach import project_classes, taught_class_fields

        taught = project_classes(data_dir, pid).get(class_id)
        if taught is None:
            raise Invalid(f"class: '{class_id}' is not in the project's model library or classes")
        classes = {**classes, class_id: taught_class_fields(taught)}
    wall = _wall(s, job.id, wall_key)
    if wall is None:
        raise Invalid(f"wall: '{wall_key}' is not a wall or surface of the project's current results")
    check_mount(classes, class_id, wall)
    _check_on_wall(wall, float(u), float(v))
    where = Snap(float(u), float(v))
    if taught is not None:  # an example of a new class: the relief blob under the click, its size
        from .teach import measure

        blob = measure(wall, data_dir, float(u), float(v))
        if blob is None:
            raise Invalid(f"class: no relief under the click at u={float(u):.2f}, v={float(v):.2f} on {wall.key} "
                          f"to measure a new '{class_id}' from (click on the object itself)")
        where = Snap(float(blob[0]), float(blob[1]))
        w_m, h_m = float(blob[2]), float(blob[3])
    else:
        if snap:
            where = _snap(s, job, wall, class_id, where, data_dir)
        w_m, h_m = float(classes[class_id]["width_m"]), float(classes[class_id]["height_m"])
    now = utcnow()
    d = DetectionRow(project_id=pid, job_id=job.id, ref=_next_ref(s, job.id), class_id=class_id,
                     detected_class=class_id, wall_key=wall.key, position=_position(wall, where.u, where.v),
                     u=where.u, v=where.v, width_m=w_m, height_m=h_m, alpha=None,
                     rho_depth=where.rho, rho_colour=None, source="reviewer", status=status,
                     version=1, reviewed_by=user.name, reviewed_at=now, note=note,
                     extra={**({"surface": wall.kind} if wall.kind else {}),  # contract 4: on a surface
                            "clicked": [float(u), float(v)], "snapped": where.snapped, **(extra or {})})
    s.add(d)
    s.flush()
    _audit(s, d, user, action, 0, {}, note)
    s.flush()
    return detection_dict(d)


def _next_ref(s: Session, job_id: int) -> str:
    """The next reference of the job's series (``D0121`` after ``D0120``; the job's rows are
    locked by the project's lock that every addition takes)."""
    refs = s.scalars(select(DetectionRow.ref).where(DetectionRow.job_id == job_id))
    numbers = [int(r[1:]) for r in refs if len(r) > 1 and r[0] == "D" and r[1:].isdigit()]
    return f"D{max(numbers, default=0) + 1:04d}"


def _snap(s: Session, job: Job, wall: WallRow, class_id: str, where: Snap, data_dir: Path) -> Snap:
    meta = (wall.images or {}).get("depth")
    if not meta:
        return where
    try:
        depth = np.load(data_dir / meta["path"], allow_pickle=False)
    except (OSError, ValueError):
        return where
    tpl = depth_template(models_dir(s, job.models_id, data_dir) / class_id, wall.pixel_m)
    if tpl is None:
        return where
    return snap_to_relief(depth, wall.pixel_m, wall.height_m, tpl, u=where.u, v=where.v)


def promote(s: Session, sid: int, user: Principal, data_dir: Path, *, pid: int | None = None) -> dict:
    """Turn a suggestion (a candidate recognition did not keep) into an accepted object."""
    sg = s.get(SuggestionRow, sid, with_for_update=True)
    if sg is None or (pid is not None and sg.project_id != pid):
        raise NotFound(f"suggestion {sid} not found")
    p = open_project(s, sg.project_id)
    if sg.job_id != p.current_job_id:
        raise Conflict(f"suggestion {sid} belongs to results replaced by job {p.current_job_id}")
    if sg.promoted_id is not None:
        raise Conflict(f"suggestion {sid} was already promoted (detection {sg.promoted_id})")
    det = add_object(s, sg.project_id, sg.class_id, sg.wall_key, sg.u, sg.v, user, data_dir,
                     snap=False, action="promote", status="accepted",
                     note=f"suggestion {sid} ({sg.source}, {sg.reason})",
                     extra={"suggestion": sid, "suggested_by": sg.source, "score": sg.score})
    sg.promoted_id = int(det["id"])
    s.flush()
    return det


def suggestion_dict(sg: SuggestionRow) -> dict:
    return {"id": str(sg.id), "class": sg.class_id, "wall": sg.wall_key, "u": sg.u, "v": sg.v,
            "width_m": sg.width_m, "height_m": sg.height_m, "source": sg.source, "score": sg.score,
            "reason": sg.reason, "promoted": None if sg.promoted_id is None else str(sg.promoted_id)}


def suggestions(s: Session, p: Project, *, include_promoted: bool = False) -> list[dict]:
    """The current job's possible misses, per wall, strongest first."""
    if p.current_job_id is None:
        return []
    q = select(SuggestionRow).where(SuggestionRow.job_id == p.current_job_id)
    if not include_promoted:
        q = q.where(SuggestionRow.promoted_id.is_(None))
    rows = list(s.scalars(q))

    def strength(sg: SuggestionRow) -> float:  # rho_D higher is better, rho_C lower is better
        if sg.score is None:
            return 0.0
        return sg.score if sg.source == "depth" else 1.0 - sg.score

    rows.sort(key=lambda sg: (sg.wall_key, -strength(sg)))
    return [suggestion_dict(sg) for sg in rows]


# --------------------------------------------------------------------------- sign-off, reopen


def signoff_dict(so: SignOff | None) -> dict | None:
    if so is None:
        return None
    return {"by": so.user_name, "at": iso(so.at), "comment": so.comment, "counts": so.counts,
            "job": so.job_id}


def sign_off(s: Session, pid: int, comment: str, user: Principal) -> dict:
    """Lock the reviewed results (manager): 409 while anything is pending or a job runs."""
    if not user.may("manager"):
        raise Forbidden(f"user '{user.name}' has role {user.role}; signing off needs manager")
    p = open_project(s, pid)
    if p.current_job_id is None:
        raise Conflict(f"project {pid} has no finished detection job to sign off")
    busy = s.scalar(select(func.count(Job.id)).where(Job.project_id == pid,
                                                     Job.status.in_(("queued", "running"))))
    if busy:
        raise Conflict(f"project {pid} has {busy} job(s) queued or running")
    counts = review_counts(s, p)
    if counts["pending"]:
        raise Conflict(f"{counts['pending']} detection(s) are still pending review")
    now = utcnow()
    so = SignOff(project_id=pid, job_id=p.current_job_id, user_id=user.id, user_name=user.name,
                 at=now, comment=comment, counts=counts)
    s.add(so)
    s.add(ProjectEvent(project_id=pid, user_id=user.id, user_name=user.name, at=now, kind="signoff",
                       comment=comment, data={"job": p.current_job_id, "counts": counts}))
    p.status = "signed_off"
    s.flush()
    return {"project": pid, "status": p.status, "counts": counts, "signoff": signoff_dict(so)}


def reopen(s: Session, pid: int, reason: str, user: Principal) -> dict:
    """Open a signed-off project again (admin), with a reason; the sign-off stays in the history."""
    if not user.may("admin"):
        raise Forbidden(f"user '{user.name}' has role {user.role}; reopening needs admin")
    if not reason or not reason.strip():
        raise Invalid("reason: say why the project is reopened")
    p = s.get(Project, pid, with_for_update=True)
    if p is None:
        raise NotFound(f"project {pid} not found")
    if p.status == "open":
        raise Conflict(f"project {pid} is not signed off")
    so = current_signoff(s, pid)
    s.add(ProjectEvent(project_id=pid, user_id=user.id, user_name=user.name, at=utcnow(), kind="reopen",
                       comment=reason.strip(), data={"signoff": signoff_dict(so)}))
    p.status = "open"
    s.flush()
    return {"project": pid, "status": p.status, "reopened_by": user.name, "reason": reason.strip()}


def event_dict(e: ProjectEvent) -> dict:
    return {"id": e.id, "kind": e.kind, "by": e.user_name, "at": iso(e.at), "comment": e.comment,
            "data": e.data}


def events(s: Session, pid: int) -> list[dict]:
    return [event_dict(e) for e in s.scalars(select(ProjectEvent).where(ProjectEvent.project_id == pid)
                                             .order_by(ProjectEvent.id))]


# --------------------------------------------------------------------------- jobs


def is_reviewed(s: Session, p: Project) -> bool:
    """Whether anyone has decided on the project's current results."""
    if p.current_job_id is None:
        return False
    ids = select(DetectionRow.id).where(DetectionRow.job_id == p.current_job_id)
    return bool(s.scalar(select(func.count(ReviewDecision.id))
                         .where(ReviewDecision.detection_id.in_(ids))))


def carry_over(s: Session, old_job_id: int | None, new_job: Job,
               tolerance_m: float = CARRY_TOLERANCE_M) -> dict:
    """Carry the decisions on ``old_job_id``'s detections to what ``new_job`` finds again.

    A new detection is the same object as a decided old one when its class is the old
    one's (as detected or as relabelled) and its position is within ``tolerance_m`` (or
    half the object's larger side); pairs are matched one to one, closest first. The new
    detection takes the old status and class, with a ``carry`` audit row naming the old
    detection. Objects a reviewer added that the new run does not find are copied over;
    other decisions stay with the old detections, in the history.
    """
    out = {"carried": 0, "added_kept": 0, "not_found": 0}
    if old_job_id is None or old_job_id == new_job.id:
        return out
    old = [d for d in s.scalars(select(DetectionRow).where(DetectionRow.job_id == old_job_id)
                                .order_by(DetectionRow.id))
           if d.status != "pending" or d.source == "reviewer"]
    if not old:
        return out
    new = list(s.scalars(select(DetectionRow).where(DetectionRow.job_id == new_job.id)
                         .order_by(DetectionRow.id)))
    pairs = []
    for i, o in enumerate(old):
        po = np.asarray(o.position, float)
        tol = max(tolerance_m, 0.5 * max(o.width_m, o.height_m))
        for j, n in enumerate(new):
            if n.detected_class not in (o.class_id, o.detected_class):
                continue
            dist = float(np.linalg.norm(np.asarray(n.position, float) - po))
            if dist <= tol:
                pairs.append((dist, i, j))
    used_o, used_n = set(), set()
    matched: dict[int, int] = {}
    for _, i, j in sorted(pairs):
        if i in used_o or j in used_n:
            continue
        used_o.add(i)
        used_n.add(j)
        matched[i] = j
    walls = {w.key: w for w in s.scalars(select(WallRow).where(WallRow.job_id == new_job.id))}
    for i, o in enumerate(old):
        if i in matched:
            n = new[matched[i]]
            before, v0 = _state(n), n.version
            n.status = o.status
            if o.class_id != n.class_id:
                n.class_id, n.width_m, n.height_m = o.class_id, o.width_m, o.height_m
            n.version += 1
            n.reviewed_by, n.reviewed_at = o.reviewed_by, o.reviewed_at or utcnow()
            n.carried_from = o.id
            s.flush()
            _audit(s, n, None, "carry", v0, before,
                   f"carried over from detection {o.id} of job {old_job_id}",
                   user_name=o.reviewed_by or "system")
            out["carried"] += 1
        elif o.source == "reviewer" and o.wall_key in walls:
            w = walls[o.wall_key]
            if not (0.0 <= o.u <= w.width_m and 0.0 <= o.v <= w.height_m):
                out["not_found"] += 1
                continue
            taken = o.ref in {d.ref for d in new}  # the new run's series may have reached it
            n = DetectionRow(project_id=o.project_id, job_id=new_job.id,
                             ref=_next_ref(s, new_job.id) if taken else o.ref, class_id=o.class_id,
                             detected_class=o.detected_class, wall_key=o.wall_key,
                             position=_position(w, o.u, o.v), u=o.u, v=o.v, width_m=o.width_m,
                             height_m=o.height_m, alpha=None, rho_depth=o.rho_depth, rho_colour=None,
                             source="reviewer", status=o.status, version=1, reviewed_by=o.reviewed_by,
                             reviewed_at=o.reviewed_at, note=o.note, extra=o.extra, carried_from=o.id)
            s.add(n)
            s.flush()
            _audit(s, n, None, "carry", 0, {}, f"added object carried over from detection {o.id} "
                   f"of job {old_job_id}", user_name=o.reviewed_by or "system")
            out["added_kept"] += 1
        else:
            out["not_found"] += 1
    s.add(ProjectEvent(project_id=new_job.project_id, user_id=None, user_name=new_job.created_by or "system",
                       at=utcnow(), kind="carry_over", comment=None,
                       data={"from_job": old_job_id, "to_job": new_job.id, **out}))
    s.flush()
    return out


# --------------------------------------------------------------------------- summary


def review_summary(s: Session, pid: int) -> dict:
    """Decisions per minute, how many in bulk, objects added, per reviewer and in all."""
    p = s.get(Project, pid)
    if p is None:
        raise NotFound(f"project {pid} not found")
    rows = list(s.scalars(select(ReviewDecision).where(ReviewDecision.project_id == pid,
                                                       ReviewDecision.action != "carry")
                          .order_by(ReviewDecision.id)))

    def stats(rs: list[ReviewDecision]) -> dict:
        if not rs:
            return {"decisions": 0, "single": 0, "bulk": 0, "bulk_batches": 0, "added": 0,
                    "promoted": 0, "minutes": 0.0, "per_minute": None, "first": None, "last": None}
        t0, t1 = rs[0].at, rs[-1].at
        minutes = max((t1 - t0).total_seconds() / 60.0, 0.0)
        bulk = [r for r in rs if r.batch]
        return {"decisions": len(rs), "single": len(rs) - len(bulk), "bulk": len(bulk),
                "bulk_batches": len({r.batch for r in bulk}),
                "added": sum(r.action == "add" for r in rs),
                "promoted": sum(r.action == "promote" for r in rs),
                "minutes": round(minutes, 3),
                "per_minute": round(len(rs) / max(minutes, 1.0 / 60.0), 2),
                "first": iso(t0), "last": iso(t1)}

    by_user: dict[str, list[ReviewDecision]] = {}
    for r in rows:
        by_user.setdefault(r.user_name, []).append(r)
    return {"project": pid, "counts": review_counts(s, p), **stats(rows),
            "reviewers": {u: stats(rs) for u, rs in sorted(by_user.items())},
            "carried": int(s.scalar(select(func.count(ReviewDecision.id)).where(
                ReviewDecision.project_id == pid, ReviewDecision.action == "carry")) or 0)}
