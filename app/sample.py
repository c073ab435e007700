"""Review projects made from a finished ``sbsc detect`` run, so ``sbsc serve`` opens on results.

``import_detect_output(detections_dir, scans=...)`` (``sbsc import``) copies the scans and the
output directory into the data dir and records them as a project with one succeeded job,
without running detection again, then prepares the 3D scene's level of detail (as a job
does when it ends) so the scene's first open reads no scan. It is idempotent: a project of
that name with results is reused. ``ensure_sample_project(scan, detections_dir)`` is the
same for one scan, under the sample's name by default.

    python -m app.sample SCAN DETECTIONS_DIR [--models DIR] [--name NAME]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import sys
import uuid
from collections.abc import Callable
from pathlib import Path

from sqlalchemy import select

from sbsc_core.errors import InputError, SbscError

from .config import AppSettings
from .db import Database, upgrade
from .job_worker import _prepare_viewer, job_dir
from .models import DesignRow, Job, ModelLibraryRow, Project, Scan, utcnow
from .results import import_results
from .storage import sha256_file

SAMPLE_NAME = "Sample: Scenario I"


def _link_or_copy(src: Path, dest: Path) -> None:
    dest.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dest)
    except OSError:
        shutil.copy2(src, dest)


def find_sample_project(settings: AppSettings, name: str = SAMPLE_NAME) -> int | None:
    """The id of the project called ``name`` that has results, if any."""
    db = Database(settings.db_url)
    try:
        upgrade(db)
        with db.read() as s:
            return s.scalar(select(Project.id).where(Project.name == name,
                                                     Project.current_job_id.is_not(None))
                            .order_by(Project.id).limit(1))
    finally:
        db.dispose()


def ensure_sample_project(scan: Path, detections_dir: Path, *, models: Path | None = None,
                          name: str = SAMPLE_NAME, settings: AppSettings | None = None,
                          points: int | None = None, design: Path | None = None) -> int:
    """Create (once) a project from ``scan`` and a finished output dir; returns its id.

    See :func:`import_detect_output`; ``points`` saves counting the scan's points.
    """
    scan = Path(scan)
    if not scan.is_file():
        raise InputError(scan, "no such scan file")
    return import_detect_output(detections_dir, scans=[scan], models=models, name=name,
                                settings=settings, points=points, design=design)[0]


def import_detect_output(detections_dir: Path, *, scans: list[Path] | tuple[Path, ...] = (),
                         models: Path | None = None, name: str = SAMPLE_NAME,
                         settings: AppSettings | None = None, points: int | None = None,
                         design: Path | None = None,
                         say: Callable[[str], None] = lambda _m: None) -> tuple[int, bool]:
    """Create (once) a review project from a finished output dir; returns (its id, made now).

    ``detections_dir`` holds ``detections.json`` and ``orthoimages/`` as written by
    ``sbsc detect``; ``scans`` the scan files it was run on (none: the project has no scan,
    its 3D scene no point cloud); ``models`` is the library it was run with (default: the
    bundled one). ``points`` (one scan) saves counting its points. ``design`` is the
    as-designed IFC to compare with; by default the simulator's ``as_designed.ifc`` beside
    the first scan, if any. A project of that name with results is returned as it is.
    """
    settings = settings or AppSettings()
    scans = [Path(p) for p in scans]
    detections_dir = Path(detections_dir)
    for scan in scans:
        if not scan.is_file():
            raise InputError(scan, "no such scan file")
    if not (detections_dir / "detections.json").is_file():
        raise InputError(detections_dir, "no detections.json here (run sbsc detect first)")
    existing = find_sample_project(settings, name)
    if existing is not None:
        return existing, False
    if design is None and scans:
        design = scans[0].parent / "as_designed.ifc"
    designed = None
    if design is not None and Path(design).is_file():
        from sbsc_core.bim.design import read_as_designed
        from sbsc_core.io.models import load_model_library
        from sbsc_core.paths import bundled_models_dir

        designed = read_as_designed(design, load_model_library(models or bundled_models_dir()))
    library_classes = None
    if models is not None:
        from sbsc_core.io.models import load_model_library

        from .storage import library_summary

        library_classes = library_summary(load_model_library(models))
    from sbsc_core.io.scans import scan_point_count

    counts = [points if points is not None and len(scans) == 1 else scan_point_count(p) for p in scans]
    settings.ensure_dirs()
    db = Database(settings.db_url)
    created: list[Path] = []
    copies: list[Path] = []
    try:
        with db.write() as s:
            project = Project(name=name, status="open", created_by="sample")
            s.add(project)
            s.flush()
            pdir = settings.projects_dir / str(project.id)
            created.append(pdir)
            for scan, count in zip(scans, counts, strict=True):
                scan_dest = pdir / "scans" / f"{uuid.uuid4().hex[:12]}_{scan.name}"
                _link_or_copy(scan, scan_dest)
                copies.append(scan_dest)
                s.add(Scan(project_id=project.id, filename=scan.name,
                           path=scan_dest.relative_to(settings.data_dir).as_posix(),
                           size_bytes=scan.stat().st_size, sha256=sha256_file(scan), points=int(count or 0),
                           uploaded_by="sample"))
            models_id = None
            if models is not None:
                lib_dest = pdir / "models" / uuid.uuid4().hex[:12]
                shutil.copytree(models, lib_dest)
                row = ModelLibraryRow(project_id=project.id, filename=Path(models).name,
                                      path=lib_dest.relative_to(settings.data_dir).as_posix(),
                                      size_bytes=0, sha256="", classes=library_classes,
                                      uploaded_by="sample")
                s.add(row)
                s.flush()
                models_id = project.models_id = row.id
            if designed is not None:
                design = Path(design)
                design_dest = pdir / "design" / f"{uuid.uuid4().hex[:12]}_{design.name}"
                _link_or_copy(design, design_dest)
                s.add(DesignRow(project_id=project.id, filename=design.name,
                                path=design_dest.relative_to(settings.data_dir).as_posix(),
                                size_bytes=design.stat().st_size, sha256=sha256_file(design),
                                objects=len(designed.objects), expected_counts=designed.expected_counts(),
                                uploaded_by="sample"))
            now = utcnow()
            job = Job(project_id=project.id, status="succeeded", stage="imported", progress=1.0,
                      models_id=models_id, created_by="sample", created_at=now, started_at=now,
                      finished_at=now, updated_at=now)
            s.add(job)
            s.flush()
            out = job_dir(settings, project.id, job.id) / "out"
            shutil.copytree(detections_dir, out)
            job.out_dir = out.relative_to(settings.data_dir).as_posix()
            import_results(s, job, out, settings.data_dir)
            s.flush()
            project.current_job_id = job.id
            pid = project.id
    except BaseException:
        for p in created:
            shutil.rmtree(p, ignore_errors=True)
        raise
    finally:
        db.dispose()
    if copies:  # the 3D scene's level of detail, read from the scans in chunks, as a job's end does
        lod = _prepare_viewer(settings, pid, copies, say)
        if lod is not None and None in counts and len(copies) == 1:
            _set_points(settings, pid, lod.source_points)
    return pid, True


def _set_points(settings: AppSettings, pid: int, points: int) -> None:
    """Record the point count of a project's only scan (a text file has none in its header)."""
    db = Database(settings.db_url)
    try:
        with db.write() as s:
            for row in s.scalars(select(Scan).where(Scan.project_id == pid)):
                row.points = int(points)
    finally:
        db.dispose()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m app.sample", description=__doc__.splitlines()[0])
    ap.add_argument("scan")
    ap.add_argument("detections_dir")
    ap.add_argument("--models")
    ap.add_argument("--name", default=SAMPLE_NAME)
    ap.add_argument("--design", help="as-designed IFC (default: as_designed.ifc beside the scan, if any)")
    args = ap.parse_args(argv)
    try:
        pid = ensure_sample_project(Path(args.scan), Path(args.detections_dir),
                                    models=Path(args.models) if args.models else None, name=args.name,
                                    design=Path(args.design) if args.design else None)
    except SbscError as exc:
        print(f"sbsc: error: {exc}", file=sys.stderr)
        return 2
    print(f"sample project {pid}: {args.name}")
    return 0


if __name__ == "__main__":
    with contextlib.suppress(KeyboardInterrupt):
        sys.exit(main())
