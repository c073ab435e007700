"""JSON with bounds: nesting depth, keys per object and size are checked before recursion.

``json.loads`` recurses once per nesting level (a file of 100,000 ``[`` is a
``RecursionError``) and builds any number of keys. :func:`loads_bounded` scans the text
once for its nesting depth before parsing, refuses ``NaN`` / ``Infinity`` constants and
counts the keys of every object as it is built, so a hostile document is refused with a
one-line :class:`~sbsc_core.errors.InputError` rather than a traceback or a large
allocation.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from ..errors import InputError

MAX_DEPTH = 32  # documents of contracts 2-5 nest 4 levels deep
MAX_KEYS = 10_000  # keys of one JSON object
MAX_BYTES = 256 * 1024 * 1024  # a JSON input file

_TOKENS = re.compile(r'"(?:[^"\\]|\\.)*"|[\[\]{}]')


def json_depth(text: str, limit: int) -> int:
    """The nesting depth of ``text`` (strings skipped), stopping once it exceeds ``limit``."""
    depth = deepest = 0
    for m in _TOKENS.finditer(text):
        c = m.group()[0]
        if c in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > limit:
                    return deepest
        elif c in "]}":
            depth -= 1
    return deepest


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


def _pairs_hook(max_keys: int):  # noqa: ANN202
    def hook(pairs: list[tuple[str, Any]]) -> dict:
        if len(pairs) > max_keys:
            raise ValueError(f"an object has {len(pairs):,} keys (at most {max_keys:,} allowed)")
        return dict(pairs)
    return hook


def loads_bounded(text: str | bytes, where: object, *, max_depth: int = MAX_DEPTH,
                  max_keys: int = MAX_KEYS) -> Any:
    """Parse JSON ``text``; InputError(where, reason) when it is invalid or beyond the bounds."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(where, "not UTF-8 text") from None
    if json_depth(text, max_depth) > max_depth:
        raise InputError(where, f"JSON nested deeper than {max_depth} levels")
    try:
        return json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_pairs_hook(max_keys))
    except json.JSONDecodeError as exc:
        raise InputError(where, f"invalid JSON (line {exc.lineno} column {exc.colno}: {exc.msg})") from None
    except (ValueError, RecursionError) as exc:
        raise InputError(where, f"invalid JSON ({exc})") from None


def load_json_file(path: Path | str, *, max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH,
                   max_keys: int = MAX_KEYS) -> Any:
    """Read and parse a JSON file within the bounds; InputError naming the file otherwise."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such file")
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise InputError(path, f"too large for a JSON document ({size:,} bytes; "
                                   f"at most {max_bytes:,})")
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror or exc})") from None
    return loads_bounded(data, path, max_depth=max_depth, max_keys=max_keys)
