"""The :class:`~app.viewer.backend.ReviewBackend` on the review service's database.

Reads go straight to the service's tables (``app.models``) and documents
(``app.results.project_document``), so the scene shows exactly what
``GET /api/projects/{pid}/detections`` answers. Decisions and added objects go through the
review service (:mod:`app.review_service`), the functions the REST routes call: one code path
for the version check, the 423 after sign-off, the relabel rules and the append-only audit
row, whichever side the decision comes from.

The change feed is the audit trail: every decision is a ``review_decisions`` row with an
increasing id, so "what changed since cursor" is one indexed query; a new current job
(results replaced) asks the scene to rebuild.
"""

from __future__ import annotations

import json
from typing import Any

from sqlalchemy import func, select

from .. import review_service as svc
from ..auth import Principal, authenticate
from ..config import AppSettings
from ..db import Database
from ..libraries import library_classes, models_dir
from ..models import DetectionRow, Job, Project, ReviewDecision, Scan
from ..results import detection_dict, project_document
from ..review_rules import check_may_review
from .backend import (
    Changes,
    Forbidden,
    NotFound,
    NotReady,
    ProjectData,
    ProjectId,
    Reviewer,
)

# Decisions are re-read this far behind the cursor: on PostgreSQL ids are handed out before
# commit, so a smaller id can become visible after a larger one. Re-reading is harmless
# (the scene ignores a detection whose version it already shows).
CURSOR_OVERLAP = 20



class DbReviewBackend:
    """The review service's database as the 3D scene sees it. Thread-safe (a session per call)."""

    def __init__(self, db: Database, settings: AppSettings) -> None:
        self.db = db
        self.settings = settings

    def _signoff(self, s: Any, pid: int) -> dict | None:
        return svc.signoff_dict(svc.current_signoff(s, pid))

    def project_data(self, pid: ProjectId) -> ProjectData:
        data_dir = self.settings.data_dir
        with self.db.read() as s:
            p = s.get(Project, int(pid))
            if p is None:
                raise NotFound(f"project {pid} not found")
            if p.current_job_id is None:
                raise NotReady(f"project {pid} has no detection results yet")
            doc = project_document(s, p)
            job = s.get(Job, p.current_job_id)
            out = data_dir / job.out_dir if job is not None and job.out_dir else None
            scans = [data_dir / path for path in s.scalars(
                select(Scan.path).where(Scan.project_id == p.id).order_by(Scan.id))]
            models_id = job.models_id if job is not None else None
            classes = library_classes(s, models_id)
            library = models_dir(s, models_id, data_dir)
            locked = p.status != "open"
            signoff = self._signoff(s, p.id) if locked else None
            name = p.name
        rois = None
        if out is not None and (out / "rois.json").is_file():
            try:
                rois = json.loads((out / "rois.json").read_text(encoding="utf-8"))
            except (OSError, ValueError):
                rois = None  # the scene simply shows no RoIs
        ortho = out / "orthoimages" if out is not None else None
        return ProjectData(
            pid=pid, name=name, detections=doc, rois=rois,
            ortho_dir=ortho if ortho is not None and ortho.is_dir() else None, scans=scans,
            cache_dir=self.settings.projects_dir / str(int(pid)) / "viewer",
            models_dir=library, classes=sorted(classes), locked=locked, signoff=signoff,
            revision=doc.get("job"))

    def changes_since(self, pid: ProjectId, cursor: Any) -> Changes:
        with self.db.read() as s:
            p = s.get(Project, int(pid))
            if p is None:
                raise NotFound(f"project {pid} not found")
            last = s.scalar(select(func.max(ReviewDecision.id))
                            .where(ReviewDecision.project_id == p.id)) or 0
            locked = p.status != "open"
            signoff = self._signoff(s, p.id) if locked else None
            now = (int(last), p.current_job_id)
            if cursor is None:
                return Changes(now, [], locked, signoff)
            seen, job = cursor
            if job != p.current_job_id:
                return Changes(now, [], locked, signoff, reload=True)
            dets: list[dict] = []
            if last > seen - CURSOR_OVERLAP and last > 0:
                ids = select(ReviewDecision.detection_id).where(
                    ReviewDecision.project_id == p.id,
                    ReviewDecision.id > seen - CURSOR_OVERLAP)
                rows = s.scalars(select(DetectionRow).where(DetectionRow.id.in_(ids),
                                                            DetectionRow.job_id == job)
                                 .order_by(DetectionRow.id))
                dets = [detection_dict(r) for r in rows]
            return Changes(now, dets, locked, signoff)

    def resolve_user(self, user_id: int, project: int | None = None) -> Reviewer | None:
        """The user behind a viewer ticket (None when disabled or gone since); for ``project``,
        with its role there (None when no longer a member)."""
        from ..membership import project_role
        from ..models import User

        with self.db.read() as s:
            u = s.get(User, int(user_id))
            if u is None or u.disabled:
                return None
            role = u.role if project is None else project_role(s, Principal(u.id, u.name, u.role), project)
            if role is None:
                return None
            return Reviewer(name=u.name, role=role, ref=Principal(id=u.id, name=u.name, role=role))

    def resolve_token(self, token: str) -> Reviewer | None:
        token = (token or "").strip()
        if not token:
            return None
        with self.db.read() as s:
            principal = authenticate(s, token)
        if principal is None:
            return None
        return Reviewer(name=principal.name, role=principal.role, ref=principal)

    def _principal(self, user: Reviewer) -> Principal:
        check_may_review(user.name, user.role)
        if not isinstance(user.ref, Principal):
            raise Forbidden(f"{user.name}: not a user of the review app")
        return user.ref

    def _call(self, op: Any) -> Any:
        """Run a review service operation in one write transaction; its errors (:mod:`app.errors`,
        the scene's own) pass through."""
        with self.db.write() as s:
            return op(s)

    def decide(self, pid: ProjectId, detection_id: str, status: str, new_class: str | None,
               version: int, user: Reviewer) -> dict:
        principal = self._principal(user)
        try:
            did = int(detection_id)
        except ValueError:
            raise NotFound(f"detection {detection_id} not found") from None
        change = svc.Change(version=int(version), status=status, class_=new_class)
        return self._call(lambda s: svc.decide(s, did, change, principal, pid=int(pid)))

    def add_object(self, pid: ProjectId, class_id: str, wall: str, u: float, v: float,
                   user: Reviewer, note: str | None = None) -> dict:
        """An object recognition missed, added where the reviewer clicked (snapped to the relief)."""
        principal = self._principal(user)
        return self._call(lambda s: svc.add_object(s, int(pid), class_id, wall, u, v, principal,
                                                   self.settings.data_dir, note=note))
