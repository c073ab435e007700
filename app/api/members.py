"""The members of a project (contract 7, third wave): list, add or change, remove."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from pydantic import BaseModel, Field

from .. import membership
from .deps import DB, Manager, ReadSession, Reviewer, get_project

router = APIRouter(prefix="/api", tags=["projects"])

ERRORS = {403: {"description": "needs an admin or the project's manager"},
          404: {"description": "no such project, user or member"},
          422: {"description": "a role above the user's global role"}}


class NewMember(BaseModel):
    user: str = Field(min_length=1, max_length=100)
    role: str = Field(pattern="^(viewer|reviewer|manager)$")


@router.get("/projects/{pid}/members")
def list_members(pid: int, _: Reviewer, s: ReadSession) -> list[dict]:
    """``[{"user", "role"}]``; admins are members of every project without being listed."""
    get_project(s, pid)
    return membership.members(s, pid)


@router.post("/projects/{pid}/members", status_code=201, responses=ERRORS)
def add_member(pid: int, body: NewMember, user: Manager, db: DB) -> dict:
    """Make a user a member with a role, or change the role of a member (admin or manager)."""
    with db.write() as s:
        try:
            return membership.set_member(s, pid, body.user, body.role, user)
        except LookupError as exc:
            raise HTTPException(404, str(exc)) from None
        except ValueError as exc:
            raise HTTPException(422, str(exc)) from None


@router.delete("/projects/{pid}/members/{user}", responses=ERRORS)
def remove_member(pid: int, user: str, caller: Manager, db: DB) -> dict:
    """End a user's membership (admin or manager)."""
    with db.write() as s:
        try:
            return membership.remove_member(s, pid, user, caller)
        except LookupError as exc:
            raise HTTPException(404, str(exc)) from None
