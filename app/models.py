"""Database tables (SQLAlchemy 2 declarative). The schema is created by Alembic (``app/migrations``).

Large files live on disk under the data dir; rows hold their relative path, size and SHA-256.
``review_decisions`` is an append-only audit trail: the ORM refuses to update or delete its
rows and the migration adds database triggers that refuse it too.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    MetaData,
    String,
    Text,
    UniqueConstraint,
    event,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

ROLES: tuple[str, ...] = ("reviewer", "manager", "admin")  # each role may do what the ones before may
JOB_STATUSES: tuple[str, ...] = ("queued", "running", "succeeded", "failed", "cancelled")
REVIEW_STATUSES: tuple[str, ...] = ("pending", "accepted", "rejected")

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC)


def iso(dt: datetime | None) -> str | None:
    """ISO 8601 in UTC with a ``Z`` (SQLite hands back naive datetimes, which are UTC here)."""
    if dt is None:
        return None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=UTC)
    return dt.astimezone(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)
    type_annotation_map = {dict[str, Any]: JSON, list[float]: JSON}


Stamp = DateTime(timezone=True)


class User(Base):
    __tablename__ = "users"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    role: Mapped[str] = mapped_column(String(20))
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)  # sha256 hex of the token
    created_at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)
    disabled: Mapped[bool] = mapped_column(Boolean, default=False)


class Project(Base):
    __tablename__ = "projects"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    status: Mapped[str] = mapped_column(String(20), default="open")  # open | signed_off
    created_at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)
    created_by: Mapped[str | None] = mapped_column(String(100))
    models_id: Mapped[int | None] = mapped_column(
        ForeignKey("model_libraries.id", use_alter=True, name="fk_projects_models_id"))
    current_job_id: Mapped[int | None] = mapped_column(
        ForeignKey("jobs.id", use_alter=True, name="fk_projects_current_job_id"))


class Scan(Base):
    __tablename__ = "scans"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    filename: Mapped[str] = mapped_column(String(255))
    path: Mapped[str] = mapped_column(String(500))  # relative to the data dir
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    sha256: Mapped[str] = mapped_column(String(64))
    points: Mapped[int] = mapped_column(BigInteger)
    uploaded_by: Mapped[str | None] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)


class ModelLibraryRow(Base):
    __tablename__ = "model_libraries"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    filename: Mapped[str] = mapped_column(String(255))
    path: Mapped[str] = mapped_column(String(500))  # extracted library dir, relative to data dir
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    sha256: Mapped[str] = mapped_column(String(64))  # of the uploaded zip
    classes: Mapped[dict[str, Any]] = mapped_column(JSON)  # class id -> model.json fields
    uploaded_by: Mapped[str | None] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)


class DesignRow(Base):
    """An as-designed IFC file of a project; the newest row is the one compared with."""

    __tablename__ = "designs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    filename: Mapped[str] = mapped_column(String(255))
    path: Mapped[str] = mapped_column(String(500))  # relative to the data dir
    size_bytes: Mapped[int] = mapped_column(BigInteger)
    sha256: Mapped[str] = mapped_column(String(64))
    objects: Mapped[int] = mapped_column(Integer)  # designed objects mapped to library classes
    expected_counts: Mapped[dict[str, Any]] = mapped_column(JSON)  # class id -> count
    uploaded_by: Mapped[str | None] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)


class Job(Base):
    __tablename__ = "jobs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    status: Mapped[str] = mapped_column(String(20), default="queued", index=True)
    stage: Mapped[str] = mapped_column(String(100), default="queued")
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    error: Mapped[str | None] = mapped_column(Text)
    expected: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    models_id: Mapped[int | None] = mapped_column(ForeignKey("model_libraries.id"))
    retry_of: Mapped[int | None] = mapped_column(ForeignKey("jobs.id"))
    created_by: Mapped[str | None] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(Stamp)
    finished_at: Mapped[datetime | None] = mapped_column(Stamp)
    updated_at: Mapped[datetime | None] = mapped_column(Stamp)
    owner: Mapped[str | None] = mapped_column(String(64))  # the server instance running it
    worker_pid: Mapped[int | None] = mapped_column(Integer)
    out_dir: Mapped[str | None] = mapped_column(String(500))  # relative to the data dir
    cancelled_by: Mapped[str | None] = mapped_column(String(100))
    storeys: Mapped[list[Any] | None] = mapped_column(JSON)  # contract 4's storeys block of the results
    expected_storeys: Mapped[dict[str, Any] | None] = mapped_column(JSON)  # contract 3's per-storey counts


class WallRow(Base):
    """A wall of a job's results, or a surface beyond walls (contract 4's ``surfaces``: ``kind``)."""

    __tablename__ = "walls"
    __table_args__ = (UniqueConstraint("job_id", "key"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    key: Mapped[str] = mapped_column(String(50))  # "W03"
    origin: Mapped[list[float]] = mapped_column(JSON)
    axis_u: Mapped[list[float]] = mapped_column(JSON)
    axis_v: Mapped[list[float]] = mapped_column(JSON)
    normal: Mapped[list[float]] = mapped_column(JSON)
    width_m: Mapped[float] = mapped_column(Float)
    height_m: Mapped[float] = mapped_column(Float)
    pixel_m: Mapped[float] = mapped_column(Float)
    images: Mapped[dict[str, Any]] = mapped_column(JSON)  # kind -> {"path", "bytes", "sha256"}
    storey: Mapped[str | None] = mapped_column(String(50))  # "S2" in a scan of several storeys
    kind: Mapped[str | None] = mapped_column(String(20))  # None: a wall; "ceiling" / "column": a surface
    extra: Mapped[dict[str, Any] | None] = mapped_column(JSON)  # other surface fields (column, radius_m, centre)


class OpeningRow(Base):
    __tablename__ = "openings"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    wall_key: Mapped[str] = mapped_column(String(50))
    kind: Mapped[str] = mapped_column(String(20))
    u_min: Mapped[float] = mapped_column(Float)
    u_max: Mapped[float] = mapped_column(Float)
    v_min: Mapped[float] = mapped_column(Float)
    v_max: Mapped[float] = mapped_column(Float)


class DetectionRow(Base):
    __tablename__ = "detections"
    __table_args__ = (UniqueConstraint("job_id", "ref"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    ref: Mapped[str] = mapped_column(String(50))  # the pipeline's id, "D0007"
    class_id: Mapped[str] = mapped_column(String(100))
    detected_class: Mapped[str] = mapped_column(String(100))
    wall_key: Mapped[str] = mapped_column(String(50))
    position: Mapped[list[float]] = mapped_column(JSON)
    u: Mapped[float] = mapped_column(Float)
    v: Mapped[float] = mapped_column(Float)
    width_m: Mapped[float] = mapped_column(Float)
    height_m: Mapped[float] = mapped_column(Float)
    alpha: Mapped[float | None] = mapped_column(Float)
    rho_depth: Mapped[float | None] = mapped_column(Float)
    rho_colour: Mapped[float | None] = mapped_column(Float)
    source: Mapped[str] = mapped_column(String(20))
    status: Mapped[str] = mapped_column(String(20), default="pending", index=True)
    version: Mapped[int] = mapped_column(Integer, default=1)
    reviewed_by: Mapped[str | None] = mapped_column(String(100))
    reviewed_at: Mapped[datetime | None] = mapped_column(Stamp)
    confidence: Mapped[float | None] = mapped_column(Float)  # contract 4's calibrated confidence
    extra: Mapped[dict[str, Any] | None] = mapped_column(JSON)  # other contract-4 fields (rotation_deg, ...)
    note: Mapped[str | None] = mapped_column(Text)  # a reviewer's note on an added object
    carried_from: Mapped[int | None] = mapped_column(Integer)  # the detection of an earlier job


class ReviewDecision(Base):
    """One review action: who, when, from what to what. Never updated, never deleted."""

    __tablename__ = "review_decisions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    detection_id: Mapped[int] = mapped_column(ForeignKey("detections.id"), index=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    user_id: Mapped[int | None] = mapped_column(ForeignKey("users.id"))
    user_name: Mapped[str] = mapped_column(String(100))
    at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)
    action: Mapped[str] = mapped_column(String(50))  # e.g. "accept", "reject+relabel", "move"
    version_from: Mapped[int] = mapped_column(Integer)
    version_to: Mapped[int] = mapped_column(Integer)
    before: Mapped[dict[str, Any]] = mapped_column(JSON)  # {"status", "class", "u", "v"}
    after: Mapped[dict[str, Any]] = mapped_column(JSON)
    comment: Mapped[str | None] = mapped_column(Text)
    batch: Mapped[str | None] = mapped_column(String(40), index=True)  # one bulk decision


class SuggestionRow(Base):
    """A candidate recognition found but did not keep: offered to the reviewer as a possible miss."""

    __tablename__ = "suggestions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    class_id: Mapped[str] = mapped_column(String(100))
    wall_key: Mapped[str] = mapped_column(String(50))
    u: Mapped[float] = mapped_column(Float)
    v: Mapped[float] = mapped_column(Float)
    width_m: Mapped[float] = mapped_column(Float)
    height_m: Mapped[float] = mapped_column(Float)
    source: Mapped[str] = mapped_column(String(20))  # depth | colour
    score: Mapped[float | None] = mapped_column(Float)  # rho_D (depth) or rho_C (colour)
    reason: Mapped[str] = mapped_column(String(40))  # below_threshold | lost_in_consensus
    promoted_id: Mapped[int | None] = mapped_column(Integer)  # the detection it became


class ProjectEvent(Base):
    """A project-level action (sign-off, reopen, job cancelled, decisions carried over). Append-only."""

    __tablename__ = "project_events"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    user_id: Mapped[int | None] = mapped_column(ForeignKey("users.id"))
    user_name: Mapped[str] = mapped_column(String(100))
    at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)
    kind: Mapped[str] = mapped_column(String(40))
    comment: Mapped[str | None] = mapped_column(Text)
    data: Mapped[dict[str, Any] | None] = mapped_column(JSON)


class SignOff(Base):
    __tablename__ = "signoffs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)  # newest = current
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id"))
    user_id: Mapped[int | None] = mapped_column(ForeignKey("users.id"))
    user_name: Mapped[str] = mapped_column(String(100))
    at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)
    comment: Mapped[str] = mapped_column(Text)
    counts: Mapped[dict[str, Any]] = mapped_column(JSON)


class ProjectMember(Base):
    """A user's role in one project (viewer, reviewer, manager); see ``app.membership``."""

    __tablename__ = "project_members"
    __table_args__ = (UniqueConstraint("project_id", "user_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    project_id: Mapped[int] = mapped_column(ForeignKey("projects.id"), index=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    role: Mapped[str] = mapped_column(String(20))
    added_by: Mapped[str | None] = mapped_column(String(100))
    added_at: Mapped[datetime] = mapped_column(Stamp, default=utcnow)


@event.listens_for(ReviewDecision, "before_update")
@event.listens_for(ReviewDecision, "before_delete")
@event.listens_for(ProjectEvent, "before_update")
@event.listens_for(ProjectEvent, "before_delete")
def _audit_is_append_only(mapper: Any, connection: Any, target: Any) -> None:
    raise PermissionError(f"{target.__tablename__} is an append-only audit trail")
