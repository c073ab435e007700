"""Teach and search again in Chromium (issue 28's acceptance in the browser).

Create a class, mark two examples on a wall's orthoimage, learn and search again: the job keeps
the earlier decisions and the new hits appear as pending suggestions. The scene is the fake
runner's with four card readers no library knows (``test_app_teach``).
"""

from __future__ import annotations

import httpx
import pytest

from .app_support import auth
from .app_support import project_with_job as project
from .teach_support import READERS, WALL_H

pytestmark = [pytest.mark.slow, pytest.mark.browser]

@pytest.fixture(scope="module")
def srv(teach_srv):
    return teach_srv


WALL_W = 4.0  # W01 of the fake runner


def test_create_a_class_mark_two_examples_learn_and_search_again(browser, srv) -> None:
    with httpx.Client(base_url=srv.url, timeout=60) as c:
        pid = project(c, srv, "teach_browser")
        rita = auth(srv.tokens["rita"])
        before = c.get(f"/api/projects/{pid}/detections", headers=rita).json()["detections"]
        for d, status in ((before[0], "accepted"), (before[1], "rejected")):  # earlier decisions
            assert c.patch(f"/api/detections/{d['id']}", json={"status": status, "version": 1},
                           headers=rita).status_code == 200
    page = browser.new_page(viewport={"width": 1440, "height": 900})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    try:
        page.goto(srv.url + "/index.html")
        page.fill("#token", srv.tokens["rita"])
        page.click("#login-form button[type=submit]")
        page.wait_for_selector("#projects", state="visible")
        page.goto(f"{srv.url}/review.html?id={pid}")
        page.wait_for_selector(".det")
        assert page.locator("#t-learn").is_disabled()  # no example yet
        page.fill("#t-name", "Card reader")
        page.fill("#t-ifc", "IfcCommunicationsAppliance")
        page.click("#t-create")
        page.wait_for_function("() => document.getElementById('add-class').value === 'card_reader'")  # a function: no eval
        page.select_option("#add-wall", "W01")
        page.wait_for_function("() => document.getElementById('wall-img').naturalWidth > 0")
        for k, (u, v) in enumerate(READERS[:2]):  # two examples: click on each, confirm it
            box = page.locator("#wall-img").bounding_box()
            page.mouse.click(box["x"] + (u + 0.02) / WALL_W * box["width"],
                             box["y"] + (WALL_H - v) / WALL_H * box["height"])
            page.wait_for_selector("#add-confirm", state="visible")
            page.click("#add-ok")
            page.wait_for_selector("#add-confirm", state="hidden")
            page.wait_for_function(f"() => document.getElementById('t-examples').textContent.includes('Card reader {k + 1}')")
        assert page.locator("#t-learn").is_enabled()
        page.click("#t-learn")
        page.wait_for_selector("#t-status:has-text('Searched again')", timeout=60_000)
        readers = page.locator(".det", has=page.locator(".cls[title=card_reader]"))
        assert readers.count() == len(READERS)
        statuses = sorted(readers.nth(i).get_attribute("data-status") for i in range(readers.count()))
        assert statuses == ["accepted", "accepted", "pending", "pending"]  # examples kept, new hits pending
        assert page.locator(".det[data-status=rejected]").count() == 1  # the earlier rejection kept
        assert page.locator(".det[data-status=accepted]").count() == 3  # the earlier acceptance + 2 examples
        assert page.locator("#t-download").is_visible()
        with page.expect_download() as dl:
            page.click("#t-download")
        assert dl.value.suggested_filename == f"models-{pid}.zip"
        # it must not make things worse: one of its hits rejected, the learnt class removed, then re-taught
        item = page.locator("#t-learnt li[data-class=card_reader]")
        item.wait_for()
        assert "learnt class" in item.inner_text() and "2 pending" in item.inner_text()
        pending = page.locator(".det[data-status=pending]", has=page.locator(".cls[title=card_reader]"))
        with httpx.Client(base_url=srv.url, timeout=60) as c:
            did = pending.first.get_attribute("data-id")
            d = c.get(f"/api/detections/{did}", headers=rita).json()
            assert c.patch(f"/api/detections/{did}", json={"status": "rejected", "version": d["review"]["version"]},
                           headers=rita).status_code == 200
        item.locator("button[data-act=remove]").click()
        page.wait_for_selector("#t-status:has-text('removed')")
        page.wait_for_selector("#t-learnt li[data-class=card_reader]:has-text('removed')")
        assert readers.count() == 3  # the untouched pending hit is gone, the decided ones stay
        assert pending.count() == 0
        page.locator("#t-learnt li[data-class=card_reader] button[data-act=re-teach]").click()
        page.wait_for_selector("#t-status:has-text('Searched again')", timeout=60_000)
        page.wait_for_function("() => document.querySelectorAll('.det[data-status=pending]').length > 0")
        assert sorted(readers.nth(i).get_attribute("data-status") for i in range(readers.count())) == [
            "accepted", "accepted", "pending", "rejected"]  # found again; the rejection kept
        assert "learnt class" in page.locator("#t-learnt li[data-class=card_reader]").inner_text()
        assert not [e for e in errors if "Content Security Policy" in e or "Refused" in e], errors
    finally:
        page.close()
