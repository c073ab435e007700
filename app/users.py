"""``sbsc user add NAME --role ROLE``: create a user in the app's database, print its token once."""

from __future__ import annotations

from sbsc_core.errors import InputError

from .auth import create_user
from .config import AppSettings
from .db import Database, upgrade


def add_user(settings: AppSettings, name: str, role: str) -> str:
    """Create the user; returns the clear token. Raises InputError (bad name, role, duplicate)."""
    settings.ensure_dirs()
    db = Database(settings.db_url)
    try:
        upgrade(db)
        with db.write() as s:
            try:
                _, token = create_user(s, name, role)
            except ValueError as exc:
                raise InputError("sbsc user add", str(exc)) from None
    finally:
        db.dispose()
    return token


def add_user_cli(name: str, role: str) -> str:
    """The text ``sbsc user add`` prints: who was created and the token, shown this once."""
    settings = AppSettings()
    token = add_user(settings, name, role)
    return (f"created user '{name.strip()}' with role {role} in {settings.db_url}\n"
            f"API token (shown only now; keep it secret):\n{token}")


def change_member_cli(name: str, project: int, role: str | None) -> str:
    """``sbsc user add-member`` (with ``role``) / ``remove-member`` (without): the text it prints.

    Raises InputError for an unknown user or project, or a role above the user's global role.
    """
    from . import membership

    settings = AppSettings()
    settings.ensure_dirs()
    db = Database(settings.db_url)
    what = "sbsc user add-member" if role else "sbsc user remove-member"
    try:
        upgrade(db)
        with db.write() as s:
            try:
                if role:
                    got = membership.set_member(s, project, name, role, None)
                else:
                    got = membership.remove_member(s, project, name, None)
            except (LookupError, ValueError) as exc:
                raise InputError(what, str(exc).strip("'\"")) from None
    finally:
        db.dispose()
    if role:
        return f"user '{got['user']}' is now {role} of project {project}"
    return f"user '{got['user']}' is no longer a member of project {project}"
