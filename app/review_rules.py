"""The review rules as plain checks, each written once.

The review service (:mod:`app.review_service`, on the database) and the 3D scene's in-memory
backend (:mod:`app.viewer.backend`, for the stand-alone viewer) both decide with these, so a
decision is refused for the same reason, with the same error (:mod:`app.errors`, mapped to
HTTP once in ``app.server``), whichever side it comes from:

- a status is one of ``REVIEW_STATUSES`` (422);
- only a reviewer, manager or admin decides (403);
- nothing changes once the project is signed off (423);
- a change names the ``version`` it was made against (409 when stale).
"""

from __future__ import annotations

from .errors import Forbidden, Invalid, Locked, StaleVersion
from .models import REVIEW_STATUSES, ROLES


def review_score(confidence: float | None, alpha: float | None) -> float | None:
    """How sure recognition is: the calibrated ``confidence`` when there is one, else ``alpha``
    (None for an object a reviewer added). The gallery's order and filter, and the 3D scene's."""
    return confidence if confidence is not None else alpha


def sort_score(d: dict) -> float:
    """:func:`review_score` of a detection dict for sorting: an object without one (added by a
    reviewer) counts 2.0, after every score."""
    score = review_score(d.get("confidence"), d.get("alpha"))
    return 2.0 if score is None else float(score)


def check_status(status: str, where: str = "status") -> None:
    if status not in REVIEW_STATUSES:
        raise Invalid(f"{where}: must be one of {', '.join(REVIEW_STATUSES)}")


def check_may_review(name: str, role: str) -> None:
    """403 unless ``role`` may decide (a project's viewer may not)."""
    if role not in ROLES:
        raise Forbidden(f"{name}: role '{role}' may not review")


def check_open(pid: object, locked: bool, current: dict | None = None) -> None:
    """423 once the project is signed off."""
    if locked:
        raise Locked(f"project {pid} is signed off; it can no longer be changed", current)


def check_version(did: object, given: int, now: int, by: str | None, current: dict | None = None) -> None:
    """409 when a change was made against a version that is no longer the detection's."""
    if int(given) != now:
        raise StaleVersion(f"stale version {given}: detection {did} is at version {now} "
                           f"(last changed by {by or 'nobody'}); reload and decide again", current)


CARRY_TOLERANCE_M = 0.10  # a new detection within this of an old one (or half its size) is the same
