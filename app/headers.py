"""Security headers on every response (issue 30): a Content-Security-Policy, no framing,
no MIME sniffing, no referrer.

The pages keep their scripts inline: the policy allows exactly those scripts by their
SHA-256 (computed from ``app/static/*.html`` when the app is made), and no other inline
script. Styles may be inline (the pages use ``style`` attributes). Images may be ``blob:``
URLs (thumbnails fetched with the API token) and the comparison report opens as a blob.
The 3D scenes are served by their own viser servers on other ports, not by this app: the
pages open them in a new tab (never in a frame), and those servers send :data:`SCENE_HEADERS`.
"""

from __future__ import annotations

import base64
import hashlib
import re
from pathlib import Path

from starlette.types import ASGIApp, Message, Receive, Scope, Send

_INLINE_SCRIPT = re.compile(r"<script(?![^>]*\bsrc\s*=)[^>]*>(.*?)</script>", re.S | re.I)


# The 3D scenes' own viser servers (app.viewer.gate): no framing, no sniffing, no referrer, and a
# policy that forbids being framed, plugins and other bases without restricting viser's own client.
SCENE_HEADERS = (
    ("Content-Security-Policy", "frame-ancestors 'none'; object-src 'none'; base-uri 'self'"),
    ("X-Frame-Options", "DENY"),
    ("X-Content-Type-Options", "nosniff"),
    ("Referrer-Policy", "no-referrer"),
)


def inline_script_hashes(static_dir: Path) -> list[str]:
    """``'sha256-...'`` of every inline script of the pages in ``static_dir``."""
    out: set[str] = set()
    for page in sorted(static_dir.glob("*.html")) if static_dir.is_dir() else ():
        for body in _INLINE_SCRIPT.findall(page.read_text(encoding="utf-8")):
            digest = base64.b64encode(hashlib.sha256(body.encode("utf-8")).digest()).decode()
            out.add(f"'sha256-{digest}'")
    return sorted(out)


def content_security_policy(script_hashes: list[str]) -> str:
    return "; ".join([
        "default-src 'self'",
        "script-src 'self' " + " ".join(script_hashes),
        "style-src 'self' 'unsafe-inline'",
        "img-src 'self' data: blob:",
        "connect-src 'self'",
        "frame-src 'self' blob:",
        "object-src 'none'",
        "base-uri 'self'",
        "form-action 'self'",
        "frame-ancestors 'none'",
    ])


class SecurityHeadersMiddleware:
    """Adds the security headers to every HTTP response (pure ASGI: streams pass through)."""

    def __init__(self, app: ASGIApp, *, static_dir: Path) -> None:
        self.app = app
        self.headers = [
            (b"content-security-policy", content_security_policy(inline_script_hashes(static_dir)).encode()),
            (b"x-frame-options", b"DENY"),
            (b"x-content-type-options", b"nosniff"),
            (b"referrer-policy", b"no-referrer"),
        ]
        self._names = {name for name, _ in self.headers}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                kept = [(k, v) for k, v in message.get("headers", []) if k.lower() not in self._names]
                message = {**message, "headers": kept + self.headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)
