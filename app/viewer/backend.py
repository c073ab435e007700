"""What the 3D review scene needs from the review service, as a small Protocol.

The scene (``app.viewer.scene``) never touches the database: it asks a :class:`ReviewBackend`
for a project's data, records decisions through it and polls its change feed. Two
implementations exist: :class:`InMemoryBackend` here (tests, and the stand-alone viewer of a
``sbsc detect`` output directory) and ``app.viewer.db_backend.DbReviewBackend`` on the review
service's tables, which records decisions through the service's own review function so that
the REST API and the scene share one code path, one audit trail and one ``version`` counter.

Detection dicts are those of contract 4 plus ``"review": {"status", "by", "at", "version"}``,
exactly as ``GET /api/projects/{pid}/detections`` answers them.
"""

from __future__ import annotations

import copy
import json
import threading
from collections.abc import Hashable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from sbsc_core.errors import InputError

from ..errors import Conflict, Forbidden, Locked, NotFound, NotReady, ReviewError, StaleVersion
from ..models import ROLES
from ..review_rules import check_may_review, check_open, check_status, check_version
from ..surfaces import point_on

__all__ = ["Changes", "Conflict", "Forbidden", "InMemoryBackend", "Locked", "NotFound", "NotReady",
           "ProjectData", "ProjectId", "ReviewBackend", "ReviewError", "Reviewer", "StaleVersion",
           "load_detection_dir"]

ProjectId = Hashable  # the service uses ints; the stand-alone viewer uses strings


@dataclass(frozen=True)
class Reviewer:
    """The person behind an API token. ``ref`` is whatever the backend needs to act as them."""

    name: str
    role: str
    ref: Any = None

    @property
    def may_decide(self) -> bool:
        return self.role in ROLES


@dataclass
class ProjectData:
    """Everything the scene shows of one project (read once when the scene is built)."""

    pid: ProjectId
    name: str
    detections: dict  # contract 4 document, each detection with its "review"
    rois: dict | None = None  # rois.json of ``sbsc detect`` (schema sbsc.rois/1)
    ortho_dir: Path | None = None  # orthoimages/ of ``sbsc detect``
    scans: list[Path] = field(default_factory=list)  # the registered scan files of the floor
    cache_dir: Path | None = None  # where the scene may keep its scan level-of-detail cache
    models_dir: Path | None = None  # model library (contract 2), for the class thumbnails
    classes: list[str] = field(default_factory=list)  # classes a detection may be relabelled to
    locked: bool = False  # signed off: read-only
    signoff: dict | None = None  # {"by", "at", "comment"} once signed off
    revision: Hashable = None  # changes when the detections document is replaced (new job)


@dataclass
class Changes:
    """What happened since a cursor: changed detections, the lock state, or a new document."""

    cursor: Any
    detections: list[dict] = field(default_factory=list)
    locked: bool = False
    signoff: dict | None = None
    reload: bool = False  # the detections document was replaced: rebuild the scene


@runtime_checkable
class ReviewBackend(Protocol):
    """The review service as the 3D scene sees it. Every method may be called from any thread."""

    def project_data(self, pid: ProjectId) -> ProjectData:
        """The project's detections (with review states), RoIs, images and scans.

        Raises :class:`NotFound` for an unknown project, :class:`NotReady` for one without
        detections yet.
        """

    def decide(self, pid: ProjectId, detection_id: str, status: str, new_class: str | None,
               version: int, user: Reviewer) -> dict:
        """Record a review decision; return the detection dict as it now stands.

        Raises :class:`StaleVersion` (409) when ``version`` is not the current one,
        :class:`Locked` (423) after sign-off, :class:`Forbidden` for a role that may not decide
        and :class:`NotFound` for an unknown detection.
        """

    def add_object(self, pid: ProjectId, class_id: str, wall: str, u: float, v: float,
                   user: Reviewer, note: str | None = None) -> dict:
        """Add an object recognition missed at ``(u, v)`` on ``wall``; return its detection dict.

        Raises :class:`Locked` (423) after sign-off, :class:`Forbidden` for a role that may not
        decide and :class:`NotFound` (or :class:`~app.errors.Invalid`) for a wall or class the
        project does not have.
        """

    def changes_since(self, pid: ProjectId, cursor: Any) -> Changes:
        """Detections changed after ``cursor`` (``None``: the current cursor, no detections)."""

    def resolve_token(self, token: str) -> Reviewer | None:
        """The user an API token belongs to, or ``None``."""


def now_iso() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def with_pending_review(doc: dict) -> dict:
    """A copy of a contract-4 document whose detections all carry a pending ``review``."""
    out = copy.deepcopy(doc)
    for d in out.get("detections", []):
        d.setdefault("review", {"status": "pending", "by": None, "at": None, "version": 1})
    return out


@dataclass
class _Project:
    data: ProjectData
    by_id: dict[str, dict]
    seq: int = 0
    changed_at: dict[str, int] = field(default_factory=dict)  # detection id -> seq of last change
    lock_seq: int = 0
    revision_seq: int = 0


class InMemoryBackend:
    """A thread-safe :class:`ReviewBackend` holding projects in memory.

    Used by the tests and by the stand-alone viewer (``python -m app.viewer DIR``). Decisions
    follow the REST rules: optimistic ``version``, 423 after sign-off, reviewer role or above.
    """

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._projects: dict[ProjectId, _Project] = {}
        self._tokens: dict[str, Reviewer] = {}

    # -- set-up ---------------------------------------------------------------------------
    def add_user(self, token: str, name: str, role: str) -> Reviewer:
        user = Reviewer(name=name, role=role, ref=name)
        with self._lock:
            self._tokens[token] = user
        return user

    def add_project(self, data: ProjectData) -> None:
        data.detections = with_pending_review(data.detections)
        with self._lock:
            old = self._projects.get(data.pid)
            p = _Project(data, {d["id"]: d for d in data.detections["detections"]})
            if old is not None:  # a new detections document: clients must rebuild
                p.seq = old.seq + 1
                p.revision_seq = p.seq
                p.lock_seq = old.lock_seq
            self._projects[data.pid] = p

    def add_detection_dir(self, pid: ProjectId, out_dir: Path, *, name: str | None = None,
                          scans: list[Path] | None = None, models_dir: Path | None = None,
                          cache_dir: Path | None = None) -> ProjectData:
        """Add a project from an output directory of ``sbsc detect``."""
        data = load_detection_dir(pid, out_dir, name=name, scans=scans, models_dir=models_dir,
                                  cache_dir=cache_dir)
        self.add_project(data)
        return data

    def sign_off(self, pid: ProjectId, user: Reviewer, comment: str = "") -> None:
        with self._lock:
            p = self._project(pid)
            p.data.locked = True
            p.data.signoff = {"by": user.name, "at": now_iso(), "comment": comment}
            p.seq += 1
            p.lock_seq = p.seq

    # -- ReviewBackend ----------------------------------------------------------------------
    def project_data(self, pid: ProjectId) -> ProjectData:
        with self._lock:
            p = self._project(pid)
            data = copy.copy(p.data)
            data.detections = copy.deepcopy(p.data.detections)
            data.revision = p.revision_seq
            return data

    def decide(self, pid: ProjectId, detection_id: str, status: str, new_class: str | None,
               version: int, user: Reviewer) -> dict:
        check_status(status)
        check_may_review(user.name, user.role)
        with self._lock:
            p = self._project(pid)
            det = p.by_id.get(detection_id)
            if det is None:
                raise NotFound(f"detection {detection_id}: not found")
            check_open(pid, p.data.locked, copy.deepcopy(det))
            check_version(detection_id, version, det["review"]["version"], det["review"].get("by"),
                          copy.deepcopy(det))
            if new_class is not None:
                det["class"] = new_class
            det["review"] = {"status": status, "by": user.name, "at": now_iso(),
                             "version": det["review"]["version"] + 1}
            p.seq += 1
            p.changed_at[detection_id] = p.seq
            return copy.deepcopy(det)

    def add_object(self, pid: ProjectId, class_id: str, wall: str, u: float, v: float,
                   user: Reviewer, note: str | None = None) -> dict:
        """An object recognition missed, accepted by ``user`` (``source: reviewer``)."""
        check_may_review(user.name, user.role)
        with self._lock:
            p = self._project(pid)
            check_open(pid, p.data.locked)
            doc = p.data.detections
            w = next((x for x in [*doc.get("walls", []), *(doc.get("surfaces") or [])] if x["id"] == wall), None)
            if w is None:
                raise NotFound(f"wall {wall}: not found")
            pos = point_on(w, u, v)  # on a wall, a ceiling, a column's face or round column
            did = f"A{len(p.by_id) + 1:04d}"
            det = {"id": did, "ref": did, "class": class_id, "detected_class": class_id, "wall": wall,
                   **({"surface": w["kind"]} if w.get("kind") else {}),
                   "position": pos, "u": u, "v": v, "width_m": 0.08, "height_m": 0.08, "alpha": None,
                   "rho_depth": None, "rho_colour": None, "source": "reviewer", "note": note,
                   "review": {"status": "accepted", "by": user.name, "at": now_iso(), "version": 1}}
            p.data.detections["detections"].append(det)
            p.by_id[did] = det
            p.seq += 1
            p.changed_at[did] = p.seq
            return copy.deepcopy(det)

    def changes_since(self, pid: ProjectId, cursor: Any) -> Changes:
        with self._lock:
            p = self._project(pid)
            if cursor is None:
                return Changes(p.seq, [], p.data.locked, p.data.signoff)
            dets = [copy.deepcopy(p.by_id[i]) for i, s in p.changed_at.items() if s > cursor]
            return Changes(p.seq, dets, p.data.locked, p.data.signoff,
                           reload=p.revision_seq > cursor)

    def resolve_token(self, token: str) -> Reviewer | None:
        with self._lock:
            return self._tokens.get(token.strip())

    def _project(self, pid: ProjectId) -> _Project:
        p = self._projects.get(pid)
        if p is None:
            raise NotFound(f"project {pid}: not found")
        return p


def _read_json(path: Path, what: str) -> dict:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(path, f"no {what}") from None
    except (OSError, ValueError) as exc:
        raise InputError(path, f"cannot read {what}: {exc}") from None


def load_detection_dir(pid: ProjectId, out_dir: Path, *, name: str | None = None,
                       scans: list[Path] | None = None, models_dir: Path | None = None,
                       cache_dir: Path | None = None) -> ProjectData:
    """Read the output directory of ``sbsc detect`` into a :class:`ProjectData` (all pending)."""
    out_dir = Path(out_dir)
    doc = _read_json(out_dir / "detections.json", "detections document")
    if not str(doc.get("schema", "")).startswith("sbsc.detections/"):
        raise InputError(out_dir / "detections.json", "not a sbsc.detections document")
    rois_path = out_dir / "rois.json"
    rois = _read_json(rois_path, "RoIs document") if rois_path.exists() else None
    ortho = out_dir / "orthoimages"
    classes = sorted({d["class"] for d in doc.get("detections", [])}
                     | set(doc.get("classes_searched", [])))
    if models_dir is not None and Path(models_dir).is_dir():
        classes = sorted(set(classes) | {p.name for p in Path(models_dir).iterdir()
                                         if (p / "model.json").exists()})
    return ProjectData(
        pid=pid, name=name or out_dir.name, detections=with_pending_review(doc), rois=rois,
        ortho_dir=ortho if ortho.is_dir() else None, scans=list(scans or []),
        cache_dir=cache_dir or out_dir, models_dir=models_dir, classes=classes)
