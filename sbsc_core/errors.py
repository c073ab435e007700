"""Errors that the command line and the web API turn into one-line messages."""

from __future__ import annotations


class SbscError(Exception):
    """Base class: the message is a single line that names the file or field and the reason."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))


class InputError(SbscError):
    """Bad user input: a file or a field that cannot be used.

    ``InputError("scan.ply", "no colour")`` reads ``scan.ply: no colour``. The CLI turns it
    into exit code 2, the review app into an HTTP 4xx.

    Parameters
    ----------
    where
        The file or field at fault (a path, an option, a JSON field).
    reason
        What is wrong with it, in a few words.
    """

    def __init__(self, where: object, reason: str) -> None:
        self.where = str(where)
        self.reason = reason
        super().__init__(f"{where}: {reason}")


class NoWallsError(SbscError):
    """The scan was readable but no wall could be segmented from it."""
