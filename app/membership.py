"""Projects belong to their members (contract 7, third wave).

Each member has a role in the project: ``viewer`` (reads), ``reviewer`` (also decides),
``manager`` (also signs off, cancels jobs, manages the members). A user's global role is
the most they may be given in any project; admins are members of every project with
their own role. A project the caller is not a member of does not exist for them: every
route under it answers 404, as for an unknown id (:func:`project_in_path`).

Changes of membership are audited as project events (``member_added``,
``member_changed``, ``member_removed``).
"""

from __future__ import annotations

from collections.abc import Mapping

from fastapi import HTTPException
from sqlalchemy import select
from sqlalchemy.orm import Session

from .auth import Principal
from .models import (
    DetectionRow,
    Job,
    Project,
    ProjectEvent,
    ProjectMember,
    SuggestionRow,
    User,
    utcnow,
)

PROJECT_ROLES: tuple[str, ...] = ("viewer", "reviewer", "manager")
LEVELS: tuple[str, ...] = ("viewer", "reviewer", "manager", "admin")  # each may what the ones before may
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})

# path parameter -> (table, its project column, what a 404 calls it)
_OWNED = {"pid": (Project, Project.id, "project"), "jid": (Job, Job.project_id, "job"),
          "did": (DetectionRow, DetectionRow.project_id, "detection"),
          "sid": (SuggestionRow, SuggestionRow.project_id, "suggestion")}


def capped(role: str, cap: str) -> str:
    """The lower of two roles (a project role capped by the user's global role)."""
    return role if LEVELS.index(role) <= LEVELS.index(cap) else cap


def project_role(s: Session, user: Principal, pid: int) -> str | None:
    """The caller's role in project ``pid`` (``admin`` for admins), None for a non-member."""
    if user.role == "admin":
        return "admin"
    role = s.scalar(select(ProjectMember.role).where(ProjectMember.project_id == pid,
                                                     ProjectMember.user_id == user.id))
    return None if role is None else capped(role, user.role)


def project_of_path(s: Session, params: Mapping[str, str]) -> tuple[int, str, str] | None:
    """``(project id, kind, key)`` of the first project-owned id in a route's path
    parameters; None when there is none or it names nothing (the route answers its own 404)."""
    for key, (table, column, kind) in _OWNED.items():
        raw = params.get(key)
        if raw is None:
            continue
        try:
            ident = int(raw)
        except ValueError:
            return None
        if not -2**63 <= ident < 2**63:
            return None
        pid = s.scalar(select(column).where(table.id == ident))
        return None if pid is None else (int(pid), kind, raw)
    return None


def project_in_path(s: Session, user: Principal, params: Mapping[str, str]) -> Principal:
    """The caller as seen in the project the path names, its role capped by the project role.

    Raises 404, worded as for an unknown id, when the caller is not a member. A path that
    names no project answers the caller unchanged.
    """
    found = project_of_path(s, params)
    if found is None:
        return user
    pid, kind, key = found
    role = project_role(s, user, pid)
    if role is None:
        raise HTTPException(404, f"{kind} {key} not found")
    return user if role == user.role else Principal(id=user.id, name=user.name, role=role)


def allows(user: Principal, needed: str, method: str) -> bool:
    """Whether ``user`` (a project-capped caller) may do what needs ``needed``.

    Reading (GET) needs only to be a member: the routes that read ask for ``reviewer``,
    the lowest global role, and a project's viewers read too.
    """
    if method.upper() in SAFE_METHODS and needed == "reviewer":
        return True
    return LEVELS.index(user.role) >= LEVELS.index(needed)


def member_ids(s: Session, user: Principal) -> list[int] | None:
    """The projects ``user`` may see; None for all of them (an admin)."""
    if user.role == "admin":
        return None
    return list(s.scalars(select(ProjectMember.project_id).where(ProjectMember.user_id == user.id)))


def members(s: Session, pid: int) -> list[dict]:
    """``[{"user", "role"}]`` of a project, by name (admins are members without being listed)."""
    rows = s.execute(select(User.name, ProjectMember.role, User.role).join(User, User.id == ProjectMember.user_id)
                     .where(ProjectMember.project_id == pid).order_by(User.name))
    return [{"user": name, "role": capped(role, cap)} for name, role, cap in rows]


def _user(s: Session, name: str) -> User:
    user = s.scalar(select(User).where(User.name == name.strip()))
    if user is None:
        raise LookupError(f"user {name.strip()!r} not found")
    return user


def _event(s: Session, pid: int, by: Principal | None, kind: str, data: dict) -> None:
    s.add(ProjectEvent(project_id=pid, user_id=by.id if by else None,
                       user_name=by.name if by else "sbsc user (command line)", at=utcnow(),
                       kind=kind, data=data))


def set_member(s: Session, pid: int, name: str, role: str, by: Principal | None) -> dict:
    """Make user ``name`` a member of project ``pid`` with ``role`` (or change its role).

    Raises LookupError for an unknown user or project, ValueError for a role not in
    :data:`PROJECT_ROLES` or above the user's global role.
    """
    if role not in PROJECT_ROLES:
        raise ValueError(f"role: must be one of {', '.join(PROJECT_ROLES)}, not {role!r}")
    if s.get(Project, pid) is None:
        raise LookupError(f"project {pid} not found")
    user = _user(s, name)
    if LEVELS.index(role) > LEVELS.index(user.role):
        raise ValueError(f"user '{user.name}' has the global role {user.role}; "
                         f"a project role may be at most that, not {role}")
    row = s.scalar(select(ProjectMember).where(ProjectMember.project_id == pid,
                                               ProjectMember.user_id == user.id))
    if row is None:
        s.add(ProjectMember(project_id=pid, user_id=user.id, role=role,
                            added_by=by.name if by else None))
        _event(s, pid, by, "member_added", {"user": user.name, "role": role})
    elif row.role != role:
        _event(s, pid, by, "member_changed", {"user": user.name, "role": role, "was": row.role})
        row.role = role
    s.flush()
    return {"user": user.name, "role": role}


def remove_member(s: Session, pid: int, name: str, by: Principal | None) -> dict:
    """End user ``name``'s membership of project ``pid``; LookupError when it is not a member."""
    if s.get(Project, pid) is None:
        raise LookupError(f"project {pid} not found")
    user = _user(s, name)
    row = s.scalar(select(ProjectMember).where(ProjectMember.project_id == pid,
                                               ProjectMember.user_id == user.id))
    if row is None:
        raise LookupError(f"user '{user.name}' is not a member of project {pid}")
    _event(s, pid, by, "member_removed", {"user": user.name, "was": row.role})
    s.delete(row)
    s.flush()
    return {"user": user.name, "removed": True}


def add_creator(s: Session, project: Project, user: Principal) -> None:
    """The user who creates a project is its manager (at most their global role)."""
    if user.role == "admin":
        return
    s.add(ProjectMember(project_id=project.id, user_id=user.id, role=capped("manager", user.role),
                        added_by=user.name))
