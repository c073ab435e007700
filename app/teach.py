"""Teach and search again (issue 28): classes a project creates, their examples, the learnt library.

- A project's **own classes** (created by a reviewer before any model of them exists) are kept
  in ``<data>/projects/<pid>/classes.json``: class id -> ``{name, ifc_class, predefined_type?,
  mount?}``, the ``CLASSES.json`` of ``sbsc learn``. They are written under the project's lock,
  atomically.
- An **example** of such a class is an object added on a wall (``POST .../detections``): it has
  no model yet, so its size is the relief blob under the click, and it is placed at the blob's
  centre (:func:`sbsc_core.recognition.learning.examples.relief_blob`).
- **Learning** is the library's :func:`sbsc_core.recognition.learning.library.learn_library` over the
  current job's detect output and the project's library, with the reviewed document of the
  accepted objects a person added or relabelled (found objects that were only accepted teach
  nothing new, and would mix the old design into a new one's medians).
- **Removing** what was learnt for a class (its hits are rejected) writes the project's library
  without it (:func:`sbsc_core.recognition.learning.forget.forget_learnt`) and puts the class in
  ``<data>/projects/<pid>/unlearnt.json``: learning skips its examples until it is re-taught.
  The pending suggestions it brought go (:func:`brought_by`).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import uuid
from pathlib import Path

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from .models import DetectionRow, Job, Project, WallRow

CLASSES_FILE = "classes.json"
UNLEARNT_FILE = "unlearnt.json"
SPEC_KEYS = ("name", "ifc_class", "predefined_type", "mount")


def classes_path(data_dir: Path, pid: int) -> Path:
    return Path(data_dir) / "projects" / str(pid) / CLASSES_FILE


def project_classes(data_dir: Path, pid: int) -> dict[str, dict]:
    """The classes created for project ``pid``: class id -> {name, ifc_class, predefined_type?, mount?}."""
    path = classes_path(data_dir, pid)
    if not path.is_file():
        return {}
    try:  # written atomically by save_project_classes; a file edited by hand may be broken
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def save_project_classes(data_dir: Path, pid: int, classes: dict[str, dict]) -> None:
    """Write the project's classes atomically (a temporary file renamed over the old one)."""
    path = classes_path(data_dir, pid)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".classes-", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(classes, fh, indent=2, sort_keys=True)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def unlearnt(data_dir: Path, pid: int) -> set[str]:
    """The classes whose learnt models were removed (learning skips their examples until re-taught)."""
    path = Path(data_dir) / "projects" / str(pid) / UNLEARNT_FILE
    try:
        doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else []
    except (OSError, ValueError):
        return set()
    return {c for c in doc if isinstance(c, str)} if isinstance(doc, list) else set()


def save_unlearnt(data_dir: Path, pid: int, classes: set[str]) -> None:
    """Write the removed classes atomically."""
    from sbsc_core.io.atomic import write_json_atomic

    write_json_atomic(Path(data_dir) / "projects" / str(pid) / UNLEARNT_FILE, sorted(classes))


def taught_class_fields(spec: dict) -> dict:
    """A created class as the app lists library classes (no size until it is learnt)."""
    return {"name": spec.get("name"), "ifc_class": spec.get("ifc_class"),
            "predefined_type": spec.get("predefined_type"), "width_m": None, "height_m": None,
            "mount": list(spec.get("mount") or []), "taught": True}


def measure(wall: WallRow, data_dir: Path, u: float, v: float) -> tuple[float, float, float, float] | None:
    """(u, v, width_m, height_m) of the relief blob under a click on ``wall``; None without one."""
    from sbsc_core.recognition.learning.examples import relief_blob

    meta = (wall.images or {}).get("depth")
    if not meta:
        return None
    try:
        depth = np.load(Path(data_dir) / meta["path"], allow_pickle=False)
    except (OSError, ValueError):
        return None
    return relief_blob(depth, wall.height_m, wall.pixel_m, u, v)


def _by_person(d: DetectionRow) -> bool:
    return d.source == "reviewer" or d.class_id != d.detected_class


def examples(s: Session, job_id: int, skip: set[str] | frozenset = frozenset()) -> list[DetectionRow]:
    """The current results' examples: accepted objects a person added or relabelled, also once
    a later run found them and took the decision over (``carried_from``); not of the classes
    in ``skip``."""
    rows = s.scalars(select(DetectionRow).where(DetectionRow.job_id == job_id,
                                                DetectionRow.status == "accepted").order_by(DetectionRow.id))
    out = []
    for d in rows:
        if d.class_id in skip:
            continue
        origin, hops = d, 0
        while not _by_person(origin) and origin.carried_from is not None and hops < 100:
            origin, hops = s.get(DetectionRow, origin.carried_from), hops + 1
            if origin is None:
                break
        if origin is not None and _by_person(origin) and origin.class_id == d.class_id:
            out.append(d)
    return out


def reviewed_document(rows: list[DetectionRow]) -> dict:
    """The examples as the reviewed document of ``sbsc learn`` (contract 4), each on its wall at (u, v)."""
    dets = []
    for d in rows:
        obj = {"id": d.ref, "class": d.class_id, "wall": d.wall_key, "u": d.u, "v": d.v,
               "position": list(d.position), "review": {"status": "accepted"}}
        rot = (d.extra or {}).get("rotation_deg")
        if rot is not None:
            obj["rotation_deg"] = rot
        if d.width_m and d.height_m:
            obj["width_m"], obj["height_m"] = d.width_m, d.height_m
        dets.append(obj)
    return {"schema": "sbsc.detections/1", "detections": dets}


def learnt_library_path(pid: int) -> Path:
    """A new folder for a learnt library of project ``pid``, relative to the data folder."""
    return Path("projects", str(pid), "models", f"learnt_{uuid.uuid4().hex[:12]}")


def learn(s: Session, project: Project, data_dir: Path, source_library: Path,
          reteach: frozenset[str] = frozenset()) -> tuple[Path, list]:
    """Learn a library from ``project``'s examples into a new folder under its ``models/``.

    The examples of removed classes (:func:`unlearnt`) are skipped unless ``reteach`` names
    them; what was learnt for the classes in ``reteach`` is dropped from ``source_library``
    first, so they are taught afresh from their current examples.

    Returns (folder relative to ``data_dir``, the ``Taught`` list of ``learn_library``).
    Raises :class:`sbsc_core.errors.InputError` (naming an example that cannot be used) or
    ``LookupError`` when there is nothing to learn from.
    """
    from sbsc_core.io.models import load_model_library
    from sbsc_core.recognition.learning.forget import forget_learnt, learnt_part
    from sbsc_core.recognition.learning.library import learn_library

    job = s.get(Job, project.current_job_id)
    if job is None or not job.out_dir or not (Path(data_dir) / job.out_dir / "detections.json").is_file():
        raise LookupError(f"project {project.id}'s current results have no detect output to learn from")
    rows = examples(s, job.id, unlearnt(data_dir, project.id) - set(reteach))
    if not rows:
        raise LookupError(f"project {project.id} has no accepted object that a person added or "
                          "relabelled to learn from")
    missing = sorted(set(reteach) - {d.class_id for d in rows})
    if missing:
        raise LookupError(f"no accepted example of class '{missing[0]}' to re-teach it from "
                          "(add and confirm one or more first)")
    rel = learnt_library_path(project.id)
    work = Path(data_dir) / "projects" / str(project.id) / "teach" / uuid.uuid4().hex[:12]
    work.mkdir(parents=True)
    try:
        drop = [c for c in sorted(reteach) if (source_library / c).is_dir() and learnt_part(source_library / c)]
        if drop:  # re-taught: from the library without what was learnt for them
            forget_learnt(source_library, work / "models", drop)
            source_library = work / "models"
        known = set(load_model_library(source_library).class_ids)
        present = {d.class_id for d in rows}
        specs = {cid: {k: v for k, v in spec.items() if k in SPEC_KEYS and v}
                 for cid, spec in project_classes(data_dir, project.id).items()
                 if cid in present and cid not in known}
        (work / "reviewed.json").write_text(json.dumps(reviewed_document(rows)), encoding="utf-8")
        classes = None
        if specs:
            classes = work / "classes.json"
            classes.write_text(json.dumps(specs), encoding="utf-8")
        (Path(data_dir) / rel).parent.mkdir(parents=True, exist_ok=True)
        taught = learn_library(Path(data_dir) / job.out_dir, work / "reviewed.json", source_library,
                               Path(data_dir) / rel, classes=classes)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rel, taught


def forget(project: Project, data_dir: Path, library: Path, class_id: str) -> tuple[Path, str]:
    """Write the project's library ``library`` without what was learnt for ``class_id`` into a
    new folder under its ``models/``. Returns (folder relative to ``data_dir``, ``"class"`` or
    ``"designs"``); :class:`sbsc_core.errors.InputError` when the class has nothing learnt."""
    from sbsc_core.recognition.learning.forget import forget_learnt

    rel = learnt_library_path(project.id)
    part = forget_learnt(library, Path(data_dir) / rel, [class_id])[class_id]
    return rel, part


def brought_by(s: Session, project: Project, data_dir: Path, class_id: str, part: str) -> list[DetectionRow]:
    """The current results' pending suggestions that what was learnt for ``class_id`` brought,
    and that nobody has touched (no review decision).

    A learnt class brought all of its hits; learnt designs of a known class the hits of that
    class that no earlier run without them found (within the carry-over tolerance).
    """
    from sbsc_core.recognition.learning.forget import learnt_design_files

    from .libraries import models_dir
    from .models import ReviewDecision
    from .review_rules import CARRY_TOLERANCE_M

    if project.current_job_id is None:
        return []
    rows = list(s.scalars(select(DetectionRow).where(
        DetectionRow.job_id == project.current_job_id, DetectionRow.status == "pending",
        DetectionRow.source != "reviewer", DetectionRow.detected_class == class_id,
        DetectionRow.class_id == class_id).order_by(DetectionRow.id)))
    touched = set(s.scalars(select(ReviewDecision.detection_id).where(
        ReviewDecision.detection_id.in_([d.id for d in rows])))) if rows else set()
    rows = [d for d in rows if d.id not in touched]
    if part != "designs" or not rows:
        return rows
    seen: list[np.ndarray] = []
    for j in s.scalars(select(Job).where(Job.project_id == project.id, Job.id != project.current_job_id,
                                         Job.status == "succeeded")):
        cdir = models_dir(s, j.models_id, Path(data_dir)) / class_id
        if cdir.is_dir() and not learnt_design_files(cdir):
            seen += [np.asarray(d.position, float) for d in s.scalars(select(DetectionRow).where(
                DetectionRow.job_id == j.id, DetectionRow.detected_class == class_id))]
    if not seen:
        return rows
    at = np.asarray(seen)
    return [d for d in rows if float(np.min(np.linalg.norm(at - np.asarray(d.position, float), axis=1)))
            > max(CARRY_TOLERANCE_M, 0.5 * max(d.width_m, d.height_m))]
