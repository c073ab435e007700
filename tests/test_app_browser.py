"""The review pages in a real browser (Debian's Chromium driven by Playwright).

Logs in with a token, opens the sample project, accepts a detection with the keyboard,
reloads and sees the decision kept; saves a screenshot of the gallery to
``docs/images/review_gallery.png``. Chromium is installed with apt-get when missing.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import httpx
import pytest

from app.config import AppSettings
from app.sample import SAMPLE_NAME, ensure_sample_project
from app.users import add_user

from .app_support import (
    ROOT,
    ServerProcess,
    auth,
    fake_control,
    join,
    simulate_one_room,
    write_small_ply,
)

pytestmark = [pytest.mark.slow, pytest.mark.browser]

# docs/images only when asked (SBSC_SAVE_SCREENSHOTS=1): a test run never changes the tree
SCREENSHOT = (ROOT / "docs" / "images" if os.environ.get("SBSC_SAVE_SCREENSHOTS") == "1"
              else Path(tempfile.gettempdir()) / "sbsc-screenshots") / "review_gallery.png"


@pytest.fixture(scope="module")
def sample_server(tmp_path_factory):
    """A server whose sample project holds the real pipeline's results on the one-room scene."""
    from sbsc_core.pipeline.detect import detect_to_dir

    base = tmp_path_factory.mktemp("app_browser")
    data = base / "data"
    settings = AppSettings(data_dir=data)
    sim = simulate_one_room(base / "sim")
    out = base / "detect-out"
    detect_to_dir([sim / "scan.ply"], sim / "models", expected=sim / "expected.json", out=out)
    n = len(json.loads((out / "detections.json").read_text())["detections"])
    assert n >= 3, "the pipeline found fewer than 3 objects in the one-room scene"
    pid = ensure_sample_project(sim / "scan.ply", out, models=sim / "models", settings=settings)
    assert ensure_sample_project(sim / "scan.ply", out, settings=settings) == pid  # idempotent
    token = add_user(settings, "rita", "reviewer")
    join(settings, pid, "rita", "reviewer")  # projects belong to their members
    server = ServerProcess(data, {"SBSC_JOB_RUNNER": "tests.app_support:fake_detect_to_dir"}).start()
    fake_control(data, mode="ok", delay_s=3.0, detections=5)
    server.token, server.pid, server.base, server.n = token, pid, base, n
    yield server
    server.stop()


def test_keyboard_review_survives_reload(browser, sample_server):
    srv = sample_server
    page = browser.new_page(viewport={"width": 1360, "height": 900})
    try:
        page.goto(srv.url + "/")
        page.fill("#token", srv.token)
        page.click("#login-form button[type=submit]")
        # a new project: upload a scan with the progress bar, run a job, follow its progress bar
        page.fill("#new-name", "Browser upload")
        page.click("#new-project button[type=submit]")
        page.wait_for_selector("#title:has-text('Browser upload')")
        page.set_input_files("#scan-file", str(write_small_ply(srv.base / "more.ply", n=777)))
        page.click("#scan-form button[type=submit]")
        page.wait_for_selector("#scan-msg:has-text('777 points')")
        page.wait_for_selector("#scans tr")  # the list is re-rendered after the message
        assert page.locator("#scans tr").count() == 1
        page.click("#run-job")
        page.wait_for_selector("#job-live progress", state="visible")
        page.wait_for_selector("#job-live", state="hidden", timeout=60_000)
        assert page.locator("#jobs tr").first.locator(".badge").inner_text() == "succeeded"
        # open the sample project and its gallery
        page.click("header >> text=Projects")
        page.click(f"text={SAMPLE_NAME}")
        page.wait_for_selector("#title:has-text('Sample')")
        page.click("#to-review")
        page.wait_for_selector(".det")
        assert page.locator(".det").count() == srv.n
        # move to the third detection with the arrow keys, accept it with A
        page.keyboard.press("ArrowRight")
        page.keyboard.press("ArrowRight")
        target = page.locator(".det.selected").get_attribute("data-id")
        page.keyboard.press("a")
        page.wait_for_selector(f".det[data-id='{target}'][data-status='accepted']")
        # the selection moved on; reject that one with R
        nxt = page.locator(".det.selected").get_attribute("data-id")
        assert nxt != target
        page.keyboard.press("r")
        page.wait_for_selector(f".det[data-id='{nxt}'][data-status='rejected']")
        page.reload()
        page.wait_for_selector(".det")
        assert page.locator(f".det[data-id='{target}']").get_attribute("data-status") == "accepted"
        assert page.locator(f".det[data-id='{nxt}']").get_attribute("data-status") == "rejected"
        # the server has them, with who decided
        det = httpx.get(f"{srv.url}/api/detections/{target}", headers=auth(srv.token)).json()
        assert det["review"]["status"] == "accepted" and det["review"]["by"] == "rita"
        # filters: only the accepted one
        page.select_option("#f-status", "accepted")
        assert page.locator(".det").count() == 1
        page.select_option("#f-status", "")
        page.locator(f".det[data-id='{target}']").click()
        page.wait_for_function(
            "() => [...document.querySelectorAll('.det img')].slice(0, 12).every(i => i.complete && i.naturalWidth > 0)")
        page.wait_for_function("() => document.querySelector('#p-colour').naturalWidth > 0")
        page.wait_for_selector("#p-history li")
        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SCREENSHOT))
        assert SCREENSHOT.stat().st_size > 10_000
        # logged out, a link to the gallery goes through the login page and back
        page.click("text=Log out")
        page.wait_for_selector("#login-form")
        page.goto(f"{srv.url}/review.html?id={srv.pid}&status=accepted")
        page.fill("#token", srv.token)
        page.click("#login-form button[type=submit]")
        page.wait_for_url("**/review.html?id=*")
        page.wait_for_selector(f".det[data-id='{target}']")
        assert page.locator(".det").count() == 1
        # a wrong token is refused on the login page
        page.click("text=Log out")
        page.fill("#token", "sbsc_wrong")
        page.click("#login-form button[type=submit]")
        page.wait_for_selector("#login-error:has-text('not valid')")
    finally:
        page.close()
