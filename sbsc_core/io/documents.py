"""JSON documents of contracts 3-5: expected counts, detections and ground truth.

Readers check every field they use (detections: the pydantic models of
:mod:`.detections_model`, the one validation path of contract 4) and raise :class:`~sbsc_core.errors.InputError`
naming the file and the field, e.g. ``truth.json: objects[3].position: expected 3
numbers``. Unknown extra keys are accepted (and kept) everywhere, so that documents
from newer writers or from the web API (``review``) still read.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..types import Detection, Opening, WallFrame
from .atomic import write_json_atomic
from .detections_model import COORD_MAX, DETECTIONS_SCHEMA, LOCAL_MAX, SIZE_MAX, validate_detections
from .safe_json import load_json_file

EXPECTED_SCHEMA = "sbsc.expected/1"
TRUTH_SCHEMA = "sbsc.truth/1"
CLASS_ID_RE = re.compile(r"^[a-z0-9_]+$")


@dataclass
class TruthObject:
    """One object of a ground-truth document (contract 5)."""

    class_id: str
    position: np.ndarray  # (3,) world, centre of the footprint on the wall plane
    normal: np.ndarray  # (3,) into the room
    width_m: float
    height_m: float
    wall: str | None = None
    u: float | None = None
    v: float | None = None
    extra: dict = field(default_factory=dict)


@dataclass
class TruthDocument:
    """A ground-truth document: objects, plus walls/openings kept as plain dicts."""

    objects: list[TruthObject]
    walls: list[dict] = field(default_factory=list)
    openings: list[dict] = field(default_factory=list)
    extra: dict = field(default_factory=dict)  # other top-level keys (scenario, seed, ...)


# --------------------------------------------------------------------------- field checks


class _Checker:
    """Field validators that raise InputError(file, "field: reason")."""

    def __init__(self, label: str) -> None:
        self.label = label

    def fail(self, where: str, reason: str) -> InputError:
        return InputError(self.label, f"{where}: {reason}" if where else reason)

    def obj(self, value: Any, where: str) -> dict:
        if not isinstance(value, dict):
            raise self.fail(where, "expected a JSON object")
        return value

    def lst(self, value: Any, where: str) -> list:
        if not isinstance(value, list):
            raise self.fail(where, "expected a list")
        return value

    def key(self, d: dict, key: str, where: str) -> Any:
        if key not in d:
            raise self.fail(where, f"missing key '{key}'")
        return d[key]

    def number(self, value: Any, where: str, *, positive: bool = False, nullable: bool = False,
               lo: float | None = None, hi: float | None = None) -> float | None:
        if value is None and nullable:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self.fail(where, f"expected a number{' or null' if nullable else ''}, got {_show(value)}")
        if positive and value <= 0:
            raise self.fail(where, f"must be > 0, got {_show(value)}")
        if positive and value > SIZE_MAX:
            raise self.fail(where, f"must be at most {SIZE_MAX:g}, got {_show(value)}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.fail(where, f"must be between {lo:g} and {hi:g}, got {_show(value)}")
        return float(value)

    def vec3(self, value: Any, where: str) -> np.ndarray:
        if (not isinstance(value, list) or len(value) != 3
                or any(isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x)
                       for x in value)):
            raise self.fail(where, f"expected 3 numbers, got {_show(value)}")
        if any(abs(x) > COORD_MAX for x in value):
            raise self.fail(where, f"coordinates must lie within ±{COORD_MAX:g} m, got {_show(value)}")
        return np.asarray(value, dtype=np.float64)

    def string(self, value: Any, where: str, *, nullable: bool = False,
               choices: tuple[str, ...] | None = None, pattern: re.Pattern | None = None) -> str | None:
        if value is None and nullable:
            return None
        if not isinstance(value, str) or not value:
            raise self.fail(where, f"expected a non-empty string, got {_show(value)}")
        if choices is not None and value not in choices:
            raise self.fail(where, f"expected one of {', '.join(choices)}, got {_show(value)}")
        if pattern is not None and not pattern.match(value):
            raise self.fail(where, f"expected lower case letters, digits and '_', got {_show(value)}")
        return value

    def schema(self, doc: dict, expected: str) -> None:
        got = self.key(doc, "schema", "")
        if got != expected:
            raise self.fail("schema", f"expected '{expected}', got {_show(got)}")


def _show(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, np.ndarray) else str(value.tolist())
    return text if len(text) <= 40 else text[:37] + "..."


def _load_json(path: Path) -> tuple[dict, _Checker]:
    path = Path(path)
    doc = load_json_file(path)
    check = _Checker(str(path))
    return check.obj(doc, ""), check


# --------------------------------------------------------------------------- expected (3)


@dataclass
class ExpectedCounts:
    """Contract 3: instances per class that the as-designed model holds for the scanned
    building (``counts``) and, optionally, per storey (``storeys``: storey id -> counts,
    bottom up, ids as in contract 4: ``S1``, ``S2``, ...)."""

    counts: dict[str, int]
    storeys: dict[str, dict[str, int]] | None = None


@dataclass(frozen=True)
class CountLimits:
    """Upper bounds on an expected-counts document from outside (the review app's jobs)."""

    classes: int | None = None  # keys of ``counts`` (and of each storey's)
    count: int | None = None  # instances of one class
    storeys: int | None = None  # storeys of ``storeys``


class _FieldChecker(_Checker):
    """A checker of a document that is a field itself: errors read ``field.key: reason``."""

    def fail(self, where: str, reason: str) -> InputError:
        return InputError(f"{self.label}.{where}" if where else self.label, reason)


def _counts(check: _Checker, value: Any, where: str, limits: CountLimits) -> dict[str, int]:
    value = check.obj(value, where)
    if limits.classes is not None and len(value) > limits.classes:
        raise check.fail(where, f"{len(value):,} classes; at most {limits.classes} allowed")
    out: dict[str, int] = {}
    for cls, n in value.items():
        at = f"{where}.{cls}" if where else str(cls)
        check.string(cls, at, pattern=CLASS_ID_RE)
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise check.fail(at, f"expected a non-negative integer, got {_show(n)}")
        if limits.count is not None and n > limits.count:
            raise check.fail(at, f"must be at most {limits.count:,}, got {_show(n)}")
        out[cls] = n
    return out


STOREY_ID_RE = re.compile(r"^S[0-9]+$")


def parse_expected_counts(doc: Any, check: _Checker, *, limits: CountLimits = CountLimits(),
                          schema: bool = True) -> ExpectedCounts:
    """Contract 3's document ``{"schema", "counts", "storeys"?}`` checked field by field.

    The one parser of expected counts (``sbsc detect --expected`` and the review app's jobs).
    ``storeys`` (an extension: ``{"S1": {"socket_x1": 20, ...}, "S2": {...}}``) must add up
    to ``counts`` class by class (a class missing from a storey counts 0 there).

    Parameters
    ----------
    doc
        The decoded JSON document.
    check
        Names the document in errors (a file, or a field of a request).
    limits
        Upper bounds on classes, counts and storeys.
    schema
        Whether ``schema`` must be present (a file must say it; a request's field need not).

    Returns
    -------
    ExpectedCounts
        ``counts`` and ``storeys`` (None without storeys).
    """
    doc = check.obj(doc, "")
    if schema:
        check.schema(doc, EXPECTED_SCHEMA)
    counts = _counts(check, check.key(doc, "counts", ""), "counts", limits)
    if doc.get("storeys") is None:
        return ExpectedCounts(counts)
    value = check.obj(doc["storeys"], "storeys")
    if limits.storeys is not None and len(value) > limits.storeys:
        raise check.fail("storeys", f"{len(value):,} storeys; at most {limits.storeys} allowed")
    storeys = {}
    for sid, st in value.items():
        if not STOREY_ID_RE.match(sid):
            raise check.fail(f"storeys.{sid}", "storey ids are S1, S2, ... (bottom up, as in the detections)")
        storeys[sid] = _counts(check, st, f"storeys.{sid}", limits)
    for cls in sorted(set(counts) | {c for st in storeys.values() for c in st}):
        total = sum(st.get(cls, 0) for st in storeys.values())
        if total != counts.get(cls, 0):
            raise check.fail(f"storeys.*.{cls}", f"the storeys hold {total} in all, counts.{cls} is "
                                                 f"{counts.get(cls, 0)}")
    return ExpectedCounts(counts, storeys or None)


def parse_expected_field(value: Any, field: str, *, limits: CountLimits = CountLimits()) -> ExpectedCounts | None:
    """Expected counts given as a request's field: bare ``{"socket_x1": 20}`` or a whole
    contract-3 document (its ``schema`` optional); None for None. Errors name ``field.key``."""
    if value is None:
        return None
    check = _FieldChecker(field)
    if isinstance(value, dict) and "counts" in value:
        return parse_expected_counts(value, check, limits=limits, schema=False)
    return ExpectedCounts(_counts(check, value, "", limits))


def read_expected_counts(path: Path | str) -> ExpectedCounts:
    """``expected.json`` (contract 3) with its optional per-storey counts
    (:func:`parse_expected_counts`)."""
    doc, check = _load_json(Path(path))
    return parse_expected_counts(doc, check)


def read_expected(path: Path | str) -> dict[str, int]:
    """``expected.json``: instances per class that the as-designed model holds."""
    return read_expected_counts(path).counts


# --------------------------------------------------------------------------- truth (5)


def read_truth(path: Path | str) -> TruthDocument:
    """``ground_truth.json`` of a simulated scene."""
    doc, check = _load_json(Path(path))
    check.schema(doc, TRUTH_SCHEMA)
    objects = []
    for i, o in enumerate(check.lst(check.key(doc, "objects", ""), "objects")):
        w = f"objects[{i}]"
        check.obj(o, w)
        objects.append(TruthObject(
            class_id=check.string(check.key(o, "class", w), f"{w}.class", pattern=CLASS_ID_RE),
            position=check.vec3(check.key(o, "position", w), f"{w}.position"),
            normal=check.vec3(check.key(o, "normal", w), f"{w}.normal"),
            width_m=check.number(check.key(o, "width_m", w), f"{w}.width_m", positive=True),
            height_m=check.number(check.key(o, "height_m", w), f"{w}.height_m", positive=True),
            wall=check.string(o.get("wall"), f"{w}.wall", nullable=True),
            u=check.number(o.get("u"), f"{w}.u", nullable=True, lo=-LOCAL_MAX, hi=LOCAL_MAX),
            v=check.number(o.get("v"), f"{w}.v", nullable=True, lo=-LOCAL_MAX, hi=LOCAL_MAX),
            extra={k: v for k, v in o.items()
                   if k not in ("class", "position", "normal", "width_m", "height_m", "wall", "u", "v")},
        ))
    lists = {}
    for key in ("walls", "openings"):
        items = check.lst(doc.get(key, []), key)
        for i, item in enumerate(items):
            check.obj(item, f"{key}[{i}]")
        lists[key] = items
    extra = {k: v for k, v in doc.items() if k not in ("schema", "objects", "walls", "openings")}
    return TruthDocument(objects=objects, walls=lists["walls"], openings=lists["openings"], extra=extra)


# --------------------------------------------------------------------------- detections (4)


def read_detections(path: Path | str) -> dict:
    """``detections.json`` (contract 4), checked; extra keys (e.g. ``review``) are kept.

    Parameters
    ----------
    path
        The document's file.

    Returns
    -------
    dict
        The document as read, once every field passed its check.

    Raises
    ------
    InputError
        Naming the file and the field, e.g. ``detections[3].position: expected 3 numbers``.
    """
    doc, check = _load_json(Path(path))
    return validate_detections(doc, check.label)


def detections_document(walls: list[tuple[str, WallFrame]], openings: list[Opening],
                        detections: list[Detection], extra: dict | None = None) -> dict:
    """Build a detections document (contract 4) from the pipeline's results.

    ``extra`` adds top-level keys (e.g. run information); it may not replace the
    contract's own keys.
    """
    doc: dict[str, Any] = {
        "schema": DETECTIONS_SCHEMA,
        "walls": [{"id": wid, **frame.to_dict()} for wid, frame in walls],
        "openings": [o.to_dict() for o in openings],
        "detections": [d.to_dict() for d in detections],
    }
    if extra:
        clash = sorted(set(extra) & set(doc))
        if clash:
            raise ValueError(f"extra keys would replace contract keys: {clash}")
        doc.update(extra)
    return doc


def write_detections(path: Path | str, document: dict) -> None:
    """Check ``document`` and write it atomically (complete or not at all)."""
    validate_detections(document, str(path))
    write_json_atomic(path, document)
