"""Browser sessions: one login per browser, for every tab and the 3D scene.

After the token login, ``POST /api/session`` (with ``Authorization: Bearer TOKEN``) sets the
cookie ``sbsc_session``: HttpOnly (no script reads it), ``SameSite=Strict`` (no other site's
page sends it) and ``Secure`` over HTTPS. Its value is a signed ticket (user id, a
fingerprint of the user's token, expiry, a random id), HMAC-SHA256 with a key kept in the
data dir (``session.key``, mode 0600), so sessions survive a restart of ``sbsc serve``. A
session ends at its expiry, at logout (``DELETE /api/session``: its id is refused from then
on) and when the user's token is replaced or the user disabled (the fingerprint or the user
no longer match). Requests that change something and come with the cookie alone must also
come from the app's own origin (``Origin``, else ``Referer``, naming the request's host).
Bearer tokens keep working for scripts.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import os
import secrets
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from sqlalchemy.orm import Session

from .auth import Principal
from .models import User

COOKIE = "sbsc_session"
SESSION_TTL_S = 7 * 24 * 3600.0
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


@dataclass(frozen=True)
class SessionTicket:
    user_id: int
    fingerprint: str  # the first characters of the user's token hash
    expires: float
    sid: str


def _key(data_dir: Path) -> bytes:
    """The signing key of this data dir, made once (readable by the owner only)."""
    path = Path(data_dir) / "session.key"
    try:
        return bytes.fromhex(path.read_text().strip())
    except (OSError, ValueError):
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".session.key.{os.getpid()}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as fh:
        fh.write(secrets.token_hex(32))
    try:
        os.link(tmp, path)  # the first writer wins; others read its key
    except FileExistsError:
        pass
    finally:
        os.unlink(tmp)
    return bytes.fromhex(path.read_text().strip())


class SessionKeeper:
    """Issues and checks session cookies; remembers the sessions ended by logout."""

    def __init__(self, key: bytes, ttl_s: float = SESSION_TTL_S) -> None:
        self._key = key
        self.ttl_s = ttl_s
        self._ended: dict[str, float] = {}  # session id -> its expiry
        self._lock = threading.Lock()

    @classmethod
    def for_data_dir(cls, data_dir: Path, ttl_s: float = SESSION_TTL_S) -> SessionKeeper:
        return cls(_key(data_dir), ttl_s)

    def _sign(self, body: str) -> str:
        return hmac.new(self._key, body.encode(), hashlib.sha256).hexdigest()

    def issue(self, user_id: int, token_hash: str, now: float | None = None) -> str:
        t = {"u": user_id, "f": token_hash[:16], "e": round((now or time.time()) + self.ttl_s),
             "s": secrets.token_urlsafe(12)}
        body = base64.urlsafe_b64encode(json.dumps(t, separators=(",", ":")).encode()).decode().rstrip("=")
        return f"{body}.{self._sign(body)}"

    def check(self, value: str, now: float | None = None) -> SessionTicket | None:
        """The ticket of a cookie value: None when forged, expired or ended."""
        body, _, sig = value.partition(".")
        if not body or len(value) > 400 or not hmac.compare_digest(sig, self._sign(body)):
            return None
        try:
            t = json.loads(base64.urlsafe_b64decode(body + "=" * (-len(body) % 4)))
            ticket = SessionTicket(int(t["u"]), str(t["f"]), float(t["e"]), str(t["s"]))
        except (ValueError, KeyError, TypeError):
            return None
        if ticket.expires < (now or time.time()):
            return None
        with self._lock:
            if ticket.sid in self._ended:
                return None
        return ticket

    def end(self, value: str) -> None:
        """Refuse this session from now on (logout)."""
        ticket = self.check(value)
        if ticket is None:
            return
        now = time.time()
        with self._lock:
            self._ended = {s: e for s, e in self._ended.items() if e > now}  # forget the expired
            self._ended[ticket.sid] = ticket.expires


def principal_of(session: Session, ticket: SessionTicket) -> Principal | None:
    """The user of a session, while the user is enabled and still holds the same token."""
    user = session.get(User, ticket.user_id)
    if user is None or user.disabled or not hmac.compare_digest(user.token_hash[:16], ticket.fingerprint):
        return None
    return Principal(id=user.id, name=user.name, role=user.role)


def same_origin(method: str, headers: dict[str, str] | object, host: str | None) -> bool:
    """Whether a request that came with the cookie alone may go on: a safe method, or an
    ``Origin`` (else ``Referer``) naming this very host. A request naming neither is refused."""
    if method.upper() in SAFE_METHODS:
        return True
    get = headers.get
    source = get("origin") or get("referer")
    if not source or source == "null" or not host:
        return False
    return urlsplit(source).netloc.lower() == host.lower()
