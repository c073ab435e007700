"""Security headers on every response (issue 30), and the pages still work under the policy."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from app.config import AppSettings
from app.headers import inline_script_hashes
from app.server import create_app

from .app_support import ServerProcess


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = AppSettings(data_dir=tmp_path_factory.mktemp("headers") / "d", viewer=False)
    with TestClient(create_app(settings, start_jobs=False)) as c:
        yield c


def test_every_answer_carries_the_security_headers(client):
    answers = [client.get("/index.html"), client.get("/review.html"), client.get("/app.js"),
               client.get("/api/health"), client.get("/api/projects"), client.get("/openapi.json"),
               client.get("/api/nowhere"), client.get("/no-such-page"), client.post("/api/projects", json={}),
               client.get("/", follow_redirects=False)]
    for r in answers:
        h = r.headers
        csp = h.get("content-security-policy", "")
        assert "frame-ancestors 'none'" in csp and "object-src 'none'" in csp, (r.url, csp)
        assert h.get("x-frame-options") == "DENY" and h.get("x-content-type-options") == "nosniff", r.url
        assert h.get("referrer-policy") == "no-referrer", r.url
    assert {r.status_code for r in answers} >= {200, 401, 404, 307}


def test_the_policy_allows_exactly_the_pages_inline_scripts(client):
    csp = client.get("/api/health").headers["content-security-policy"]
    script_src = next(p for p in csp.split("; ") if p.startswith("script-src"))
    assert "'unsafe-inline'" not in script_src and "'unsafe-eval'" not in script_src
    hashes = set(re.findall(r"'sha256-[^']+'", script_src))
    assert hashes and hashes == set(inline_script_hashes(client.app.state.settings.static_dir))
    assert len(hashes) >= 4  # one inline script per page


@pytest.mark.slow
@pytest.mark.browser
def test_pages_run_under_the_policy(browser, tmp_path):
    server = ServerProcess(tmp_path / "d", {"SBSC_VIEWER": "false"}).start()
    page = browser.new_page()
    violations: list[str] = []
    page.on("console", lambda m: violations.append(m.text) if "Content Security Policy" in m.text else None)
    try:
        for name in ("index", "project", "review", "signoff"):
            page.goto(f"{server.url}/{name}.html?id=1")
            page.wait_for_load_state("networkidle")
            assert page.evaluate("typeof SBSC") == "object", name  # app.js ran
        page.goto(f"{server.url}/index.html")
        page.wait_for_selector("#login", state="visible")  # the page's inline script ran
    finally:
        page.close()
        server.stop()
    assert violations == []
