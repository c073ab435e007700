"""Slow clients time out (issue 30): a request's headers must arrive within a deadline, and a
body that stops arriving is dropped after an idle time.

uvicorn bounds the idle time between requests (``timeout_keep_alive``), the open connections
and tasks (``limit_concurrency``: 503 beyond) and the size of the headers
(``h11_max_incomplete_event_size``), but nothing bounds the time to *read* a request: a
client that sends half its headers, or half its body, holds its connection for ever. Its
HTTP protocol is therefore used here with two timers (:class:`TimedH11Protocol`):

- headers: from the moment a connection opens (or the next request starts on a kept-alive
  one), the request line and headers must be complete within ``header_timeout_s``, however
  slowly they trickle in (a 408 answers, then the connection closes);
- body: while a body is being received, ``body_idle_s`` without a byte closes the connection
  (the endpoint sees the client go away). Time during which the server itself stopped
  reading (flow control: the endpoint has not taken the last chunk yet) does not count, so
  a large upload at any steady speed is never cut.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol


class TimedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with a header deadline and a body idle limit (class attributes)."""

    header_timeout_s: float = 10.0
    body_idle_s: float = 30.0

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._read_timer: asyncio.TimerHandle | None = None
        self._reading_headers = False
        self._update()

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        self._update(data_came=True)

    def on_response_complete(self) -> None:
        super().on_response_complete()  # uvicorn's keep-alive timer now waits for the next request
        self._stop_timer()

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_timer()
        super().connection_lost(exc)

    # -- the timers ----------------------------------------------------------------------
    def _stop_timer(self) -> None:
        if getattr(self, "_read_timer", None) is not None:
            self._read_timer.cancel()
        self._read_timer = None
        self._reading_headers = False

    def _update(self, data_came: bool = False) -> None:
        """Set the timer for the state the client is in after what it sent."""
        if self.transport.is_closing():
            self._stop_timer()
            return
        state = self.conn.their_state
        if state is h11.IDLE and self.conn.our_state is h11.IDLE:
            # (a new connection, or bytes of the next request) the headers' deadline runs
            # from their first moment and is not pushed back by each byte that trickles in
            if not self._reading_headers and (data_came or self.timeout_keep_alive_task is None):
                self._stop_timer()
                self._reading_headers = True
                self._read_timer = self.loop.call_later(self.header_timeout_s, self._headers_late)
        elif state is h11.SEND_BODY:
            self._stop_timer()
            self._read_timer = self.loop.call_later(self.body_idle_s, self._body_idle)
        else:
            self._stop_timer()

    def _headers_late(self) -> None:
        self._read_timer = None
        if self.transport.is_closing() or self.conn.their_state is not h11.IDLE:
            return
        detail = f"request headers not received within {self.header_timeout_s:g} s"
        body = json.dumps({"detail": detail}).encode()
        self.transport.write(b"HTTP/1.1 408 Request Timeout\r\ncontent-type: application/json\r\n"
                             b"connection: close\r\ncontent-length: " + str(len(body)).encode() + b"\r\n\r\n" + body)
        self.transport.close()

    def _body_idle(self) -> None:
        self._read_timer = None
        if self.transport.is_closing() or self.conn.their_state is not h11.SEND_BODY:
            return
        if self.flow.read_paused:  # the server is not reading: not the client's delay
            self._read_timer = self.loop.call_later(self.body_idle_s, self._body_idle)
            return
        self.logger.info("closed a connection whose request body stopped for %g s", self.body_idle_s)
        self.transport.close()


def timed_protocol(header_timeout_s: float, body_idle_s: float) -> type[TimedH11Protocol]:
    """The protocol class for ``uvicorn.run(http=...)`` with these limits."""
    return type("SbscH11Protocol", (TimedH11Protocol,),
                {"header_timeout_s": float(header_timeout_s), "body_idle_s": float(body_idle_s)})


def uvicorn_options(settings: Any) -> dict[str, Any]:
    """uvicorn's own limits and the timed protocol, from the app's settings."""
    return {"http": timed_protocol(settings.http_header_timeout_s, settings.http_body_idle_s),
            "timeout_keep_alive": settings.http_keep_alive_s,
            "limit_concurrency": settings.http_limit_concurrency,
            "h11_max_incomplete_event_size": settings.http_max_header_bytes,
            "backlog": settings.http_backlog}
