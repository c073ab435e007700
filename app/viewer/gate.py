"""The 3D scene's door: the app's login, carried by a cookie; the scene's own origin only.

The review pages hold the API token; asking ``GET /api/projects/{pid}/viewer`` with it sets
a short-lived, HttpOnly, ``SameSite=Strict`` cookie holding a signed ticket (user id, role,
expiry; HMAC-SHA256 with a secret that lives only in this server process). Cookies are
per host, not per port, so the browser sends it to the project's viser server too: the
scene signs the reviewer in with no second token.

viser has no hook for this, so each viser server is started with a request filter in front
of its own (``websockets``' ``process_request``): every request without a valid ticket is
refused with 403, and so is a websocket whose ``Origin`` is not the scene's own page. The
user of each accepted websocket is remembered for the scene (:meth:`ViewerGate.user_of`).
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import secrets
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from http.cookies import CookieError, SimpleCookie
from typing import Any

import viser

from ..headers import SCENE_HEADERS

COOKIE = "sbsc_viewer"
TICKET_TTL_S = 3600.0  # asked again each time a page opens the scene; an open scene stays connected
_SERVE_LOCK = threading.Lock()  # the request filter is put in place while one viser server starts


@dataclass(frozen=True)
class Ticket:
    user_id: int
    name: str
    role: str
    expires: float
    project: int | None = None  # the one project whose scene it opens


def cookie_name(project: int | None) -> str:
    """The cookie of one project's scene (each scene has its own: opening one keeps another)."""
    return COOKIE if project is None else f"{COOKIE}_{project}"


class ViewerGate:
    """Issues and checks viewer tickets; filters the requests of the viser servers."""

    def __init__(self, ttl_s: float = TICKET_TTL_S, secret: bytes | None = None) -> None:
        self.ttl_s = ttl_s
        self._secret = secret or secrets.token_bytes(32)
        # websocket connection -> who opened it (forgotten with the connection)
        self._users: weakref.WeakKeyDictionary[Any, Ticket] = weakref.WeakKeyDictionary()
        self._lock = threading.Lock()

    # -- tickets -------------------------------------------------------------------------
    def issue(self, user_id: int, name: str, role: str, now: float | None = None, *,
              project: int | None = None) -> str:
        """A signed ticket; with ``project``, it opens that project's scene only."""
        body = json.dumps({"u": user_id, "n": name, "r": role, "p": project,
                           "e": round((now or time.time()) + self.ttl_s)}, separators=(",", ":"))
        b = base64.urlsafe_b64encode(body.encode()).decode().rstrip("=")
        return f"{b}.{self._sign(b)}"

    def _sign(self, b: str) -> str:
        return hmac.new(self._secret, b.encode(), hashlib.sha256).hexdigest()

    def verify(self, ticket: str | None, now: float | None = None) -> Ticket | None:
        if not ticket or "." not in ticket or len(ticket) > 2000:
            return None
        b, _, sig = ticket.rpartition(".")
        if not hmac.compare_digest(sig, self._sign(b)):
            return None
        try:
            d = json.loads(base64.urlsafe_b64decode(b + "=" * (-len(b) % 4)))
            p = d.get("p")
            t = Ticket(int(d["u"]), str(d["n"]), str(d["r"]), float(d["e"]), None if p is None else int(p))
        except (ValueError, KeyError, TypeError):
            return None
        return t if t.expires > (now or time.time()) else None

    def ticket_of(self, cookie_header: str | None, project: int | None = None) -> Ticket | None:
        """The valid ticket in a ``Cookie`` header; for ``project``, one naming that project."""
        if not cookie_header:
            return None
        try:
            jar = SimpleCookie(cookie_header)
        except CookieError:
            return None
        morsel = jar.get(cookie_name(project))
        ticket = self.verify(morsel.value if morsel else None)
        return ticket if ticket is not None and ticket.project == project else None

    # -- requests ------------------------------------------------------------------------
    def check(self, connection: Any, request: Any, project: int | None = None) -> Any:
        """``process_request`` of a viser server: None lets the request through, else a 403.

        The scene of ``project`` lets only tickets of that project in.
        """
        headers = request.headers
        ticket = self.ticket_of(headers.get("Cookie"), project)
        if ticket is None:
            return connection.respond(403, "Sign in to the sbsc review app and open the 3D view "
                                           "from the project's page.\n")
        if headers.get("Upgrade", "").lower() == "websocket":
            origin = headers.get("Origin")
            host = headers.get("Host", "")
            if origin is not None and origin not in (f"http://{host}", f"https://{host}"):
                return connection.respond(403, "websocket refused: foreign origin\n")
            with self._lock:
                self._users[connection] = ticket
        return None

    def user_of(self, connection: Any) -> Ticket | None:
        """Who opened an accepted websocket connection (None when unknown)."""
        if connection is None:
            return None
        with self._lock:
            return self._users.get(connection)

    # -- servers -------------------------------------------------------------------------
    def server(self, project: int | None = None, **kwargs: Any) -> viser.ViserServer:
        """A ``viser.ViserServer(**kwargs)`` whose every request goes through :meth:`check`
        (with ``project``: tickets of that project only)."""
        import websockets.asyncio.server as wss

        original = wss.serve
        gate = self

        def check(connection: Any, request: Any) -> Any:
            return gate.check(connection, request, project)

        def serve(handler: Callable, *args: Any, process_request: Callable | None = None,
                  process_response: Callable | None = None, **kw: Any):
            def gated(connection: Any, request: Any) -> Any:
                refused = check(connection, request)
                if refused is not None:
                    return refused
                return process_request(connection, request) if process_request else None

            def secured(connection: Any, request: Any, response: Any) -> Any:
                out = process_response(connection, request, response) if process_response else None
                for name, value in SCENE_HEADERS:  # every answer of the scene: pages, files, refusals
                    target = (out or response).headers
                    if name in target:
                        del target[name]
                    target[name] = value
                return out

            return original(handler, *args, process_request=gated, process_response=secured, **kw)

        with _SERVE_LOCK:
            wss.serve = serve
            try:
                server = viser.ViserServer(**kwargs)
            finally:
                wss.serve = original
        return server


def connection_of(server: viser.ViserServer, client_id: int) -> Any:
    """The websocket connection of a viser client (viser keeps it in a private table)."""
    ws = getattr(server, "_websock_server", None)
    return getattr(ws, "_live_connections", {}).get(client_id)
