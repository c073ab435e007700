"""The first hour of a new user, in Chromium: one login per browser (issue 29)."""

from __future__ import annotations

import pytest

from .test_app_browser import browser  # noqa: F401 - the fixture (Debian chromium + Playwright)
from .test_app_pages import VIEWPORT, site  # noqa: F401 - a server with a sample project

pytestmark = pytest.mark.browser


def test_one_login_serves_every_tab_until_logout(browser, site) -> None:  # noqa: F811
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
