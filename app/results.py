"""Detection results in the database: importing a finished output dir, building documents.

A job's output directory (``detections.json`` of contract 4, ``orthoimages/``) is imported
in the caller's single transaction. The documents served by the API and handed to the IFC
export are rebuilt from the rows: contract 4 with a ``review`` object per detection.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from sbsc_core.io.documents import read_detections

from .models import DetectionRow, Job, OpeningRow, Project, SuggestionRow, WallRow, iso
from .storage import sha256_file
from .surfaces import FRAME_FIELDS

DEFAULT_PIXEL_M = 0.005
# contract-4 detection fields with columns of their own; any other field is kept in ``extra``
DETECTION_COLUMNS = ("id", "class", "wall", "position", "u", "v", "width_m", "height_m", "alpha",
                     "rho_depth", "rho_colour", "source", "confidence", "review")
IMAGE_FILES = {"colour": "{w}_colour.png", "depth_png": "{w}_depth.png",
               "depth": "{w}_depth.npy", "overlay": "{w}_overlay.png"}


def file_meta(path: Path, data_dir: Path) -> dict:
    return {"path": path.relative_to(data_dir).as_posix(), "bytes": path.stat().st_size,
            "sha256": sha256_file(path)}


def import_results(session: Session, job: Job, out_dir: Path, data_dir: Path) -> dict[str, int]:
    """Add the walls, openings and detections of ``out_dir`` to ``session`` (not committed)."""
    doc = read_detections(out_dir / "detections.json")
    pixel_m = float(doc.get("pixel_m") or DEFAULT_PIXEL_M)
    surfaces = list(doc.get("surfaces") or [])  # contract 4: ceilings and column faces
    for w in [*doc["walls"], *surfaces]:
        images = {}
        for kind, pattern in IMAGE_FILES.items():
            p = out_dir / "orthoimages" / pattern.format(w=w["id"])
            if p.is_file():
                images[kind] = file_meta(p, data_dir)
        kind = str(w["kind"])[:20] if w.get("kind") else None
        extra = {k: v for k, v in w.items() if k not in FRAME_FIELDS} if kind else None
        session.add(WallRow(project_id=job.project_id, job_id=job.id, key=w["id"],
                            origin=list(w["origin"]), axis_u=list(w["axis_u"]),
                            axis_v=list(w["axis_v"]), normal=list(w["normal"]),
                            width_m=float(w["width_m"]), height_m=float(w["height_m"]),
                            pixel_m=pixel_m, images=images,
                            storey=str(w["storey"])[:50] if w.get("storey") else None,
                            kind=kind, extra=extra or None))
    if doc.get("storeys"):  # contract 4: several storeys, bottom up
        job.storeys = [{"id": str(st["id"]), "floor_z": float(st["floor_z"]), "ceiling_z": float(st["ceiling_z"])}
                       for st in doc["storeys"]]
    for o in doc["openings"]:
        session.add(OpeningRow(project_id=job.project_id, job_id=job.id, wall_key=o["wall"],
                               kind=o["kind"], u_min=o["u_min"], u_max=o["u_max"],
                               v_min=o["v_min"], v_max=o["v_max"]))
    for d in doc["detections"]:
        session.add(DetectionRow(
            project_id=job.project_id, job_id=job.id, ref=d["id"], class_id=d["class"],
            detected_class=d["class"], wall_key=d["wall"], position=[float(x) for x in d["position"]],
            u=float(d["u"]), v=float(d["v"]), width_m=float(d["width_m"]),
            height_m=float(d["height_m"]), alpha=d.get("alpha"), rho_depth=d.get("rho_depth"),
            rho_colour=d.get("rho_colour"), source=d["source"], status="pending", version=1,
            confidence=_float_or_none(d.get("confidence")),
            extra={k: v for k, v in d.items() if k not in DETECTION_COLUMNS} or None))
    n_sugg = import_suggestions(session, job, out_dir)
    return {"walls": len(doc["walls"]), "surfaces": len(surfaces), "openings": len(doc["openings"]),
            "detections": len(doc["detections"]), "suggestions": n_sugg}


def _float_or_none(x: object) -> float | None:
    try:
        return None if x is None else float(x)
    except (TypeError, ValueError):
        return None


def import_suggestions(session: Session, job: Job, out_dir: Path) -> int:
    """Add the possible misses of ``suggestions.json`` (when the run wrote one)."""
    path = out_dir / "suggestions.json"
    if not path.is_file():
        return 0
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        items = list(doc.get("suggestions", []))
    except (OSError, ValueError, AttributeError, TypeError):
        return 0  # suggestions are a help, never a reason to lose the results
    n = 0
    for sg in items:
        try:
            row = SuggestionRow(project_id=job.project_id, job_id=job.id, class_id=str(sg["class"]),
                                wall_key=str(sg["wall"]), u=float(sg["u"]), v=float(sg["v"]),
                                width_m=float(sg["width_m"]), height_m=float(sg["height_m"]),
                                source=str(sg.get("source", "depth"))[:20],
                                score=_float_or_none(sg.get("score")),
                                reason=str(sg.get("reason", "not_kept"))[:40])
        except (KeyError, TypeError, ValueError):
            continue
        session.add(row)
        n += 1
    return n


def wall_dict(w: WallRow) -> dict:
    """A wall of contract 4, or an entry of its ``surfaces`` (with ``kind`` and its other fields)."""
    out = {"id": w.key, "origin": w.origin, "axis_u": w.axis_u, "axis_v": w.axis_v,
           "normal": w.normal, "width_m": w.width_m, "height_m": w.height_m}
    if w.kind:
        out = {"id": w.key, "kind": w.kind, **{k: v for k, v in out.items() if k != "id"},
               **(w.extra or {})}
    if w.storey:
        out["storey"] = w.storey
    return out


def review_dict(d: DetectionRow) -> dict:
    return {"status": d.status, "by": d.reviewed_by, "at": iso(d.reviewed_at), "version": d.version}


def detection_dict(d: DetectionRow, *, id_is_ref: bool = False) -> dict:
    """One detection of contract 4 plus ``review``; ``id`` is the API's id unless ``id_is_ref``."""
    out = {**(d.extra or {}),
           "id": d.ref if id_is_ref else str(d.id), "ref": d.ref, "class": d.class_id,
           "detected_class": d.detected_class, "wall": d.wall_key, "position": d.position,
           "u": d.u, "v": d.v, "width_m": d.width_m, "height_m": d.height_m, "alpha": d.alpha,
           "rho_depth": d.rho_depth, "rho_colour": d.rho_colour, "source": d.source,
           "review": review_dict(d)}
    if d.confidence is not None:
        out["confidence"] = d.confidence
    if d.note:
        out["note"] = d.note
    if d.carried_from is not None:
        out["carried_from"] = str(d.carried_from)
    return out


def project_document(session: Session, project: Project, *, id_is_ref: bool = False) -> dict:
    """The contract-4 document of the project's current results (empty before any job)."""
    doc: dict = {"schema": "sbsc.detections/1", "project": project.id, "job": project.current_job_id,
                 "walls": [], "openings": [], "detections": []}
    jid = project.current_job_id
    if jid is None:
        return doc
    walls = session.scalars(select(WallRow).where(WallRow.job_id == jid).order_by(WallRow.key)).all()
    doc["pixel_m"] = walls[0].pixel_m if walls else DEFAULT_PIXEL_M
    job = session.get(Job, jid)
    if job is not None and job.storeys:
        doc["storeys"] = list(job.storeys)
    doc["walls"] = [wall_dict(w) for w in walls if not w.kind]
    surfaces = [wall_dict(w) for w in walls if w.kind]
    if surfaces:  # contract 4: ceilings and column faces; absent when the run looked at walls only
        doc["surfaces"] = surfaces
    doc["openings"] = [
        {"wall": o.wall_key, "kind": o.kind, "u_min": o.u_min, "u_max": o.u_max,
         "v_min": o.v_min, "v_max": o.v_max}
        for o in session.scalars(select(OpeningRow).where(OpeningRow.job_id == jid)
                                 .order_by(OpeningRow.id))]
    doc["detections"] = [detection_dict(d, id_is_ref=id_is_ref) for d in session.scalars(
        select(DetectionRow).where(DetectionRow.job_id == jid).order_by(DetectionRow.id))]
    return doc


def review_counts(session: Session, project: Project) -> dict:
    """Counts of the current results: by status, and by class for each status."""
    out: dict = {"total": 0, "pending": 0, "accepted": 0, "rejected": 0, "by_class": {}}
    if project.current_job_id is None:
        return out
    rows = session.execute(select(DetectionRow.class_id, DetectionRow.status)
                           .where(DetectionRow.job_id == project.current_job_id)).all()
    by = Counter(rows)
    for (cls, status), n in sorted(by.items()):
        out["total"] += n
        out[status] += n
        out["by_class"].setdefault(cls, {"pending": 0, "accepted": 0, "rejected": 0})[status] += n
    return out


def job_dict(job: Job) -> dict:
    return {"id": job.id, "project": job.project_id, "status": job.status, "stage": job.stage,
            "progress": round(float(job.progress), 4), "error": job.error, "retry_of": job.retry_of,
            "created_by": job.created_by, "created_at": iso(job.created_at),
            "started_at": iso(job.started_at), "finished_at": iso(job.finished_at),
            "updated_at": iso(job.updated_at), "expected": job.expected,
            **({"expected_storeys": job.expected_storeys} if job.expected_storeys else {}),
            **({"storeys": job.storeys} if job.storeys else {})}
