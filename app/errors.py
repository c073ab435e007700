"""The review operations' errors, one set for the REST routes, the review service and the 3D scene.

Each carries the HTTP status the REST API answers and, when known, ``current``: the
detection as it now stands (a stale decision shows the reviewer what changed meanwhile).
"""

from __future__ import annotations


class ReviewError(Exception):
    """A review operation refused; ``status`` is the HTTP code, ``current`` the detection now."""

    status = 400

    def __init__(self, message: str, current: dict | None = None) -> None:
        super().__init__(message)
        self.current = current


class NotFound(ReviewError):
    status = 404


class Forbidden(ReviewError):
    status = 403


class Conflict(ReviewError):
    status = 409


class StaleVersion(Conflict):
    """A decision made against a version that is no longer the detection's."""


class NotReady(Conflict):
    """The project exists but has no detections yet."""


class Invalid(ReviewError):
    status = 422


class Locked(ReviewError):
    """The project is signed off."""

    status = 423
