"""Bounds on every request before it reaches a route (issue 10).

- **ids**: a number in the path or the query that does not fit a signed 64-bit integer
  (what the database stores) answers 404 (path) or 422 (query), never an
  ``OverflowError``;
- **JSON bodies**: at most ``max_json_body_bytes`` (413; a body without a length is cut
  there too), nested at most ``max_json_depth`` levels with at most ``max_json_keys`` keys
  per object (422), and no NUL or bidirectional control characters in any string (422);
- multipart uploads keep their own, larger caps (:mod:`app.storage`).

A pure ASGI middleware: the body of a JSON request is read once (it is small by then)
and handed on unchanged.
"""

from __future__ import annotations

import json
import re
from collections.abc import Awaitable, Callable
from typing import Any

from sbsc_core.errors import InputError
from sbsc_core.io.safe_json import loads_bounded

INT64_MAX = 2**63 - 1
LARGE_BODY = 64 * 1024  # a JSON body above this is checked in a worker thread
_NUMBER = re.compile(r"^[+-]?\d+$")
UPLOAD_PATH = re.compile(r"^/api/projects/[^/]+/(scans|models|design)/?$")  # streamed, own caps
# NUL and the bidirectional controls (U+202A..U+202E, U+2066..U+2069, U+200E/U+200F, U+061C)
_BAD_CHARS = re.compile("[\u0000\u202a-\u202e\u2066-\u2069\u200e\u200f\u061c]")

ASGIApp = Callable[[dict, Callable[[], Awaitable[dict]], Callable[[dict], Awaitable[None]]], Awaitable[None]]


def out_of_int64(text: str) -> bool:
    """True for a decimal integer outside the signed 64-bit range."""
    return bool(_NUMBER.match(text)) and not -INT64_MAX - 1 <= int(text) <= INT64_MAX


def bad_string(value: Any, where: str = "body") -> str | None:
    """Where a NUL / bidi control character hides in a parsed JSON value, or None."""
    stack = [(value, where)]
    while stack:
        v, at = stack.pop()
        if isinstance(v, str):
            m = _BAD_CHARS.search(v)
            if m:
                return f"{at}: contains the control character U+{ord(m.group()):04X}"
        elif isinstance(v, dict):
            for k, x in v.items():
                if _BAD_CHARS.search(k):
                    return f"{at}: a key contains a control character"
                stack.append((x, f"{at}.{k}" if at != "body" else k))
        elif isinstance(v, list):  # (100,000 ids: only what may hold a bad value is looked at)
            for i, x in enumerate(v):
                if isinstance(x, (str, dict, list)) or (type(x) is int and not -INT64_MAX - 1 <= x <= INT64_MAX):
                    stack.append((x, f"{at}[{i}]"))
        elif isinstance(v, int) and not isinstance(v, bool) and not -INT64_MAX - 1 <= v <= INT64_MAX:
            return f"{at}: number out of range (at most {INT64_MAX})"
    return None


async def _send_json(send: Callable[[dict], Awaitable[None]], status: int, detail: str,
                     headers: list[tuple[bytes, bytes]] | None = None) -> None:
    body = json.dumps({"detail": detail}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode()), *(headers or [])]})
    await send({"type": "http.response.body", "body": body})


class BoundsMiddleware:
    """See the module docstring; ``settings`` is the app's :class:`~app.config.AppSettings`."""

    def __init__(self, app: ASGIApp, *, max_body: int, max_depth: int, max_keys: int) -> None:
        self.app, self.max_body, self.max_depth, self.max_keys = app, max_body, max_depth, max_keys

    def _check(self, body: bytes) -> str | None:
        """Why a JSON body is refused (InputError for its shape, a reason for its strings), or None."""
        return bad_string(loads_bounded(body, "body", max_depth=self.max_depth, max_keys=self.max_keys))

    async def __call__(self, scope: dict, receive, send) -> None:  # noqa: ANN001
        if scope["type"] != "http" or not scope["path"].startswith("/api/"):
            await self.app(scope, receive, send)
            return
        for seg in scope["path"].split("/"):
            if out_of_int64(seg):
                await _send_json(send, 404, f"not found: id {seg[:40]} is out of range")
                return
        query = scope.get("query_string", b"").decode("latin-1")
        for pair in filter(None, query.split("&")):
            name, _, value = pair.partition("=")
            if out_of_int64(value):
                await _send_json(send, 422, f"query.{name[:40]}: number out of range (at most {INT64_MAX})")
                return
        headers = dict(scope.get("headers") or [])
        ctype = headers.get(b"content-type", b"").split(b";")[0].strip().lower()
        if scope["method"] in ("GET", "HEAD", "OPTIONS", "DELETE") and not headers.get(b"content-length", b"0") \
                .strip(b"0") and b"transfer-encoding" not in headers:
            await self.app(scope, receive, send)
            return
        if ctype.startswith(b"multipart/") and UPLOAD_PATH.match(scope["path"]):
            await self.app(scope, receive, send)  # uploads: streamed with their own caps
            return
        declared = headers.get(b"content-length", b"")
        if declared.isdigit() and int(declared) > self.max_body:
            await _send_json(send, 413, f"request body too large ({int(declared):,} bytes; "
                                        f"at most {self.max_body:,} for this call)")
            return
        chunks, size, more = [], 0, True
        while more:
            msg = await receive()
            if msg["type"] == "http.disconnect":
                return
            chunk = msg.get("body", b"")
            size += len(chunk)
            if size > self.max_body:
                await _send_json(send, 413, f"request body too large (more than {self.max_body:,} bytes)")
                return
            chunks.append(chunk)
            more = msg.get("more_body", False)
        body = b"".join(chunks)
        if body.strip() and (ctype in (b"application/json", b"") or ctype.endswith(b"+json")) \
                and scope["method"] != "GET":
            try:
                if len(body) > LARGE_BODY:  # parsed and checked in a worker thread, off the event loop
                    import anyio

                    why = await anyio.to_thread.run_sync(self._check, body)
                else:
                    why = self._check(body)
            except InputError as exc:
                await _send_json(send, 422, str(exc))
                return
            if why:
                await _send_json(send, 422, why)
                return
        sent = False

        async def replay() -> dict:
            nonlocal sent
            if not sent:
                sent = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)
