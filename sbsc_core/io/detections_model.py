"""The detections document (contract 4) as pydantic models: the one validation path.

``evaluate``, ``export-ifc``, ``compare``, the job import of the web app and every writer
check a detections document with :func:`validate_detections`. Known fields are typed and
bounded; fields beyond the contract are allowed and kept (``review``, ``ref``, run
information, ...), so documents of newer writers and of the review service still read.

- coordinates are finite and within :data:`COORD_MAX` metres (a national grid is ~1e7 m);
  sizes are > 0 and at most :data:`SIZE_MAX`; wall coordinates ``u``, ``v`` at most
  :data:`LOCAL_MAX`;
- ids are non-empty printable strings without control characters, unique among the
  walls and surfaces, and among the detections;
- classes match ``^[a-z0-9_]+$`` (a class is a directory name of the model library);
- each detection's ``wall`` names a wall or a surface, each opening's a wall, each wall's
  optional ``storey`` a storey;
- ``alpha`` and ``confidence`` lie in 0..1, ``source`` is ``both``, ``depth``, ``colour``
  or (review service) ``reviewer``.

A failure is one :class:`~sbsc_core.errors.InputError` naming the document and the field:
``detections.json: detections[2].wall: unknown wall "W99"``.
"""

from __future__ import annotations

import json
import math
import re
import unicodedata
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, model_validator

from ..errors import InputError

DETECTIONS_SCHEMA = "sbsc.detections/1"
COORD_MAX = 1.0e8  # |world coordinate| in metres
SIZE_MAX = 1.0e4  # a wall or an object, metres
LOCAL_MAX = 1.0e5  # |u|, |v| in a wall's frame, metres
ID_MAX_LEN = 200
CLASS_ID_RE = re.compile(r"^[a-z0-9_]{1,100}$")
SOURCES = ("both", "depth", "colour", "reviewer")
OPENING_KINDS = ("door", "window")
REVIEW_STATUSES = ("pending", "accepted", "rejected")


def show(value: Any) -> str:
    """A short JSON rendering of ``value`` for an error message."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def bad_text(text: str) -> str | None:
    """Why ``text`` cannot be a name or an id (control / bidi / NUL characters), else None."""
    for ch in text:
        cat = unicodedata.category(ch)
        if cat in ("Cc", "Cf", "Cs", "Co", "Zl", "Zp"):
            return f"contains the control character U+{ord(ch):04X}"
    return None


# --------------------------------------------------------------------------- field types


def _number(value: Any, *, lo: float, hi: float, nullable: bool = False,
            positive: bool = False) -> float | None:
    if value is None and nullable:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"expected a number{' or null' if nullable else ''}, got {show(value)}")
    if positive and value <= 0:
        raise ValueError(f"must be > 0, got {show(value)}")
    if value < lo or value > hi:
        raise ValueError(f"must be between {lo:g} and {hi:g}, got {show(value)}")
    return float(value)


def _vec3(value: Any) -> list[float]:
    if (not isinstance(value, list) or len(value) != 3
            or any(isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x)
                   for x in value)):
        raise ValueError(f"expected 3 numbers, got {show(value)}")
    if any(abs(x) > COORD_MAX for x in value):
        raise ValueError(f"coordinates must lie within ±{COORD_MAX:g} m, got {show(value)}")
    return [float(x) for x in value]


def _ident(value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"expected a non-empty string, got {show(value)}")
    if len(value) > ID_MAX_LEN:
        raise ValueError(f"longer than {ID_MAX_LEN} characters")
    why = bad_text(value)
    if why:
        raise ValueError(why)
    return value


def _class_id(value: Any) -> str:
    if not isinstance(value, str) or not CLASS_ID_RE.match(value):
        raise ValueError(f"expected lower case letters, digits and '_', got {show(value)}")
    return value


def _choice(choices: tuple[str, ...]):  # noqa: ANN202
    def check(value: Any) -> str:
        if value not in choices:
            raise ValueError(f"expected one of {', '.join(choices)}, got {show(value)}")
        return value
    return check


def _schema(value: Any) -> str:
    if value != DETECTIONS_SCHEMA:
        raise ValueError(f"expected '{DETECTIONS_SCHEMA}', got {show(value)}")
    return value


Coord = Annotated[float, BeforeValidator(lambda v: _number(v, lo=-COORD_MAX, hi=COORD_MAX))]
Local = Annotated[float, BeforeValidator(lambda v: _number(v, lo=-LOCAL_MAX, hi=LOCAL_MAX))]
Size = Annotated[float, BeforeValidator(lambda v: _number(v, lo=0.0, hi=SIZE_MAX, positive=True))]
Unit = Annotated[float | None, BeforeValidator(lambda v: _number(v, lo=0.0, hi=1.0, nullable=True))]
Score = Annotated[float | None, BeforeValidator(lambda v: _number(v, lo=-1e6, hi=1e6, nullable=True))]
Angle = Annotated[float | None, BeforeValidator(lambda v: _number(v, lo=-3600.0, hi=3600.0, nullable=True))]
Vec3 = Annotated[list[float], BeforeValidator(_vec3)]
Ident = Annotated[str, BeforeValidator(_ident)]
ClassId = Annotated[str, BeforeValidator(_class_id)]
Kind = Annotated[str, BeforeValidator(_class_id)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow", populate_by_name=True)


class Storey(_Model):
    id: Ident
    floor_z: Coord
    ceiling_z: Coord


class Wall(_Model):
    id: Ident
    origin: Vec3
    axis_u: Vec3
    axis_v: Vec3
    normal: Vec3
    width_m: Size
    height_m: Size
    storey: Ident | None = None


class Surface(Wall):
    kind: Kind


class Opening(_Model):
    wall: Ident
    kind: Annotated[str, BeforeValidator(_choice(OPENING_KINDS))]
    u_min: Local
    u_max: Local
    v_min: Local
    v_max: Local

    @model_validator(mode="after")
    def _ordered(self) -> Opening:
        if self.u_min > self.u_max or self.v_min > self.v_max:
            raise ValueError("u_min/v_min must not exceed u_max/v_max")
        return self


class Review(_Model):
    """The review service's decision on a detection (``review`` of its documents)."""

    status: Annotated[str, BeforeValidator(_choice(REVIEW_STATUSES))]
    version: Annotated[int, Field(ge=0, le=2**63 - 1, strict=True)] | None = None


class Detection(_Model):
    id: Ident
    class_: ClassId = Field(alias="class")
    wall: Ident
    position: Vec3
    u: Local
    v: Local
    width_m: Size
    height_m: Size
    alpha: Unit  # required key; null only for objects a reviewer added
    rho_depth: Score
    rho_colour: Score
    source: Annotated[str, BeforeValidator(_choice(SOURCES))]
    confidence: Unit = None
    rotation_deg: Angle = None
    surface: Kind | None = None
    review: Review | None = None


class DetectionsDocument(_Model):
    """Contract 4 (``sbsc.detections/1``); extra keys are kept."""

    schema_: Annotated[str, BeforeValidator(_schema)] = Field(alias="schema")
    walls: list[Wall]
    openings: list[Opening]
    detections: list[Detection]
    storeys: list[Storey] | None = None
    surfaces: list[Surface] | None = None


# --------------------------------------------------------------------------- errors


def _where(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def _message(err: dict) -> tuple[str, str]:
    """(field, reason) of one pydantic error."""
    loc = tuple(err.get("loc", ()))
    kind = err.get("type", "")
    if kind == "missing":
        return _where(loc[:-1]), f"missing key '{loc[-1]}'"
    if kind == "value_error":
        return _where(loc), str(err.get("ctx", {}).get("error", err.get("msg", "invalid")))
    if kind in ("model_type", "model_attributes_type", "dict_type"):
        return _where(loc), "expected a JSON object"
    if kind == "list_type":
        return _where(loc), "expected a list"
    return _where(loc), str(err.get("msg", "invalid"))


def _fail(label: str, where: str, reason: str) -> InputError:
    return InputError(label, f"{where}: {reason}" if where else reason)


# --------------------------------------------------------------------------- validation


def parse_detections(doc: Any, label: str = "detections.json") -> DetectionsDocument:
    """The checked document as models; InputError(label, "field: reason") on the first problem."""
    if not isinstance(doc, dict):
        raise _fail(label, "", "expected a JSON object (a detections document)")
    try:
        model = DetectionsDocument.model_validate(doc)
    except ValidationError as exc:
        where, reason = _message(exc.errors(include_url=False)[0])
        raise _fail(label, where, reason) from None
    frames: set[str] = set()
    storeys = {s.id for s in model.storeys or ()}
    for key, items in (("walls", model.walls), ("surfaces", model.surfaces or [])):
        for i, w in enumerate(items):
            if w.id in frames:
                raise _fail(label, f"{key}[{i}].id", f"duplicate wall id {show(w.id)}")
            frames.add(w.id)
            if w.storey is not None and model.storeys is not None and w.storey not in storeys:
                raise _fail(label, f"{key}[{i}].storey", f"unknown storey {show(w.storey)}")
    walls = {w.id for w in model.walls}
    for i, o in enumerate(model.openings):
        if o.wall not in walls:
            raise _fail(label, f"openings[{i}].wall", f"unknown wall {show(o.wall)}")
    ids: set[str] = set()
    for i, d in enumerate(model.detections):
        if d.id in ids:
            raise _fail(label, f"detections[{i}].id", f"duplicate detection id {show(d.id)}")
        ids.add(d.id)
        if d.wall not in frames:
            raise _fail(label, f"detections[{i}].wall", f"unknown wall {show(d.wall)}")
    return model


def validate_detections(doc: Any, label: str = "detections.json") -> dict:
    """Check a detections document (contract 4); returns it unchanged."""
    parse_detections(doc, label)
    return doc
