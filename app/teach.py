"""Teach and search again (issue 28): classes a project creates, their examples, the learnt library.

- A project's **own classes** (created by a reviewer before any model of them exists) are kept
  in ``<data>/projects/<pid>/classes.json``: class id -> ``{name, ifc_class, predefined_type?,
  mount?}``, the ``CLASSES.json`` of ``sbsc learn``. They are written under the project's lock,
  atomically.
- An **example** of such a class is an object added on a wall (``POST .../detections``): it has
  no model yet, so its size is the relief blob under the click, and it is placed at the blob's
  centre (:func:`sbsc_core.learning.examples.relief_blob`).
- **Learning** is the library's :func:`sbsc_core.learning.library.learn_library` over the
  current job's detect output, with the reviewed document of the accepted objects a person
  added or relabelled (found objects that were only accepted teach nothing new, and would mix
  the old design into a new one's medians).
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


def taught_class_fields(spec: dict) -> dict:
    """A created class as the app lists library classes (no size until it is learnt)."""
    return {"name": spec.get("name"), "ifc_class": spec.get("ifc_class"),
            "predefined_type": spec.get("predefined_type"), "width_m": None, "height_m": None,
            "mount": list(spec.get("mount") or []), "taught": True}


def measure(wall: WallRow, data_dir: Path, u: float, v: float) -> tuple[float, float, float, float] | None:
    """(u, v, width_m, height_m) of the relief blob under a click on ``wall``; None without one."""
    from sbsc_core.learning.examples import relief_blob

    meta = (wall.images or {}).get("depth")
    if not meta:
        return None
    try:
        depth = np.load(Path(data_dir) / meta["path"], allow_pickle=False)
    except (OSError, ValueError):
        return None
    return relief_blob(depth, wall.height_m, wall.pixel_m, u, v)


def examples(s: Session, job_id: int) -> list[DetectionRow]:
    """The current results' examples: accepted objects a person added or relabelled."""
    rows = s.scalars(select(DetectionRow).where(DetectionRow.job_id == job_id,
                                                DetectionRow.status == "accepted").order_by(DetectionRow.id))
    return [d for d in rows if d.source == "reviewer" or d.class_id != d.detected_class]


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


def learn(s: Session, project: Project, data_dir: Path, source_library: Path) -> tuple[Path, list]:
    """Learn a library from ``project``'s examples into a new folder under its ``models/``.

    Returns (folder relative to ``data_dir``, the ``Taught`` list of ``learn_library``).
    Raises :class:`sbsc_core.errors.InputError` (naming an example that cannot be used) or
    ``LookupError`` when there is nothing to learn from.
    """
    from sbsc_core.io.models import load_model_library
    from sbsc_core.learning.library import learn_library

    job = s.get(Job, project.current_job_id)
    if job is None or not job.out_dir or not (Path(data_dir) / job.out_dir / "detections.json").is_file():
        raise LookupError(f"project {project.id}'s current results have no detect output to learn from")
    rows = examples(s, job.id)
    if not rows:
        raise LookupError(f"project {project.id} has no accepted object that a person added or "
                          "relabelled to learn from")
    known = set(load_model_library(source_library).class_ids)
    present = {d.class_id for d in rows}
    specs = {cid: {k: v for k, v in spec.items() if k in SPEC_KEYS and v}
             for cid, spec in project_classes(data_dir, project.id).items()
             if cid in present and cid not in known}
    rel = Path("projects", str(project.id), "models", f"learnt_{uuid.uuid4().hex[:12]}")
    work = Path(data_dir) / "projects" / str(project.id) / "teach" / uuid.uuid4().hex[:12]
    work.mkdir(parents=True)
    try:
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
