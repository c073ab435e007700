"""Ceilings and columns in headless Chromium (Playwright): issue 11's browser checks.

A ceiling object reviewed in the gallery (the "On" filter, the panel naming the ceiling seen
from below, the A key) and a missed object added by a click on the ceiling's orthoimage; a
ceiling object reviewed in the 3D scene (Next pending flies below it, Accept).
"""

from __future__ import annotations

import json
import time

import httpx
import pytest

from app.config import AppSettings
from app.sample import ensure_sample_project
from app.users import add_user

from .app_support import ServerProcess, auth, join, write_small_ply
from .browser_support import GL, VIEW, login
from .surfaces_output import write_surfaces_output

pytestmark = [pytest.mark.slow, pytest.mark.browser]
BROWSER_ARGS = GL  # the 3D scene needs WebGL: software rendering


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    base = tmp_path_factory.mktemp("surfaces_browser")
    data = base / "data"
    settings = AppSettings(data_dir=data)
    pids = {}
    for name in ("gallery", "scene"):
        out = base / f"out_{name}"
        doc = write_surfaces_output(out)
        for d in doc["detections"]:  # the ceiling's smoke detector is the least sure: first in order
            if d["id"] == "D0101":
                d["alpha"] = 0.2
        (out / "detections.json").write_text(json.dumps(doc))
        pids[name] = ensure_sample_project(write_small_ply(base / f"{name}.ply", n=3000), out, settings=settings,
                                           points=3000, name=f"Surfaces {name}")
    token = add_user(settings, "rita", "reviewer")
    for pid in pids.values():
        join(settings, pid, "rita", "reviewer")  # projects belong to their members
    server = ServerProcess(data).start()
    server.token, server.pids = token, pids
    yield server
    server.stop()


def detections(srv, pid: int) -> list[dict]:  # noqa: ANN001
    return httpx.get(f"{srv.url}/api/projects/{pid}/detections", headers=auth(srv.token)).json()["detections"]


def test_ceiling_object_reviewed_and_added_in_the_gallery(browser, srv):
    pid = srv.pids["gallery"]
    page = browser.new_page(viewport=VIEW)
    try:
        login(page, srv)
        page.goto(f"{srv.url}/review.html?id={pid}&surface=ceiling")
        page.wait_for_selector(".det")
        assert page.locator("#f-surface-box").is_visible()
        assert page.locator(".det").count() == 1
        assert "ceiling C01" in page.locator(".det .where").first.inner_text()
        page.locator(".det").first.click()
        page.wait_for_selector("#p-facts:has-text('ceiling, seen from below')")
        page.wait_for_function("() => document.querySelector('#p-colour').naturalWidth > 0")  # its crop of the ceiling
        assert "Move (metres on the ceiling)" in page.locator("#p-move-title").inner_text()
        page.keyboard.press("a")
        page.wait_for_selector(".det[data-status='accepted']")
        d = next(x for x in detections(srv, pid) if x["ref"] == "D0101")
        assert d["review"]["status"] == "accepted" and d["review"]["by"] == "rita" and d["surface"] == "ceiling"
        # the columns' objects under "On: columns"
        page.select_option("#f-surface", "column")
        page.wait_for_function("() => document.querySelectorAll('.det').length === 2")
        # a bulk accept under "On: columns" takes the columns' objects only, and says so
        page.fill("#bulk-min", "0")
        page.click("#bulk-go")
        page.wait_for_selector("#bulk-dialog[open]")
        assert page.locator("#bulk-text").inner_text().startswith("Accept 2 pending detection(s) on columns")
        page.click("#bulk-ok")
        page.wait_for_selector(".det[data-status='pending']", state="detached")
        now = detections(srv, pid)
        assert all(x["review"]["status"] == "accepted" for x in now if x.get("surface") == "column")
        assert all(x["review"]["status"] == "pending" for x in now if not x.get("surface"))
        # add a missed smoke detector: choose the ceiling, click on its image (seen from below)
        page.select_option("#add-wall", "C01")
        offered = page.eval_on_selector_all("#add-class option", "os => os.map(o => o.value)")
        assert offered == ["exit_light", "smoke_detector"]  # the ceiling classes of the library (model.json mount)
        page.select_option("#add-class", "smoke_detector")
        page.wait_for_function("() => document.querySelector('#wall-img').naturalWidth > 0")
        box = page.locator("#wall-img").bounding_box()
        page.locator("#wall-img").click(position={"x": box["width"] * 0.25, "y": box["height"] * 0.5})
        page.wait_for_selector("#add-msg:has-text('Smoke detector on C01')")  # the library's name
        added = [x for x in detections(srv, pid) if x["source"] == "reviewer"]
        assert len(added) == 1 and added[0]["surface"] == "ceiling" and added[0]["wall"] == "C01"
        assert added[0]["u"] == pytest.approx(1.0, abs=0.15) and added[0]["v"] == pytest.approx(1.5, abs=0.15)
        assert added[0]["position"][2] == pytest.approx(2.5)  # on the ceiling plane
    finally:
        page.close()


def test_ceiling_object_reviewed_in_the_scene(browser, srv):
    pid = srv.pids["scene"]
    ctx = browser.new_context(viewport=VIEW)
    page = ctx.new_page()
    try:
        login(page, srv)
        page.goto(f"{srv.url}/project.html?id={pid}")
        page.wait_for_selector("#title:has-text('Surfaces scene')")
        with page.expect_popup() as pop:
            page.click("#open-3d")
        scene = pop.value
        scene.get_by_text("Signed in as rita").wait_for(timeout=60_000)
        scene.get_by_text("2 column(s)").wait_for(timeout=60_000)
        scene.add_style_tag(content=".mantine-Notifications-root{display:none}")
        scene.get_by_role("button", name="Next pending ▶").click()
        scene.get_by_text("ceiling C01 (seen from below)").wait_for(timeout=15_000)
        scene.get_by_text("Review: pending").wait_for(timeout=10_000)
        time.sleep(1.0)  # the camera flight below the ceiling
        scene.get_by_role("button", name="Accept", exact=True).click()
        deadline = time.monotonic() + 15
        d = None
        while time.monotonic() < deadline:
            d = next(x for x in detections(srv, pid) if x["ref"] == "D0101")
            if d["review"]["status"] == "accepted":
                break
            time.sleep(0.3)
        assert d["review"]["status"] == "accepted" and d["review"]["by"] == "rita" and d["surface"] == "ceiling"
        others = [x for x in detections(srv, pid) if x["ref"] != "D0101"]
        assert all(x["review"]["status"] == "pending" for x in others)
    finally:
        ctx.close()
