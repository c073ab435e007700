"""``GET /api/projects/{pid}/viewer``: where a project's 3D review scene is.

The app mounts the router::

    from app.viewer.api import viewer_router
    app.include_router(viewer_router(lambda request: request.app.state.viewer, require_user))

``manager`` is the :class:`ViewerManager`, or a function of the request that returns it
(when the manager is made in the app's lifespan). ``auth_dependency`` is the app's FastAPI
dependency that checks the bearer token and answers the caller. When the manager has a
:class:`~app.viewer.gate.ViewerGate`, the answer also sets the viewer cookie (HttpOnly,
SameSite=Strict): the scene then knows the caller without a second login.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request, Response

from .backend import ReviewError
from .gate import cookie_name
from .manager import ViewerManager

ManagerSource = ViewerManager | Callable[[Request], ViewerManager]


def viewer_router(manager: ManagerSource, auth_dependency: Callable[..., Any]) -> APIRouter:
    """A router with ``GET /api/projects/{pid}/viewer`` answering ``{"url", "ready"}``."""
    router = APIRouter(tags=["viewer"])

    def get_manager(request: Request) -> ViewerManager:
        return manager if isinstance(manager, ViewerManager) else manager(request)

    @router.get("/api/projects/{pid}/viewer", summary="Address of the project's 3D review scene",
                responses={404: {"description": "no such project"},
                           409: {"description": "no detections yet"}})
    def project_viewer(pid: int, request: Request, response: Response,
                       user: Any = Depends(auth_dependency)) -> dict:  # noqa: B008 - a closure's dependency
        """Start the project's 3D scene if needed and answer its address.

        ``url`` opens as it is in a browser (or an ``<iframe>``); ``ready`` is false while
        the scene is still being built (the page then says so and fills in by itself).
        """
        m = get_manager(request)
        try:
            url = m.url_for(pid, request_host=request.url.hostname)
        except ReviewError as exc:
            raise HTTPException(exc.status, str(exc)) from None
        if m.gate is not None and hasattr(user, "id"):
            response.set_cookie(cookie_name(pid), m.gate.issue(user.id, user.name, user.role, project=pid),
                                max_age=int(m.gate.ttl_s), httponly=True, samesite="strict",
                                secure=request.url.scheme == "https", path="/")
        return {"url": url, "ready": m.scene_for(pid).ready.is_set()}

    return router
