"""Dependencies shared by the routers: settings, database sessions, the caller and its role."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from sqlalchemy.orm import Session

from ..auth import Principal, authenticate, hash_token
from ..config import AppSettings
from ..db import Database
from ..jobs import JobManager
from ..membership import allows, project_in_path
from ..models import ROLES, Project
from ..sessions import COOKIE as SESSION_COOKIE
from ..sessions import SessionKeeper, principal_of, same_origin
from ..thumbnails import ImageCache


async def get_settings(request: Request) -> AppSettings:
    return request.app.state.settings


async def get_database(request: Request) -> Database:
    return request.app.state.db


async def get_jobs(request: Request) -> JobManager:
    return request.app.state.jobs


async def get_image_cache(request: Request) -> ImageCache:
    return request.app.state.images


def read_session(db: Annotated[Database, Depends(get_database)]) -> Iterator[Session]:
    """A session for reading (its transaction is rolled back at the end).

    Writes never use a dependency: a yield dependency may finish after the response has
    been sent, so endpoints that write commit in ``with db.write()`` before they answer.
    """
    with db.read() as session:
        yield session


Settings = Annotated[AppSettings, Depends(get_settings)]
DB = Annotated[Database, Depends(get_database)]
Jobs = Annotated[JobManager, Depends(get_jobs)]
Images = Annotated[ImageCache, Depends(get_image_cache)]
ReadSession = Annotated[Session, Depends(read_session)]


class TokenCache:
    """Recently verified tokens (by their hash) -> caller, for ``ttl_s`` seconds."""

    def __init__(self, ttl_s: float = 30.0, maxsize: int = 1000) -> None:
        self.ttl_s, self.maxsize = ttl_s, maxsize
        self._items: dict[str, tuple[float, Principal]] = {}
        self._lock = threading.Lock()

    def get(self, token: str) -> Principal | None:
        key = hash_token(token)
        with self._lock:
            hit = self._items.get(key)
        if hit is None or hit[0] < time.monotonic():
            return None
        return hit[1]

    def put(self, token: str, user: Principal) -> None:
        with self._lock:
            if len(self._items) >= self.maxsize:
                self._items.clear()
            self._items[hash_token(token)] = (time.monotonic() + self.ttl_s, user)


def _unauthorized(detail: str) -> HTTPException:
    return HTTPException(401, detail, headers={"WWW-Authenticate": "Bearer"})


async def current_user(request: Request, db: DB) -> Principal:
    """The caller named by ``Authorization: Bearer TOKEN``, else by the browser's session
    cookie (:mod:`app.sessions`); 401 without a valid token or session.

    Valid tokens are remembered for a few seconds (``app.state.auth_cache``) so that a
    busy reviewer does not cost a user lookup per request.
    """
    header = request.headers.get("authorization", "")
    scheme, _, token = header.partition(" ")
    if not header and request.cookies.get(SESSION_COOKIE):
        return await _session_user(request, db)
    if not header:
        raise _unauthorized("missing API token (send 'Authorization: Bearer TOKEN')")
    if scheme.lower() != "bearer" or not token.strip():
        raise _unauthorized("malformed Authorization header (expected 'Bearer TOKEN')")
    cache: TokenCache = request.app.state.auth_cache
    user = cache.get(token.strip())
    if user is None:
        user = await run_in_threadpool(_lookup, db, token.strip())
        if user is None:
            raise _unauthorized("invalid or revoked API token")
        cache.put(token.strip(), user)
    return user


async def _session_user(request: Request, db: Database) -> Principal:
    """The caller of a request that came with the session cookie alone (see app.sessions)."""
    ticket = keeper(request).check(request.cookies[SESSION_COOKIE])
    if ticket is None:
        raise _unauthorized("session expired or ended: log in again")
    if not same_origin(request.method, request.headers, request.headers.get("host")):
        raise HTTPException(403, "a change made with the session cookie must come from this app's pages")

    def lookup() -> Principal | None:
        with db.read() as s:
            return principal_of(s, ticket)

    user = await run_in_threadpool(lookup)
    if user is None:
        raise _unauthorized("session no longer valid (user disabled or token replaced): log in again")
    return user


def _lookup(db: Database, token: str) -> Principal | None:
    with db.read() as s:
        return authenticate(s, token)


PROJECT_KEYS = frozenset({"pid", "jid", "did", "sid"})


def _in_project(db: Database, user: Principal, params: dict) -> Principal:
    with db.read() as s:
        return project_in_path(s, user, params)


def require(role: str) -> Callable[..., Principal]:
    """A dependency that lets callers with ``role`` (or a higher one) through, else 403.

    Under a project (a ``pid``, ``jid``, ``did`` or ``sid`` in the path) the caller must be
    a member (else 404) and its role there is what counts (:mod:`app.membership`).
    """
    if role not in ROLES:
        raise ValueError(role)

    async def check(request: Request, user: Annotated[Principal, Depends(current_user)], db: DB) -> Principal:
        if PROJECT_KEYS & request.path_params.keys():  # 404 outside the caller's projects
            user = await run_in_threadpool(_in_project, db, user, request.path_params)
        if not allows(user, role, request.method):
            raise HTTPException(403, f"user '{user.name}' has role {user.role}; this needs {role}")
        return user

    check.__name__ = f"require_{role}"
    return check


User = Annotated[Principal, Depends(current_user)]
Reviewer = Annotated[Principal, Depends(require("reviewer"))]
Manager = Annotated[Principal, Depends(require("manager"))]
Admin = Annotated[Principal, Depends(require("admin"))]


def get_project(session: Session, pid: int, *, for_update: bool = False) -> Project:
    project = session.get(Project, pid, with_for_update=True if for_update else None)
    if project is None:
        raise HTTPException(404, f"project {pid} not found")
    return project


def keeper(request: Request) -> SessionKeeper:
    """The app's session keeper (made on first use, its key in the data dir)."""
    state = request.app.state
    if getattr(state, "sessions", None) is None:
        state.sessions = SessionKeeper.for_data_dir(state.settings.data_dir)
    return state.sessions
