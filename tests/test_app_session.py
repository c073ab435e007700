"""One login per browser: the HttpOnly session cookie after the token login (app.sessions)."""

from __future__ import annotations

from fastapi.testclient import TestClient
from sqlalchemy import update

from app.auth import create_user, hash_token
from app.config import AppSettings
from app.models import User
from app.server import create_app
from app.sessions import COOKIE, SessionKeeper


def _app(tmp_path):
    settings = AppSettings(data_dir=tmp_path / "d", viewer=False)
    return create_app(settings, start_jobs=False)

def test_token_login_gives_a_cookie_session_for_every_tab(tmp_path):
    with TestClient(_app(tmp_path)) as browser:
        db = browser.app.state.db
        with db.write() as s:
            rita, token = create_user(s, "rita", "manager")
            rita_id = rita.id
        assert browser.post("/api/session").status_code == 401  # no token, no session
        assert browser.post("/api/session", headers={"Authorization": "Bearer sbsc_wrong"}).status_code == 401
        r = browser.post("/api/session", headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 200 and r.json()["name"] == "rita"
        cookie = r.headers["set-cookie"]
        assert cookie.startswith(f"{COOKIE}=") and "HttpOnly" in cookie and "SameSite=strict" in cookie
        assert "Path=/" in cookie and "Max-Age=" in cookie
        assert token not in cookie  # the token is not in the cookie
        # any tab of this browser (the same cookie jar): signed in without the token
        assert browser.get("/api/me").json() == {"id": rita_id, "name": "rita", "role": "manager"}
        assert browser.get("/api/projects").status_code == 200
        # a change made with the cookie alone must come from the app's own pages
        assert browser.post("/api/projects", json={"name": "A"}).status_code == 403
        evil = browser.post("/api/projects", json={"name": "B"}, headers={"Origin": "http://evil.example"})
        assert evil.status_code == 403
        ok = browser.post("/api/projects", json={"name": "C"}, headers={"Origin": "http://testserver"})
        assert ok.status_code in (200, 201), ok.text
        assert browser.post("/api/projects", json={"name": "D"},
                            headers={"Referer": "http://testserver/index.html"}).status_code in (200, 201)
        # scripts keep their bearer token (no cookie, no Origin needed)
        with TestClient(browser.app) as script:
            assert script.get("/api/me").status_code == 401
            assert script.post("/api/projects", json={"name": "E"},
                               headers={"Authorization": f"Bearer {token}"}).status_code in (200, 201)
        # logout ends the session even for a copy of the cookie kept elsewhere
        kept = browser.cookies.get(COOKIE)
        assert browser.delete("/api/session").json() == {"ended": True}
        assert browser.get("/api/me").status_code == 401  # cookie cleared
        browser.cookies.set(COOKIE, kept)
        assert browser.get("/api/me").status_code == 401  # and refused by the server
        # a new session ends when the user's token is replaced
        browser.cookies.clear()
        browser.post("/api/session", headers={"Authorization": f"Bearer {token}"})
        assert browser.get("/api/me").status_code == 200
        with db.write() as s:
            s.execute(update(User).where(User.id == rita_id).values(token_hash=hash_token("sbsc_new")))
        assert browser.get("/api/me").status_code == 401

def test_session_tickets_are_signed_and_expire(tmp_path):
    k = SessionKeeper.for_data_dir(tmp_path)
    assert (tmp_path / "session.key").stat().st_mode & 0o777 == 0o600
    value = k.issue(3, "ab" * 32, now=1000.0)
    t = k.check(value, now=1000.0 + k.ttl_s - 1)
    assert t is not None and t.user_id == 3 and t.fingerprint == "ab" * 8
    assert k.check(value, now=1000.0 + k.ttl_s + 1) is None  # expired
    body, _, sig = value.partition(".")
    assert k.check(body.replace(body[2], "A" if body[2] != "A" else "B", 1) + "." + sig, now=1000.0) is None
    # the key lives in the data dir: a restarted server keeps the sessions, another data dir does not
    assert SessionKeeper.for_data_dir(tmp_path).check(value, now=1001.0) is not None
    assert SessionKeeper.for_data_dir(tmp_path / "other").check(value, now=1001.0) is None
    assert k.check(k.issue(3, "cd" * 32)) is not None
