"""API tokens and roles.

A token is 32 random bytes (URL-safe base64, prefixed ``sbsc_``), shown once when the user
is created. The database keeps only its SHA-256: tokens carry 256 bits of entropy, so a
fast hash suffices (no dictionary to attack) and lookup is a single indexed query.
Roles are ordered: ``reviewer`` < ``manager`` < ``admin``; a role may do what the ones
before it may.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from .models import ROLES, User

TOKEN_PREFIX = "sbsc_"
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._@ -]{0,99}$")


@dataclass(frozen=True)
class Principal:
    """The caller of one request."""

    id: int
    name: str
    role: str

    def may(self, role: str) -> bool:
        levels = ("viewer", *ROLES)  # a project's viewer (app.membership) is below every global role
        return levels.index(self.role) >= levels.index(role)


def new_token() -> str:
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode("utf-8")).hexdigest()


def check_role(role: str) -> str:
    if role not in ROLES:
        raise ValueError(f"role: must be one of {', '.join(ROLES)}, not {role!r}")
    return role


def check_name(name: str) -> str:
    name = name.strip()
    if not NAME_RE.match(name):
        raise ValueError("name: 1-100 letters, digits, '.', '_', '@', '-' or spaces")
    return name


def create_user(session: Session, name: str, role: str) -> tuple[User, str]:
    """Add a user; returns the row and the clear token (never stored)."""
    name, role = check_name(name), check_role(role)
    if session.scalar(select(User.id).where(User.name == name)) is not None:
        raise ValueError(f"user {name!r} already exists")
    token = new_token()
    user = User(name=name, role=role, token_hash=hash_token(token))
    session.add(user)
    session.flush()
    return user, token


def authenticate(session: Session, token: str) -> Principal | None:
    """The user holding ``token``, or None (unknown token, disabled user)."""
    if not token.startswith(TOKEN_PREFIX) or len(token) > 200:
        return None
    digest = hash_token(token)
    user = session.scalar(select(User).where(User.token_hash == digest))
    if user is None or user.disabled or not hmac.compare_digest(user.token_hash, digest):
        return None
    return Principal(id=user.id, name=user.name, role=user.role)


def user_count(session: Session) -> int:
    return int(session.scalar(select(func.count(User.id))) or 0)
