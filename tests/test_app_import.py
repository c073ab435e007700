"""``sbsc import``: a review project from a detect output, with its 3D scene prepared."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient

import app.viewer.lod as lod_mod
from app.auth import create_user
from app.cli import REGISTRARS
from app.config import AppSettings
from app.membership import set_member
from app.sample import find_sample_project
from app.server import create_app, start_page
from sbsc_core.cli import main
from sbsc_core.io.ply import write_ply
from sbsc_core.io.scans import read_scan

from .app_support import _fake_output


def _sbsc(*argv: str) -> int:
    return main(list(argv), registrars=list(REGISTRARS))


def test_import_makes_a_project_with_its_scene_prepared(tmp_path, monkeypatch, capsys):
    data = tmp_path / "data"
    monkeypatch.setenv("SBSC_DATA_DIR", str(data))
    out = tmp_path / "detect"
    _fake_output(out, 5, lambda s, f: None, 0.0)
    rng = np.random.default_rng(4)
    xyz = rng.random((5000, 3)) * [6.0, 4.0, 2.7] + [500_000.0, 5_400_000.0, 100.0]
    scan = tmp_path / "scan.xyz"  # a text scan: no point count in any header
    np.savetxt(scan, np.hstack([xyz, rng.integers(0, 255, (5000, 3))]), fmt="%.4f %.4f %.4f %d %d %d")
    assert _sbsc("import", str(out), "--scan", str(scan), "--name", "Floor 2") == 0
    said = capsys.readouterr().out
    assert "3D view prepared" in said and "project 1 made: Floor 2" in said
    settings = AppSettings(data_dir=data)
    pid = find_sample_project(settings, "Floor 2")
    assert pid == 1
    lods = list((settings.projects_dir / "1" / "viewer").glob("viewer_lod_*.npz"))
    assert len(lods) == 1  # the scene opens from this, never from the scan

    def no_reading(*_a, **_k):
        raise AssertionError("the first open must not read the scan")

    monkeypatch.setattr(lod_mod, "iter_scan", no_reading)
    from app.viewer.lod import scan_lod
    from app.viewer.scene import SceneSettings

    scans = list((settings.projects_dir / "1" / "scans").iterdir())
    ss = SceneSettings()
    lod = scan_lod(scans, ss.max_points, settings.projects_dir / "1" / "viewer", ss.overview_points)
    assert lod.source_points == 5000
    assert np.allclose(lod.xyz.astype(np.float64).min(axis=0) + lod.centre,
                       read_scan(scan).xyz.min(axis=0) + read_scan(scan).origin, atol=1e-3)
    # a second import under the same name keeps the project; another name makes another
    assert _sbsc("import", str(out), "--name", "Floor 2") == 0
    assert "already there" in capsys.readouterr().out
    with TestClient(create_app(settings, start_jobs=False)) as client:
        with client.app.state.db.write() as s:
            _, token = create_user(s, "rita", "reviewer")
            set_member(s, pid, "rita", "reviewer", None)  # an imported project has only the admins as members
        p = client.get(f"/api/projects/{pid}", headers={"Authorization": f"Bearer {token}"}).json()
        assert p["name"] == "Floor 2" and p["scans"][0]["points"] == 5000
        assert p["jobs"][0]["status"] == "succeeded"


def test_import_refuses_bad_input_in_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("SBSC_DATA_DIR", str(tmp_path / "data"))
    assert _sbsc("import", str(tmp_path)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "detections.json" in err[0] and str(tmp_path) in err[0]
    out = tmp_path / "detect"
    _fake_output(out, 2, lambda s, f: None, 0.0)
    assert _sbsc("import", str(out), "--scan", str(tmp_path / "nope.ply")) == 2
    assert "nope.ply" in capsys.readouterr().err
    assert not (tmp_path / "data" / "projects").exists() or not any((tmp_path / "data" / "projects").iterdir())


def test_sample_name_is_the_start_page(tmp_path, monkeypatch):
    monkeypatch.setenv("SBSC_DATA_DIR", str(tmp_path / "data"))
    out = tmp_path / "detect"
    _fake_output(out, 2, lambda s, f: None, 0.0)
    scan = tmp_path / "scan.ply"
    write_ply(scan, np.random.default_rng(5).random((300, 3)), np.zeros((300, 3), np.uint8))
    assert _sbsc("import", str(out), "--scan", str(scan), "--name", "Sample: Scenario I") == 0
    assert start_page(AppSettings(data_dir=tmp_path / "data")) == "/review.html?id=1"
