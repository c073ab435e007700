"""``/api/session``: the browser's session after the token login (see :mod:`app.sessions`)."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from sqlalchemy import select

from ..models import User
from ..sessions import COOKIE
from .deps import ReadSession, Reviewer, Settings, keeper

router = APIRouter(prefix="/api", tags=["users"])




@router.post("/session", summary="Start a browser session (sets the HttpOnly session cookie)")
def start_session(request: Request, response: Response, user: Reviewer, s: ReadSession,
                  settings: Settings) -> dict:
    """Called once after the token login: the cookie then signs in every tab and the 3D scene."""
    k = keeper(request)
    token_hash = s.scalar(select(User.token_hash).where(User.id == user.id)) or ""
    response.set_cookie(COOKIE, k.issue(user.id, token_hash), max_age=int(k.ttl_s), httponly=True,
                        samesite="strict", secure=request.url.scheme == "https", path="/")
    return {"id": user.id, "name": user.name, "role": user.role, "expires_in_s": int(k.ttl_s)}


@router.delete("/session", summary="Log out: end the browser session and clear its cookie")
def end_session(request: Request, response: Response) -> dict:
    value = request.cookies.get(COOKIE)
    if value:
        keeper(request).end(value)
    response.delete_cookie(COOKIE, path="/", httponly=True, samesite="strict")
    return {"ended": bool(value)}
