"""Fixtures shared by several test modules.

``browser``: Debian's Chromium driven by Playwright (one per module; a module's ``BROWSER_ARGS``
adds flags, e.g. software WebGL). ``site``: a server with a sample project for the page tests.
``teach_srv``: the server of the teach-and-search-again tests.
"""

from __future__ import annotations

import json

import httpx
import pytest

from app.config import AppSettings
from app.sample import ensure_sample_project
from app.users import add_user
from sbsc_core.bim.design_writer import write_as_designed_ifc

from .app_support import ServerProcess, _fake_output, auth, join, server_with_users, write_small_ply
from .bim_fixtures import truth_document
from .browser_support import CHROMIUM_ARGS, LONG_CLASSES, SHOTS, chromium_path
from .teach_support import RUNNER as TEACH_RUNNER


@pytest.fixture(scope="module")
def browser(request):
    """Headless Chromium; skipped when neither chromium nor playwright can be had."""
    exe = chromium_path()
    if exe is None:
        pytest.skip("Debian chromium is not installed and apt-get could not install it")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("the playwright package is missing (pip install playwright; no 'playwright install' needed)")
    extra = list(getattr(request.module, "BROWSER_ARGS", []))
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS + extra, headless=True)
        yield b
        b.close()


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A server with a sample project (results with long class names, the simulator's
    as_designed.ifc beside its scan) and an empty project without a design."""
    base = tmp_path_factory.mktemp("pages")
    data = base / "data"
    settings = AppSettings(data_dir=data, viewer=False)
    out = base / "out"
    _fake_output(out, 8, lambda stage, f: None, 0.0)
    doc = json.loads((out / "detections.json").read_text())
    for i, d in enumerate(doc["detections"]):
        d["class"] = LONG_CLASSES[i % len(LONG_CLASSES)]
    doc["detections"][1]["rho_colour"] = None
    doc["detections"][1]["source"] = "depth"
    (out / "detections.json").write_text(json.dumps(doc))
    sim = base / "sim"
    sim.mkdir()
    write_as_designed_ifc(truth_document(), sim / "as_designed.ifc", seed=0, n_moved=1, n_removed=1, n_added=1)
    pid = ensure_sample_project(write_small_ply(sim / "scan.ply", n=200), out, settings=settings, points=200)
    token = add_user(settings, "max", "manager")
    join(settings, pid, "max", "manager")
    server = ServerProcess(data, {"SBSC_VIEWER": "false"}).start()
    with httpx.Client(base_url=server.url, timeout=30) as c:
        empty = c.post("/api/projects", json={"name": "Empty"}, headers=auth(token)).json()["id"]
    server.token, server.pid, server.empty = token, pid, empty
    SHOTS.mkdir(parents=True, exist_ok=True)
    yield server
    server.stop()


@pytest.fixture(scope="module")
def teach_srv(tmp_path_factory):
    """A server whose jobs run the teach scene's fake runner; four users of every role."""
    server = server_with_users(tmp_path_factory.mktemp("teach"),
                               [("rita", "reviewer"), ("max", "manager"), ("ada", "admin"), ("olga", "reviewer")],
                               {"SBSC_JOB_RUNNER": TEACH_RUNNER, "SBSC_VIEWER": "0"})
    yield server
    server.stop()
