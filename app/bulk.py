"""Bulk decisions in bounded batches: one decision for many detections that never holds the
database long (issue 30).

The selection is made in a read transaction (no write lock; the dry run and the confirmed
count ``expect`` stop here). The changes are then written in batches of ``batch_size``
detections, each its own short write transaction, so a single decision of another reviewer
(or on another project) waits for one batch at most, never for the whole request; between
batches the bulk pauses for half a batch's time, so the other requests keep most of the
CPU (Python threads share one) while it runs. Every
batch re-checks what it changes (a detection decided meanwhile is skipped with its reason),
and all batches share one ``batch`` id and one time: the result and the audit trail read
exactly as those of one request.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Sequence

from sqlalchemy import insert, select, update
from sqlalchemy.orm import Session

from .auth import Principal
from .db import Database
from .errors import Conflict, Invalid
from .models import DetectionRow, Project, ReviewDecision, utcnow
from .review_rules import check_status
from .review_service import ACTIONS, BULK_MAX, RELABELLED, Filter, open_project, select_detections

BATCH = 100  # detections per write transaction (~5-15 ms on SQLite; 250 gave a longer tail)
YIELD_S = 0.002  # between batches at least: other writers waiting on the lock get it first
PACE = 0.5  # and this times the batch's own time: the other requests keep most of the CPU
_IN = 500  # ids per IN (...) of a read


def _select_ids(s: Session, p: Project, ids: Sequence[int | str], status: str) -> tuple[list[int], list[dict]]:
    """The detections ``ids`` names that would change, in their order, and the skipped ones."""
    if len(ids) > BULK_MAX:
        raise Invalid(f"ids: at most {BULK_MAX}")
    skipped: list[dict] = []
    wanted: list[int] = []
    seen: set[int] = set()
    for raw in ids:
        try:
            did = int(raw)
        except (TypeError, ValueError):
            skipped.append({"id": str(raw), "reason": "not a detection id"})
            continue
        if did in seen:
            continue
        if not 0 < did < 2**62:
            skipped.append({"id": str(raw), "reason": "not found in this project"})
            continue
        seen.add(did)
        wanted.append(did)
    found: dict[int, tuple] = {}
    for i in range(0, len(wanted), _IN):
        chunk = wanted[i:i + _IN]
        for row in s.execute(select(DetectionRow.id, DetectionRow.project_id, DetectionRow.job_id,
                                    DetectionRow.status, DetectionRow.class_id, DetectionRow.detected_class)
                             .where(DetectionRow.id.in_(chunk))):
            found[row[0]] = row
    rows: list[int] = []
    for did in wanted:
        row = found.get(did)
        if row is None or row[1] != p.id:
            skipped.append({"id": str(did), "reason": "not found in this project"})
        elif row[2] != p.current_job_id:
            skipped.append({"id": str(did), "reason": "replaced by a newer job"})
        elif row[3] == status:
            skipped.append({"id": str(did), "reason": f"already {status}"})
        elif row[4] != row[5]:
            skipped.append({"id": str(did), "reason": RELABELLED})
        else:
            rows.append(did)
    return rows, skipped


def _write_batch(s: Session, pid: int, chunk: list[int], status: str, user: Principal, *,
                 batch: str, now, comment: str | None) -> tuple[list[int], list[dict]]:  # noqa: ANN001
    """Decide ``chunk`` in this transaction; answers the changed ids and the ones skipped now."""
    p = s.get(Project, pid, with_for_update=True)
    if p is None or p.status != "open":
        why = "the project was signed off meanwhile" if p is not None else "the project is gone"
        return [], [{"id": str(d), "reason": why} for d in chunk]
    cols = (DetectionRow.id, DetectionRow.job_id, DetectionRow.status, DetectionRow.class_id,
            DetectionRow.u, DetectionRow.v, DetectionRow.version, DetectionRow.detected_class)
    current = {r[0]: r for r in s.execute(select(*cols).where(DetectionRow.id.in_(chunk)).with_for_update())}
    audit, done, skipped = [], [], []
    for did in chunk:
        r = current.get(did)
        if r is None:
            skipped.append({"id": str(did), "reason": "not found in this project"})
        elif r[1] != p.current_job_id:
            skipped.append({"id": str(did), "reason": "replaced by a newer job"})
        elif r[2] == status:
            skipped.append({"id": str(did), "reason": f"already {status}"})
        elif r[3] != r[7]:
            skipped.append({"id": str(did), "reason": RELABELLED})
        else:
            _, _, was, cls, u, v, version, _ = r
            audit.append({"detection_id": did, "project_id": pid, "user_id": user.id, "user_name": user.name,
                          "at": now, "action": ACTIONS[status], "version_from": version,
                          "version_to": version + 1, "before": {"status": was, "class": cls, "u": u, "v": v},
                          "after": {"status": status, "class": cls, "u": u, "v": v}, "comment": comment,
                          "batch": batch})
            done.append(did)
    if done:  # one UPDATE for the batch (the rows are locked: their versions are the ones read)
        table = DetectionRow.__table__
        s.execute(update(table).where(table.c.id.in_(done))
                  .values(status=status, version=table.c.version + 1, reviewed_by=user.name, reviewed_at=now))
        s.execute(insert(ReviewDecision.__table__), audit)  # Core: many rows in few statements
    return done, skipped


def bulk_decide(db: Database, pid: int, status: str, user: Principal, *,
                ids: Sequence[int | str] | None = None, flt: Filter | None = None,
                dry_run: bool = False, expect: int | None = None, comment: str | None = None,
                batch_size: int = BATCH) -> dict:
    """One decision for many detections (``ids`` or ``flt``), written in batches.

    ``dry_run`` only counts (for the confirmation the UI shows); ``expect`` is the count the
    reviewer confirmed: when the selection has changed meanwhile nothing is decided (409).
    Answers ``{"changed", "matched", "skipped": [{"id", "reason"}], "ids", "batch"}``; raises
    :mod:`app.errors` (404, 409, 422, 423).
    """
    check_status(status)
    if (ids is None) == (flt is None):
        raise Invalid("give either ids or filter")
    with db.read() as s:
        p = open_project(s, pid, lock=False)
        if ids is not None:
            rows, skipped = _select_ids(s, p, ids, status)
        else:
            assert flt is not None
            check_status(flt.review, "filter.review")
            chosen = [d for d in select_detections(s, p, flt) if d.status != status]
            rows = [d.id for d in chosen if d.class_id == d.detected_class]
            skipped = [{"id": str(d.id), "reason": RELABELLED} for d in chosen if d.class_id != d.detected_class]
    if expect is not None and expect != len(rows):
        raise Conflict(f"the selection changed: {len(rows)} detection(s) match now, not {expect}; "
                       "look again and confirm")
    out = {"changed": 0 if dry_run else len(rows), "matched": len(rows), "skipped": skipped,
           "ids": [str(d) for d in rows], "batch": None}
    if dry_run or not rows:
        return out
    batch, now = uuid.uuid4().hex[:16], utcnow()
    changed: list[int] = []
    pause = 0.0
    for i in range(0, len(rows), batch_size):
        if i:
            time.sleep(max(YIELD_S, pause))
        t0 = time.monotonic()
        with db.write() as s:
            if i == 0:  # as one request: a project locked before anything changed is a 423
                open_project(s, pid, lock=False)
            done, late = _write_batch(s, pid, rows[i:i + batch_size], status, user, batch=batch, now=now,
                                      comment=comment)
        changed += done
        skipped += late
        pause = min(PACE * (time.monotonic() - t0), 0.5)
    out.update(changed=len(changed), ids=[str(d) for d in changed], batch=batch if changed else None)
    return out
