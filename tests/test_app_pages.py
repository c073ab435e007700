"""Each page at 1440x900 in Chromium, checked for what a person sees (and saved as a screenshot).

Hidden parts stay hidden (``[hidden]`` beats ``.row{display:flex}``), primary link-buttons
are styled, an image that is not loaded is a grey square (no broken-image icon or alt
text), long class names wrap instead of being cut, α / ρ are explained, ``/favicon.ico``
exists, and the sample project comes with the simulator's as-designed model.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import httpx
import numpy as np
import pytest

from .app_support import auth
from .browser_support import DISPLAY_NAMES, LONG_CLASSES, SHOTS, VIEWPORT

pytestmark = [pytest.mark.slow, pytest.mark.browser]





@pytest.fixture
def page(browser, site):
    p = browser.new_page(viewport=VIEWPORT)
    yield p
    p.close()


def _login(page, site) -> None:
    page.goto(site.url + "/index.html")
    if page.locator("#login").is_visible():
        page.fill("#token", site.token)
        page.click("#login-form button[type=submit]")
    page.wait_for_selector("#projects", state="visible")


def _no_horizontal_overflow(page) -> None:
    assert page.evaluate("document.documentElement.scrollWidth") <= VIEWPORT["width"]


def _shot(page, name: str) -> Path:
    path = SHOTS / f"page_{name}.png"
    page.screenshot(path=str(path))
    assert path.stat().st_size > 5_000
    return path


def test_favicon_is_served(site) -> None:
    r = httpx.get(site.url + "/favicon.ico")
    assert r.status_code == 200 and r.content[:4] == b"\x00\x00\x01\x00"  # an ICO file


def test_index_login_then_projects(browser, site) -> None:
    page = browser.new_page(viewport=VIEWPORT)
    try:
        page.goto(site.url + "/index.html")
        page.wait_for_selector("#login", state="visible")
        assert page.locator("#projects").is_hidden()
        button = page.locator("#login-form button.primary")
        assert button.evaluate("b => getComputedStyle(b).backgroundColor") == "rgb(31, 111, 235)"
        _shot(page, "login")
        page.fill("#token", site.token)
        page.click("#login-form button[type=submit]")
        page.wait_for_selector("#projects", state="visible")
        assert page.locator("#login").is_hidden()
        page.wait_for_selector("text=Sample: Scenario I")
        _no_horizontal_overflow(page)
        _shot(page, "projects")
    finally:
        page.close()


def test_project_without_design_hides_comparison_and_bcf(page, site) -> None:
    _login(page, site)
    page.goto(f"{site.url}/project.html?id={site.empty}")
    page.wait_for_selector("#title:has-text('Empty')")
    links = page.locator("#comparison-links")
    assert links.count() == 1 and links.is_hidden(), "the comparison and BCF links show without a design"
    assert page.locator("#comparison").is_hidden()
    _no_horizontal_overflow(page)
    _shot(page, "project_empty")


def test_sample_project_has_the_design_and_a_styled_gallery_button(page, site) -> None:
    _login(page, site)
    page.goto(f"{site.url}/project.html?id={site.pid}")
    page.wait_for_selector("#design:has-text('as_designed.ifc')")
    page.wait_for_selector("#comparison-links", state="visible", timeout=30_000)
    to_review = page.locator("#to-review")  # an <a class="button primary">
    assert to_review.is_visible()
    assert to_review.evaluate("a => getComputedStyle(a).backgroundColor") == "rgb(31, 111, 235)"
    assert to_review.evaluate("a => getComputedStyle(a).color") == "rgb(255, 255, 255)"
    _no_horizontal_overflow(page)
    _shot(page, "project_sample")


def test_review_tiles_names_and_explanations(page, site) -> None:
    _login(page, site)
    dets = httpx.get(f"{site.url}/api/projects/{site.pid}/detections", headers=auth(site.token)).json()["detections"]
    ids = {d["ref"] if "ref" in d else d["id"]: str(d["id"]) for d in dets}
    first, second, third = ids.get("D0001", str(dets[0]["id"])), str(dets[1]["id"]), str(dets[2]["id"])
    # the first detection's thumbnails never arrive: its tile must stay a plain grey square
    page.route(f"**/api/detections/{first}/thumbnail/**", lambda route: route.abort())
    page.goto(f"{site.url}/review.html?id={site.pid}")
    page.wait_for_selector(".det")
    page.wait_for_function("() => [...document.querySelectorAll('.det img')].slice(2, 8)"  # a function: no eval under the CSP
                           ".every(i => i.complete && i.naturalWidth > 0)")
    # long class names: the whole name is on the tile, nothing cut or hidden
    for cls in page.locator(".det .cls").all():
        text = cls.inner_text().strip()
        assert text in DISPLAY_NAMES.values()  # the library's names, never the class ids
        assert cls.evaluate("e => e.scrollWidth <= e.clientWidth + 1 && e.scrollHeight <= e.clientHeight + 1")
        card = cls.evaluate("e => { const a = e.getBoundingClientRect(), b = e.closest('.det')"
                            ".getBoundingClientRect(); return a.right <= b.right + 0.5 && a.left >= b.left - 0.5 }")
        assert card, text
    # the unloaded tile: uniform grey where the images are, no icon, no alt text
    tile = page.locator(f".det[data-id='{first}'] .thumbs")
    img = cv2.imdecode(np.frombuffer(tile.screenshot(), np.uint8), cv2.IMREAD_GRAYSCALE)
    assert img.min() >= 200, "broken-image icon or alt text on a tile that is not loaded"
    loaded = cv2.imdecode(np.frombuffer(page.locator(f".det[data-id='{third}'] .thumbs").screenshot(), np.uint8),
                          cv2.IMREAD_GRAYSCALE)
    assert loaded.std() > 5  # a real thumbnail is not a flat square
    # α and ρ are explained, and what the numbers mean is said in the panel
    legend = page.locator("#legend")
    assert legend.is_visible() and "α" in legend.inner_text() and "ρ depth" in legend.inner_text()
    page.locator(f".det[data-id='{second}']").click()
    facts = page.locator("#p-facts").inner_text()
    assert "not found in colour" in facts and "depth only" in facts and "ρ colour" not in facts
    page.locator(f".det[data-id='{third}']").click()
    facts = page.locator("#p-facts").inner_text()
    assert "depth and colour" in facts and "colour distance" in facts
    _no_horizontal_overflow(page)
    _shot(page, "review")


def test_signoff_page(page, site) -> None:
    _login(page, site)
    page.goto(f"{site.url}/signoff.html?id={site.pid}")
    page.wait_for_selector("#form-box", state="visible")
    assert page.locator("#done").is_hidden()  # not signed off: the 'Signed off' card stays hidden
    assert page.locator("#sign").is_disabled() and "pending" in page.locator("#msg").inner_text()
    assert page.locator("#rows tr").count() == len(LONG_CLASSES)
    _no_horizontal_overflow(page)
    _shot(page, "signoff")
