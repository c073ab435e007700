"""The review app: FastAPI application, start-up and shutdown, ``sbsc serve``.

Start-up migrates the database (Alembic), empties the scratch directory, fails the jobs a
previous server left running and starts the job supervisor; shutdown stops the workers.
The pages in ``app/static/`` are served at ``/``, the API under ``/api``.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import webbrowser
from collections.abc import AsyncIterator

import anyio
from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles
from sqlalchemy.exc import DBAPIError

from sbsc_core.errors import InputError, SbscError

from .api.deps import TokenCache
from .bounds import BoundsMiddleware
from .config import AppSettings
from .db import Database, upgrade
from .errors import ReviewError
from .failures import DISK_FULL, disk_full
from .headers import SecurityHeadersMiddleware
from .jobs import JobManager
from .openapi import allowed_methods, truthful_openapi
from .slow_clients import uvicorn_options
from .storage import clean_tmp, sweep_orphans
from .thumbnails import ImageCache

log = logging.getLogger("sbsc.server")


def _sweep(settings: AppSettings, db: Database) -> list:
    from sqlalchemy import select

    from .models import Job, ModelLibraryRow, Scan

    with db.read() as s:
        scans = set(s.scalars(select(Scan.path)))
        models = set(s.scalars(select(ModelLibraryRow.path)))
        jobs = set(s.scalars(select(Job.id)))
    return sweep_orphans(settings.projects_dir, settings.data_dir, scans, models, jobs)


def reap_orphans(settings: AppSettings) -> None:
    """Kill the job processes a crashed server left behind (``<data>/run/*.pgid``)."""
    from .job_processes import GroupFiles

    killed = GroupFiles(settings.data_dir).reap_all()
    if killed:
        log.warning("killed %d orphaned job process(es) left by a previous server", killed)


def _validation_detail(exc: RequestValidationError) -> str:
    """A one-line message from pydantic's error list: ``body.status: Input should be ...``."""
    parts = []
    for err in exc.errors()[:3]:
        loc = ".".join(str(x) for x in err.get("loc", ()) if x != "body") or "body"
        parts.append(f"{loc}: {err.get('msg', 'invalid')}")
    return "; ".join(parts) or "invalid request"


def create_app(settings: AppSettings | None = None, *, start_jobs: bool = True) -> FastAPI:
    """The application; ``settings`` default to the environment (``SBSC_*``)."""
    settings = settings or AppSettings()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        # Few threads for the blocking endpoints: SQLite writes are serialized anyway, and
        # fewer runnable threads means the one holding the write lock gets the GIL sooner.
        anyio.to_thread.current_default_thread_limiter().total_tokens = settings.threads
        settings.ensure_dirs()
        reap_orphans(settings)  # before the database: a frozen orphan may hold its lock
        db = Database(settings.db_url)
        upgrade(db)
        removed = clean_tmp(settings.tmp_dir)
        orphans = _sweep(settings, db)
        if removed or orphans:
            log.info("removed %d partial upload(s) and %d unreferenced file(s) left by a previous run",
                     removed, len(orphans))
        jobs = JobManager(settings, db)
        app.state.settings, app.state.db, app.state.jobs = settings, db, jobs
        app.state.images = ImageCache()
        app.state.bundled_classes = None
        app.state.auth_cache = TokenCache()
        app.state.viewer = _viewer_manager(settings, db) if settings.viewer else None
        if start_jobs:
            jobs.start()
        else:
            jobs.recover()
        try:
            yield
        finally:
            jobs.stop()
            if app.state.viewer is not None:
                app.state.viewer.stop_all()
            db.dispose()

    app = FastAPI(title="sbsc review", version="1.0",
                  description="Review of scan-to-BIM recognition results (contract 7).",
                  lifespan=lifespan)

    @app.exception_handler(RequestValidationError)
    async def _on_validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        return JSONResponse({"detail": _validation_detail(exc)}, status_code=422)

    @app.exception_handler(ReviewError)
    async def _on_review_error(_: Request, exc: ReviewError) -> JSONResponse:
        # the one mapping of the review rules (app.errors: 403, 404, 409, 422, 423) to HTTP;
        # a stale decision also shows the detection as it now stands
        content = {"detail": str(exc)} if exc.current is None else {"detail": str(exc), "current": exc.current}
        return JSONResponse(content, status_code=exc.status)

    @app.exception_handler(SbscError)
    async def _on_sbsc_error(_: Request, exc: SbscError) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=422)

    @app.exception_handler(OverflowError)
    async def _on_overflow(_: Request, exc: OverflowError) -> JSONResponse:
        # a number beyond what the database stores (64-bit) that the bounds did not catch
        return JSONResponse({"detail": "a number in the request is out of range (at most 2**63-1)"},
                            status_code=422)

    async def _on_disk_full(_: Request, exc: Exception) -> JSONResponse:
        # a full disk (a file, the database) is a 507 the client can act on, never a 500
        if not disk_full(exc):
            raise exc
        log.warning("refused a request: %s", exc)
        return JSONResponse({"detail": DISK_FULL}, status_code=507)

    app.add_exception_handler(OSError, _on_disk_full)
    app.add_exception_handler(DBAPIError, _on_disk_full)

    app.add_middleware(BoundsMiddleware, max_body=settings.max_json_body_bytes,
                       max_depth=settings.max_json_depth, max_keys=settings.max_json_keys)
    app.add_middleware(SecurityHeadersMiddleware, static_dir=settings.static_dir)  # outermost: every answer

    from .api import design, export, jobs, members, projects, review, session, teach, uploads

    for module in (projects, uploads, jobs, review, export, design, session, members, teach):
        app.include_router(module.router)

    if settings.viewer:
        _include_viewer(app)

    @app.api_route("/api/{path:path}", methods=["GET", "POST", "PATCH", "PUT", "DELETE", "HEAD", "OPTIONS"],
                   include_in_schema=False)
    def _api_not_found(path: str, request: Request) -> JSONResponse:
        allowed = allowed_methods(app, request.url.path)
        if allowed:
            return JSONResponse({"detail": f"method {request.method} not allowed on /api/{path}"},
                                status_code=405, headers={"Allow": ", ".join(sorted(allowed))})
        raise HTTPException(404, f"no such API endpoint: /api/{path}")

    app.openapi = lambda: truthful_openapi(app)

    @app.get("/", include_in_schema=False)
    def _index() -> RedirectResponse:
        return RedirectResponse("/index.html")

    if settings.static_dir.is_dir():
        app.mount("/", StaticFiles(directory=settings.static_dir, html=True), name="static")
    return app


def _viewer_manager(settings: AppSettings, db: Database):  # noqa: ANN202
    """The 3D review scenes (``app.viewer``): one viser server per project, started on demand."""
    try:
        from .viewer.db_backend import DbReviewBackend
        from .viewer.manager import ViewerManager
    except ImportError as exc:  # viser missing: the REST app works without the 3D view
        log.warning("3D viewer unavailable: %s", exc)
        return None
    from .viewer.gate import ViewerGate

    return ViewerManager(DbReviewBackend(db, settings), host=settings.viewer_host, gate=ViewerGate(),
                         idle_s=settings.viewer_idle_s,
                         idle_check_s=max(1.0, min(30.0, settings.viewer_idle_s / 4)))


def _viewer_of(request: Request):  # noqa: ANN202
    """The ViewerManager the lifespan made (503 when the 3D view is unavailable)."""
    manager = getattr(request.app.state, "viewer", None)
    if manager is None:
        raise HTTPException(503, "the 3D viewer is not available on this server")
    return manager


def _include_viewer(app: FastAPI) -> None:
    try:
        from .viewer.api import viewer_router
    except ImportError as exc:
        log.warning("3D viewer unavailable: %s", exc)
        return
    from .api.deps import require

    app.include_router(viewer_router(_viewer_of, require("reviewer")))


def first_run(settings: AppSettings) -> str | None:
    """Create the user 'admin' if the database has none; returns its token (else None)."""
    from .auth import create_user, user_count

    if not settings.create_admin_on_first_run:
        return None
    db = Database(settings.db_url)
    try:
        upgrade(db)
        with db.write() as s:
            if user_count(s):
                return None
            _, token = create_user(s, "admin", "admin")
            return token
    finally:
        db.dispose()


def start_page(settings: AppSettings) -> str:
    """The sample project's gallery when there is one, else the project list."""
    from .sample import find_sample_project

    pid = find_sample_project(settings)
    return f"/review.html?id={pid}" if pid is not None else "/index.html"


def refuse_busy_port(host: str, port: int) -> None:
    """Raise InputError (one line) when ``host:port`` cannot be listened on, before any work.

    Binds a probe socket the way uvicorn will (``SO_REUSEADDR``, so a port in TIME_WAIT
    counts as free) and closes it at once; port 0 (any free port) is never busy.
    """
    import errno
    import socket

    if port == 0:
        return
    family = socket.AF_INET6 if ":" in host else socket.AF_INET  # as uvicorn binds it
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host.strip("[]"), port))
        except socket.gaierror as exc:
            raise InputError("--host", f"cannot listen on '{host}' ({exc.strerror})") from None
        except OSError as exc:
            why = "is busy (another program listens on it)" if exc.errno == errno.EADDRINUSE \
                else f"cannot be listened on ({exc.strerror})"
            raise InputError("--port", f"port {port} on {host} {why}; choose another with "
                                       "--port P (0 picks a free one)") from None


def serve(host: str = "127.0.0.1", port: int = 8000, open_browser: bool = False) -> None:
    """``sbsc serve``: run the app with uvicorn until interrupted.

    A busy port is refused first, in one line (exit 2), before the data folder is touched.
    """
    from urllib.parse import quote

    import uvicorn

    refuse_busy_port(host, port)
    settings = AppSettings()
    settings.ensure_dirs()
    reap_orphans(settings)
    base = f"http://{'localhost' if host in ('127.0.0.1', '0.0.0.0', '::') else host}:{port}"
    token = first_run(settings)
    page = start_page(settings)
    print(f"sbsc review app: {base}{page}  (data: {settings.data_dir})")
    if token:
        print("First run: created user 'admin' (role admin). Its API token, shown only this once:\n\n"
              f"    {token}\n\nPaste it on the login page.")
    print("More users: sbsc user add NAME --role reviewer|manager|admin", flush=True)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if open_browser:
        url = f"{base}/index.html?next={quote(page)}" + (f"#token={token}" if token else "")
        threading.Timer(1.5, lambda: webbrowser.open(url)).start()
    try:
        uvicorn.run(create_app(settings), host=host, port=port, log_level="info",
                    timeout_graceful_shutdown=10, **uvicorn_options(settings))  # slow clients time out
    except KeyboardInterrupt:
        pass
    sys.stdout.flush()
