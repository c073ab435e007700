"""The review app's parts in-process: schema migrations, audit trail, tokens, jobs, thumbnails, zips."""

from __future__ import annotations

import io
import json
import sqlite3
import stat
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from fastapi.testclient import TestClient
from sqlalchemy import inspect, select

from app.auth import authenticate, create_user, hash_token
from app.config import AppSettings
from app.db import Database, alembic_config, upgrade
from app.job_processes import describe_exit
from app.job_progress import STAGE_SPANS, overall_progress
from app.jobs import JobManager, parse_expected
from app.membership import set_member
from app.models import Base, DetectionRow, Job, Project, ReviewDecision
from app.sample import ensure_sample_project, find_sample_project
from app.server import create_app, first_run
from app.storage import UploadRefused, check_zip, safe_filename
from app.thumbnails import ImageCache, thumbnail
from app.users import add_user_cli
from sbsc_core.errors import InputError
from sbsc_core.stages import Stage

from .app_support import _fake_output, write_small_ply


@pytest.fixture()
def db(tmp_path):
    d = Database(f"sqlite:///{tmp_path / 't.db'}")
    upgrade(d)
    yield d
    d.dispose()


def test_migrations_build_exactly_the_models_schema_and_go_back(db):
    with db.engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
    upgrade(db)  # idempotent
    cfg = alembic_config(db.url)
    with db.engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.downgrade(cfg, "base")
    assert set(inspect(db.engine).get_table_names()) == {"alembic_version"}
    upgrade(db)
    assert "review_decisions" in inspect(db.engine).get_table_names()


def test_audit_trail_is_append_only_in_orm_and_database(db, tmp_path):
    with db.write() as s:
        p = Project(name="p")
        s.add(p)
        s.flush()
        j = Job(project_id=p.id, status="succeeded")
        s.add(j)
        s.flush()
        d = DetectionRow(project_id=p.id, job_id=j.id, ref="D1", class_id="switch", detected_class="switch",
                         wall_key="W1", position=[0, 0, 0], u=1, v=1, width_m=0.1, height_m=0.1,
                         source="both")
        s.add(d)
        s.flush()
        s.add(ReviewDecision(detection_id=d.id, project_id=p.id, user_name="a", action="accept",
                             version_from=1, version_to=2, before={}, after={}))
    with pytest.raises(PermissionError), db.write() as s:
        row = s.scalars(select(ReviewDecision)).one()
        row.user_name = "mallory"
        s.flush()
    with pytest.raises(PermissionError), db.write() as s:
        s.delete(s.scalars(select(ReviewDecision)).one())
        s.flush()
    with sqlite3.connect(tmp_path / "t.db") as con, pytest.raises(sqlite3.DatabaseError, match="append-only"):
        con.execute("UPDATE review_decisions SET action = 'reject'")
    with db.read() as s:
        assert s.scalars(select(ReviewDecision.user_name)).all() == ["a"]


def test_tokens_are_hashed_and_roles_ordered(db):
    with db.write() as s:
        user, token = create_user(s, "rita", "reviewer")
        assert user.token_hash == hash_token(token) and token not in user.token_hash
        with pytest.raises(ValueError, match="already exists"):
            create_user(s, "rita", "manager")
        with pytest.raises(ValueError, match="role"):
            create_user(s, "bob", "boss")
        with pytest.raises(ValueError, match="name"):
            create_user(s, "../x", "reviewer")
    with db.read() as s:
        who = authenticate(s, token)
        assert who.name == "rita" and who.may("reviewer") and not who.may("manager")
        assert authenticate(s, token + "x") is None and authenticate(s, "garbage") is None


def test_user_add_cli_and_first_run(tmp_path, monkeypatch):
    monkeypatch.setenv("SBSC_DATA_DIR", str(tmp_path / "d"))
    settings = AppSettings()
    assert settings.data_dir == tmp_path / "d"
    token = first_run(settings)
    assert token and first_run(settings) is None  # only once
    text = add_user_cli("max", "manager")
    new = text.strip().splitlines()[-1]
    assert "role manager" in text and new.startswith("sbsc_")
    with pytest.raises(InputError, match="already exists"):
        add_user_cli("max", "reviewer")
    d = Database(settings.db_url)
    with d.read() as s:
        assert authenticate(s, new).role == "manager" and authenticate(s, token).name == "admin"
    d.dispose()


def test_default_data_dir_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("SBSC_DATA_DIR", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    s = AppSettings()
    assert s.data_dir == tmp_path / "xdg" / "sbsc"
    assert s.db_url == f"sqlite:///{(tmp_path / 'xdg' / 'sbsc' / 'sbsc.db').as_posix()}"
    monkeypatch.setenv("SBSC_DATABASE_URL", "postgresql+psycopg://u@h/sbsc")
    assert AppSettings().db_url == "postgresql+psycopg://u@h/sbsc"


def test_expected_counts_progress_and_exit_reasons():
    assert parse_expected({"socket_x1": 3}) == {"socket_x1": 3}
    assert parse_expected({"schema": "sbsc.expected/1", "counts": {"switch": 0}}) == {"switch": 0}
    assert parse_expected(None) is None
    for bad in ({"Socket": 1}, {"switch": 1.5}, {"switch": True}, {"switch": -2}, [1]):
        with pytest.raises(InputError):
            parse_expected(bad)
    p = 0.0
    seen = []
    for stage, f in [("reading", 0), ("segmentation", 0), ("walls", 0.5), ("walls", 0.9),
                     ("unknown", 0.1), ("ceilings", 0.5), ("columns", 0.5), ("consensus", 1), ("writing", 0),
                     ("done", 1), ("importing", 0)]:
        p = overall_progress(stage, f, p)
        seen.append(p)
    assert seen == sorted(seen) and 0 < seen[0] < seen[-1] < 1
    assert seen[5] > seen[3] and seen[6] > seen[5]  # ceilings and columns move the bar on
    # every stage the pipeline reports has its span, in running order
    spans = [STAGE_SPANS[stage] for stage in Stage]
    assert all(a[1] == pytest.approx(b[0]) for a, b in zip(spans, spans[1:], strict=False))
    assert "SIGKILL" in describe_exit(-9) and "code 3" in describe_exit(3)


def test_recover_fails_jobs_of_a_dead_server(tmp_path, db):
    with db.write() as s:
        p = Project(name="p")
        s.add(p)
        s.flush()
        s.add_all([Job(project_id=p.id, status="running", stage="walls", owner="old"),
                   Job(project_id=p.id, status="queued"), Job(project_id=p.id, status="succeeded")])
    mgr = JobManager(AppSettings(data_dir=tmp_path), db)
    assert mgr.recover() == 1
    with db.read() as s:
        jobs = s.scalars(select(Job).order_by(Job.id)).all()
        assert [j.status for j in jobs] == ["failed", "queued", "succeeded"]
        assert jobs[0].error == "server restarted while the job was running (stage 'walls')"


def test_thumbnail_is_centred_on_the_footprint(tmp_path):
    px, H, W = 0.005, 200, 300  # a 1.5 x 1.0 m wall
    img = np.full((H, W, 3), 200, np.uint8)
    img[80:96, 150:166] = (0, 0, 255)  # red (BGR) object, 16 px = 8 cm
    cv2.imwrite(str(tmp_path / "c.png"), img)
    u, v = (158 + 0.0) * px, 1.0 - (88 + 0.0) * px  # centre between pixels 157/158 and 87/88
    png = thumbnail(ImageCache(), tmp_path / "c.png", "colour", wall_height_m=1.0, pixel_m=px, u=u, v=v,
                    width_m=0.08, height_m=0.08, size_px=160, context=2.5, min_side_m=0.2)
    th = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert th.shape == (160, 160, 3)
    assert tuple(th[80, 80]) == (0, 0, 255)  # the object in the middle
    assert tuple(th[5, 5]) == (200, 200, 200)  # wall around it
    # at the wall's corner the crop is padded, not failed
    depth = np.zeros((H, W), np.float32)
    depth[:10] = np.nan
    np.save(tmp_path / "d.npy", depth)
    png = thumbnail(ImageCache(), tmp_path / "d.npy", "depth", wall_height_m=1.0, pixel_m=px, u=0.0, v=1.0,
                    width_m=0.08, height_m=0.08, size_px=64, context=2.5, min_side_m=0.2)
    assert cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR).shape == (64, 64, 3)


def test_zip_checks_refuse_bombs_links_and_escapes(tmp_path):
    caps = dict(max_entries=10, max_entry_bytes=50 << 20, max_total_bytes=60 << 20, max_ratio=100.0)

    def make(name: str, entries: list[tuple[zipfile.ZipInfo | str, bytes]]) -> Path:
        p = tmp_path / name
        with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as zf:
            for info, data in entries:
                zf.writestr(info, data)
        return p

    check_zip(make("ok.zip", [("m/a/model.json", b"{}")]), "ok.zip", **caps)
    with pytest.raises(UploadRefused, match="ratio"):
        check_zip(make("bomb.zip", [("m/a/depth.npy", b"\0" * (20 << 20))]), "bomb.zip", **caps)
    link = zipfile.ZipInfo("m/a/colour.png")
    link.external_attr = (stat.S_IFLNK | 0o777) << 16
    with pytest.raises(UploadRefused, match="symbolic"):
        check_zip(make("link.zip", [(link, b"/etc/passwd")]), "link.zip", **caps)
    with pytest.raises(UploadRefused, match="leaves"):
        check_zip(make("esc.zip", [("m/../../x", b"x")]), "esc.zip", **caps)
    with pytest.raises(UploadRefused, match="too many"):
        check_zip(make("many.zip", [(f"m/{i}", b"x") for i in range(11)]), "many.zip", **caps)
    assert safe_filename("../../etc/passwd") == "passwd"
    assert safe_filename("C:\\scans\\my scan (1).ply") == "my_scan__1_.ply"
    assert safe_filename("..") == "upload"


def test_sample_project_from_a_finished_run(tmp_path):
    settings = AppSettings(data_dir=tmp_path / "d")
    out = tmp_path / "out"
    _fake_output(out, 5, lambda s, f: None, 0.0)
    scan = write_small_ply(tmp_path / "scan.ply", n=321)
    with pytest.raises(InputError, match="detections.json"):
        ensure_sample_project(scan, tmp_path, settings=settings)
    pid = ensure_sample_project(scan, out, settings=settings)
    assert ensure_sample_project(scan, out, settings=settings) == pid == find_sample_project(settings)
    token = None
    with TestClient(create_app(settings, start_jobs=False)) as client:
        d = client.app.state.db
        with d.write() as s:
            _, token = create_user(s, "rita", "reviewer")
            set_member(s, pid, "rita", "reviewer", None)  # projects belong to their members
        h = {"Authorization": f"Bearer {token}"}
        p = client.get(f"/api/projects/{pid}", headers=h).json()
        assert p["scans"][0]["points"] == 321 and p["jobs"][0]["status"] == "succeeded"
        doc = client.get(f"/api/projects/{pid}/detections", headers=h).json()
        assert len(doc["detections"]) == 5
        assert json.loads((out / "detections.json").read_text())["detections"][0]["id"] == doc["detections"][0]["ref"]
        r = client.get(f"/api/detections/{doc['detections'][0]['id']}/thumbnail/colour", headers=h)
        assert r.status_code == 200 and io.BytesIO(r.content).read(4) == b"\x89PNG"
        assert client.get("/").status_code == 200  # the pages are served
        assert b"Detections" in client.get("/review.html").content
    # files that a crash left without a row are removed at the next start; the rest stays
    pdir = settings.projects_dir / str(pid)
    stray = [pdir / "scans" / "dead_scan.ply", pdir / "jobs" / "999" / "out" / "x.json",
             pdir / "models" / "abc" / "m" / "model.json"]
    for p in stray:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("{}")
    kept = sorted(q for q in pdir.rglob("*") if q.is_file() and q not in stray)
    with TestClient(create_app(settings, start_jobs=False)):
        pass
    assert not any(p.exists() for p in stray)
    assert sorted(q for q in pdir.rglob("*") if q.is_file()) == kept and len(kept) > 5
