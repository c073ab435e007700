"""Review that closes the loop, in headless Chromium (Playwright): issue 14's browser checks.

- add a missed object from the gallery (click on the wall's image) and from the 3D scene
  (shift-click on a wall);
- promote a suggestion with one key;
- bulk-accept by filter, after a confirmation that states the count;
- the 3D scene opens signed in, with no second login; its websocket is refused without a
  login and from a foreign origin.
"""

from __future__ import annotations

import time

import httpx
import pytest

from app.config import AppSettings
from app.users import add_user

from .app_support import ServerProcess, auth, fake_control, wait_job, write_small_ply
from .browser_support import GL, VIEW, login

pytestmark = [pytest.mark.slow, pytest.mark.browser]
BROWSER_ARGS = GL  # the 3D scene needs WebGL: software rendering
WS_TRY = """([url, proto]) => new Promise(res => {
    const ws = new WebSocket(url, proto);
    ws.onopen = () => { ws.close(); res("open"); };
    ws.onclose = () => res("refused");
    ws.onerror = () => res("refused");
    setTimeout(() => res("timeout"), 40000); })"""


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    base = tmp_path_factory.mktemp("review_browser")
    data = base / "data"
    settings = AppSettings(data_dir=data)
    token = add_user(settings, "rita", "reviewer")
    server = ServerProcess(data, {"SBSC_JOB_RUNNER": "tests.app_support:fake_with_suggestions"}).start()
    fake_control(data, delay_s=0.2, detections=8)
    server.token, server.base = token, base
    yield server
    server.stop()


def new_project(srv, name: str) -> int:  # noqa: ANN001
    h = auth(srv.token)
    with httpx.Client(base_url=srv.url, timeout=60) as c:
        pid = c.post("/api/projects", json={"name": name}, headers=h).json()["id"]
        ply = write_small_ply(srv.base / f"{name}.ply", n=3000)
        with open(ply, "rb") as fh:
            assert c.post(f"/api/projects/{pid}/scans", files={"file": (ply.name, fh)}, headers=h).status_code == 201
        jid = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).json()["id"]
        assert wait_job(c, jid, srv.token)["status"] == "succeeded"
    return pid


def detections(srv, pid: int) -> list[dict]:  # noqa: ANN001
    return httpx.get(f"{srv.url}/api/projects/{pid}/detections", headers=auth(srv.token)).json()["detections"]


def test_a_click_on_the_wall_while_an_add_is_saving_is_told_not_lost(browser, srv):
    """The add request is held (as a slow snap to the scan would hold it): a second click on
    the wall meanwhile gets a message instead of nothing, and only one object is added."""
    pid = new_project(srv, "busy")
    page = browser.new_page(viewport=VIEW)
    held = []
    try:
        login(page, srv)
        page.goto(f"{srv.url}/review.html?id={pid}")
        page.wait_for_selector(".det")
        page.route(f"**/api/projects/{pid}/detections",
                   lambda route: held.append(route) if route.request.method == "POST" else route.continue_())
        page.select_option("#add-wall", "W01")
        page.select_option("#add-class", "switch")
        page.wait_for_function("() => document.querySelector('#wall-img').naturalWidth > 0")
        box = page.locator("#wall-img").bounding_box()
        page.locator("#wall-img").click(position={"x": box["width"] * 0.3, "y": box["height"] * 0.5})
        page.wait_for_function("() => document.querySelector('#wall-img').style.cursor === 'progress'")
        assert len(held) == 1
        page.locator("#wall-img").click(position={"x": box["width"] * 0.7, "y": box["height"] * 0.5})
        page.wait_for_selector("#toast.show")
        assert page.locator("#toast").inner_text() == "Still saving the last change: click the wall again in a moment."
        held[0].continue_()
        page.wait_for_selector("#add-msg:has-text('pending until you confirm it')")
        assert page.locator("#wall-img").evaluate("e => e.style.cursor") == "crosshair"
        assert len(held) == 1 and sum(d["source"] == "reviewer" for d in detections(srv, pid)) == 1
    finally:
        page.close()

def test_gallery_add_promote_and_bulk_accept(browser, srv):
    pid = new_project(srv, "gallery")
    page = browser.new_page(viewport=VIEW)
    try:
        login(page, srv)
        page.goto(f"{srv.url}/review.html?id={pid}")
        page.wait_for_selector(".det")
        assert page.locator(".det").count() == 8
        # uncertain first: the gallery starts with the least sure object
        alphas = sorted(d["alpha"] for d in detections(srv, pid))
        first = page.locator(".det").first.get_attribute("data-id")
        assert next(d for d in detections(srv, pid) if d["id"] == first)["alpha"] == alphas[0]
        # add a missed object: choose wall and class, click on the wall's image
        page.select_option("#add-wall", "W01")
        page.select_option("#add-class", "switch")
        page.wait_for_function("() => document.querySelector('#wall-img').naturalWidth > 0")
        box = page.locator("#wall-img").bounding_box()
        page.locator("#wall-img").click(position={"x": box["width"] * 0.55, "y": box["height"] * 0.5})
        page.wait_for_selector("#add-msg:has-text('Switch on W01')")  # the library's name
        assert "pending until you confirm it" in page.locator("#add-msg").inner_text()
        added = [d for d in detections(srv, pid) if d["source"] == "reviewer"]
        assert len(added) == 1 and added[0]["review"]["status"] == "pending"
        page.click("#add-ok")  # confirmed
        page.wait_for_selector("#add-confirm", state="hidden")
        added = [d for d in detections(srv, pid) if d["source"] == "reviewer"]
        assert len(added) == 1 and added[0]["wall"] == "W01" and added[0]["review"]["by"] == "rita"
        assert added[0]["review"]["status"] == "accepted"
        assert added[0]["u"] == pytest.approx(0.55 * 4.0, abs=0.15)
        assert added[0]["v"] == pytest.approx(1.25, abs=0.15)
        assert page.locator(".det").count() == 9
        # promote a suggestion with one key
        page.locator("#suggestions button.sugg").first.click()
        page.keyboard.press("s")
        page.wait_for_selector("#sugg-count:has-text('(1)')")
        added = [d for d in detections(srv, pid) if d["source"] == "reviewer"]
        assert len(added) == 2 and {d["class"] for d in added} == {"switch"}
        # bulk accept by filter: the confirmation states the count
        n_pending = sum(d["review"]["status"] == "pending" for d in detections(srv, pid))
        page.fill("#bulk-min", "0")
        page.click("#bulk-go")
        page.wait_for_selector("#bulk-dialog[open]")
        text = page.locator("#bulk-text").inner_text()
        assert text.startswith(f"Accept {n_pending} pending detection(s)"), text
        page.click("#bulk-ok")
        page.wait_for_selector(".det[data-status='pending']", state="detached")
        final = detections(srv, pid)
        assert all(d["review"]["status"] == "accepted" for d in final)
        trail = httpx.get(f"{srv.url}/api/projects/{pid}/decisions", headers=auth(srv.token)).json()
        assert sum(t["action"] == "accept" for t in trail) == n_pending + 1  # each audited (and the confirmation)
    finally:
        page.close()


def test_scene_opens_signed_in_refuses_strangers_and_adds_on_a_wall(browser, srv):
    pid = new_project(srv, "scene")
    ctx = browser.new_context(viewport=VIEW)
    page = ctx.new_page()
    try:
        login(page, srv)
        page.goto(f"{srv.url}/project.html?id={pid}")
        page.wait_for_selector("#title:has-text('scene')")
        t0 = time.monotonic()
        with page.expect_popup() as pop:
            page.click("#open-3d")
        scene = pop.value
        scene.get_by_text("Signed in as rita").wait_for(timeout=30_000)  # no second login
        scene.get_by_text("objects on 2 walls").wait_for(timeout=30_000)
        print(f"\nscene ready {time.monotonic() - t0:.2f} s after the click")
        viewer_url = scene.url
        # the scene's websocket from a foreign origin (the app's page) is refused
        ws_url = viewer_url.replace("http://", "ws://")
        outcome = page.evaluate(WS_TRY, [ws_url, "viser-v" + _viser_version()])
        assert outcome == "refused"
        # without a login the scene is refused
        other = browser.new_context()
        try:
            stranger = other.new_page()
            r = stranger.goto(viewer_url)
            assert r.status == 403
            outcome = stranger.evaluate(WS_TRY, [ws_url, "viser-v" + _viser_version()])
            assert outcome == "refused"
        finally:
            other.close()
        # add a missed object from the scene: fly to an object, shift-click on its wall
        scene.add_style_tag(content=".mantine-Notifications-root{display:none}")
        scene.get_by_role("button", name="Next pending ▶").click()
        scene.get_by_text("Review: pending").wait_for(timeout=10_000)
        time.sleep(1.5)  # the camera flight
        before = {d["id"] for d in detections(srv, pid)}
        scene.keyboard.down("Shift")
        scene.mouse.click(VIEW["width"] * 0.5, VIEW["height"] * 0.5 - 60)
        scene.keyboard.up("Shift")
        deadline = time.monotonic() + 15
        new = []
        while time.monotonic() < deadline and not new:
            new = [d for d in detections(srv, pid) if d["id"] not in before]
            time.sleep(0.3)
        assert len(new) == 1 and new[0]["source"] == "reviewer" and new[0]["review"]["by"] == "rita"
    finally:
        ctx.close()


def _viser_version() -> str:
    import viser

    return viser.__version__
