"""The first hour of a new user, in Chromium: one login per browser (issue 29)."""

from __future__ import annotations

import pytest

from .browser_support import VIEWPORT

pytestmark = [pytest.mark.slow, pytest.mark.browser]


def test_one_login_serves_every_tab_until_logout(browser, site) -> None:
    ctx = browser.new_context(viewport=VIEWPORT)
    try:
        first = ctx.new_page()
        first.goto(site.url + "/index.html")
        first.fill("#token", site.token)
        first.click("#login-form button[type=submit]")
        first.wait_for_selector("#projects", state="visible")
        assert first.evaluate("document.cookie") == ""  # HttpOnly: no script reads the session
        assert site.token not in first.evaluate("JSON.stringify(sessionStorage) + JSON.stringify(localStorage)")
        # a new tab on a project page: signed in, no token asked
        second = ctx.new_page()
        second.goto(f"{site.url}/project.html?id={site.pid}")
        second.wait_for_selector("#title:has-text('Sample')")
        assert "max (manager)" in second.locator("#who").inner_text()
        # log out in one tab: the other is sent to the login page at its next request
        second.click("#who button")
        second.wait_for_selector("#login", state="visible")
        first.goto(f"{site.url}/project.html?id={site.pid}")
        first.wait_for_selector("#login", state="visible")
        assert "next=" in first.url
        # another browser (another context) never shares the session
        other = browser.new_page(viewport=VIEWPORT)
        other.goto(f"{site.url}/project.html?id={site.pid}")
        other.wait_for_selector("#login", state="visible")
        other.close()
    finally:
        ctx.close()


def _login(page, site) -> None:  # noqa: ANN001, F811
    page.goto(site.url + "/index.html")
    page.fill("#token", site.token)
    page.click("#login-form button[type=submit]")
    page.wait_for_selector("#projects", state="visible")


def test_signoff_page_has_every_export(browser, site) -> None:
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        _login(page, site)
        page.goto(f"{site.url}/signoff.html?id={site.pid}")
        for b in ("#export-ifc", "#export-json", "#export-report", "#export-bcf"):
            page.wait_for_selector(b, state="visible")
        with page.expect_download() as dl:
            page.click("#export-bcf")
        assert dl.value.suggested_filename.endswith("findings.bcf")
        with page.expect_download() as dl:
            page.click("#export-ifc")
        assert dl.value.suggested_filename == f"Sample__Scenario_I-{site.pid}.ifc"
        page.goto(f"{site.url}/signoff.html?id={site.empty}")  # no design: says how to get the comparison
        page.wait_for_selector("#export-no-design", state="visible")
        assert page.locator("#export-bcf").is_hidden()
    finally:
        page.close()


def test_add_missed_from_the_top_and_the_panel_pending_until_confirmed(browser, site) -> None:
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        _login(page, site)
        page.goto(f"{site.url}/review.html?id={site.pid}")
        page.wait_for_selector(".det")
        # the detail panel fits the window: its last part (History) is reachable inside it
        page.locator(".det").first.click()
        assert page.locator("#panel").bounding_box()["height"] <= 800
        page.evaluate("window.scrollBy(0, document.getElementById('panel').getBoundingClientRect().top)")
        box = page.locator("#panel").bounding_box()  # scrolled to it: the whole panel is in the window
        assert 0 <= box["y"] and box["y"] + box["height"] <= 800 + 1
        page.locator("#p-history").scroll_into_view_if_needed()
        assert page.locator("#b-move").is_visible()
        # from the panel: the add box opens on the selected object's wall
        wall = page.locator(".det.selected .where").inner_text().split("·")[1].strip()
        page.click("#b-add-here")
        assert page.locator("#add-wall").input_value() == wall
        assert page.locator("#add-box").bounding_box()["y"] < 800  # scrolled to it
        page.evaluate("window.scrollTo(0, 0)")
        page.click("#to-add")  # and from the top of the page
        assert page.locator("#add-box").bounding_box()["y"] < 800
        page.wait_for_function("() => document.getElementById('wall-img').naturalWidth > 0")
        refs = sorted(t.split("·")[0].strip() for t in page.locator(".det .where").all_inner_texts())
        img = page.locator("#wall-img").bounding_box()
        # a click on the image where it is when clicked (a later layout shift must not move it off)
        page.locator("#wall-img").click(position={"x": img["width"] * 0.5, "y": img["height"] * 0.5})
        page.wait_for_selector("#add-confirm", state="visible")
        msg = page.locator("#add-msg").inner_text()
        new_ref = f"D{int(refs[-1][1:]) + 1:04d}"
        assert msg.startswith(f"Added {new_ref} ") and "pending" in msg
        card = page.locator(".det", has_text=new_ref)
        assert card.get_attribute("data-status") == "pending"
        page.click("#add-undo")  # undo: rejected, audited
        page.wait_for_selector("#add-confirm", state="hidden")
        assert page.locator(".det", has_text=new_ref).get_attribute("data-status") == "rejected"
        page.locator("#wall-img").click(position={"x": img["width"] * 0.3, "y": img["height"] * 0.5})
        page.wait_for_selector("#add-confirm", state="visible")
        second = f"D{int(refs[-1][1:]) + 2:04d}"
        assert page.locator("#add-msg").inner_text().startswith(f"Added {second} ")
        page.click("#add-ok")  # confirmed: accepted
        page.wait_for_selector("#add-confirm", state="hidden")
        assert page.locator(".det", has_text=second).get_attribute("data-status") == "accepted"
    finally:
        page.close()


def test_relabel_in_the_gallery_accepts_and_says_so(browser, site) -> None:
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        _login(page, site)
        page.goto(f"{site.url}/review.html?id={site.pid}&status=pending")
        page.wait_for_selector(".det")
        page.locator(".det").first.click()
        ref = page.locator(".det.selected .where").inner_text().split("·")[0].strip()
        current = page.locator("#p-class").input_value()
        options = [o for o in page.locator("#p-class option").all() if o.get_attribute("value") != current]
        target, name = options[0].get_attribute("value"), options[0].inner_text()
        assert name != target  # the library's display name in the list, not the class id
        page.select_option("#p-class", target)
        page.click("#b-relabel")
        page.wait_for_selector("#toast.show")
        assert page.locator("#toast").inner_text() == f"{ref} relabelled as {name} and accepted."
        assert page.locator(".det[data-status='accepted']", has_text=ref).count() == 1
        assert "(relabelled)" in page.locator("#p-facts").inner_text()
    finally:
        page.close()


def test_project_page_puts_results_first_and_locks_after_signoff(browser, site) -> None:
    import httpx

    from .app_support import auth

    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        _login(page, site)
        page.goto(f"{site.url}/project.html?id={site.pid}")
        page.wait_for_selector("#counts:has-text('detections from job')")
        headings = page.locator("main section h2").all_inner_texts()
        assert headings[0] == "Results"
        assert page.locator("#to-review").bounding_box()["y"] < 800  # in the first screen
        assert page.locator("#expected").is_enabled()
        name = "Signed off here"
        p2 = httpx.post(f"{site.url}/api/projects", json={"name": name}, headers=auth(site.token)).json()["id"]
        from app.db import (
            Database,  # sign it off as the server would (no results needed for the lock)
        )
        from app.models import Project

        db = Database(f"sqlite:///{site.data_dir / 'sbsc.db'}")
        with db.write() as s:
            s.get(Project, p2).status = "signed_off"
        db.dispose()
        page.goto(f"{site.url}/project.html?id={p2}")
        page.wait_for_selector(f"#title:has-text('{name}')")
        page.wait_for_function("() => document.getElementById('expected').disabled")
        assert page.locator("#run-job").is_disabled()
    finally:
        page.close()
