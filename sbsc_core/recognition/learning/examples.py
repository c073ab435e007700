"""The examples of ``sbsc learn``: reviewed objects found on a surface of a detect output, snapped and cut out.

A detect output (``sbsc detect --out DIR``) holds ``detections.json`` (contract 4: the walls'
and surfaces' frames, ``pixel_m``) and ``orthoimages/<id>_colour.png`` / ``<id>_depth.npy``
for every wall and surface. A reviewed document (``--reviewed``, contract 4) gives each
example by its ``class`` and either its ``wall``, ``u``, ``v`` or only its ``position``
(3D); then the example's surface is the wall or surface whose plane is nearest to it and
whose extent holds it, and the example is snapped to the relief there:

- a class of the library: to the best match of its depth models nearby
  (:func:`~sbsc_core.recognition.learning.snap.snap_to_relief`, as the review app places an added object);
- a new class: to the centre of the relief blob under the click, which also gives its size
  when the example does not (``width_m``, ``height_m``).

An example that cannot be used is an :class:`~sbsc_core.errors.InputError` naming it and
saying why: not on any surface, its footprint leaving the surface, less than
:data:`~sbsc_core.recognition.learning.crops.MIN_SEEN` of it scanned, turned from upright.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from ...errors import InputError
from ...io.detections_model import (
    REVIEW_STATUSES,
    Angle,
    ClassId,
    Ident,
    Local,
    Size,
    Vec3,
    _choice,
    _message,
    parse_detections,
)
from ...io.safe_json import load_json_file
from ...types import WallFrame
from .crops import MIN_SEEN, Window, footprint, seen_share, surface_colour, surface_level, upright
from .snap import snap_to_relief

MAX_OFF_SURFACE_M = 0.15  # an example's position at most this far from its surface's plane
EDGE_SLACK_M = 0.05  # ... and at most this far beyond its edges
BLOB_MIN_RELIEF_M = 0.003  # a new class's relief blob: pixels standing out at least this much
BLOB_PEAK_SHARE = 0.35  # ... and at least this share of the relief's peak near the click
BLOB_SEARCH_M = 0.05  # the blob must reach this close to the click
BLOB_MAX_M = 2.5  # larger blobs are a piece of furniture or the surface bending, not an object
SNAP_RADIUS_M = 0.06  # a library class's example moves at most this far to its best match
SNAP_AGREE_M = 0.02  # a snap this far from the relief blob's centre is not trusted
SIZE_TOLERANCE = 0.3  # a blob within this share of a class's sides has its size
REVIEWED_MAX_BYTES = 64 << 20


@dataclass
class Surface:
    """A wall or surface of the detect output with its orthoimages (loaded on first use)."""

    id: str
    kind: str
    frame: WallFrame
    pixel_m: float
    images: Path
    _colour: np.ndarray | None = None
    _depth: np.ndarray | None = None

    def colour(self) -> np.ndarray:
        """The colour orthoimage (BGR uint8, row 0 at the top)."""
        if self._colour is None:
            path = self.images / f"{self.id}_colour.png"
            img = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if img is None:
                raise InputError(path, "missing or not a readable PNG (the detect output is incomplete)")
            self._colour = img
        return self._colour

    def depth(self) -> np.ndarray:
        """The depth orthoimage (metres out of the plane, NaN unseen)."""
        if self._depth is None:
            path = self.images / f"{self.id}_depth.npy"
            try:
                self._depth = np.load(path, allow_pickle=False).astype(np.float32)
            except (OSError, ValueError) as exc:
                raise InputError(path, f"missing or not a readable .npy ({exc.__class__.__name__}); "
                                       "the detect output is incomplete") from None
            if self._depth.shape != self.colour().shape[:2]:
                raise InputError(path, "its size differs from the colour orthoimage's")
        return self._depth


@dataclass
class Example:
    """One usable example: where it is (snapped), its size and its crops."""

    label: str  # "reviewed.json: detections[3] (radiator)" for messages
    class_id: str
    surface: Surface
    u: float
    v: float
    width_m: float
    height_m: float
    colour: np.ndarray  # BGR crop over the footprint, float32, NaN where the scan saw nothing
    relief: np.ndarray  # depth crop minus the surface level (NaN unseen)
    rho: float | None = None  # the snap's match with the class's models (None: not snapped by them)
    surface_bgr: np.ndarray | None = None  # the surface's colour around the footprint


# --------------------------------------------------------------------------- reading


class ReviewedObject(BaseModel):
    """A reviewed object: ``class`` and ``position``, or ``class``, ``wall``, ``u``, ``v``."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)
    class_: ClassId = Field(alias="class")
    id: Ident | None = None
    position: Vec3 | None = None
    wall: Ident | None = None
    u: Local | None = None
    v: Local | None = None
    width_m: Size | None = None
    height_m: Size | None = None
    rotation_deg: Angle = None
    review: dict | None = None


class ReviewedDocument(BaseModel):
    model_config = ConfigDict(extra="allow", populate_by_name=True)
    schema_: Annotated[str, BeforeValidator(_choice(("sbsc.detections/1",)))] = Field(alias="schema")
    detections: list[ReviewedObject]


def read_reviewed(path: Path) -> list[tuple[str, ReviewedObject]]:
    """The examples of a reviewed document: (label, object) of each object a person kept.

    Objects whose ``review.status`` is ``rejected`` or ``pending`` are no examples.
    """
    doc = load_json_file(path, max_bytes=REVIEWED_MAX_BYTES)
    try:
        model = ReviewedDocument.model_validate(doc)
    except ValidationError as exc:
        where, reason = _message(exc.errors(include_url=False)[0])
        raise InputError(path, f"{where}: {reason}" if where else reason) from None
    out = []
    for i, d in enumerate(model.detections):
        label = f"{path.name}: detections[{i}] ({d.class_})"
        status = (d.review or {}).get("status", "accepted")
        if status not in REVIEW_STATUSES:
            raise InputError(label, f"review.status must be one of {', '.join(REVIEW_STATUSES)}")
        if status != "accepted":
            continue
        if d.position is None and (d.wall is None or d.u is None or d.v is None):
            raise InputError(label, "give its 'position', or its 'wall', 'u' and 'v'")
        out.append((label, d))
    if not out:
        raise InputError(path, "no accepted object to learn from")
    return out


def read_detect_output(detect_out: Path) -> dict[str, Surface]:
    """The walls and surfaces of a detect output, by id."""
    det_path = detect_out / "detections.json"
    if not det_path.is_file():
        raise InputError(detect_out, "not a detect output (no detections.json; run sbsc detect --out first)")
    doc = load_json_file(det_path, max_bytes=REVIEWED_MAX_BYTES)
    model = parse_detections(doc, str(det_path))
    pixel_m = doc.get("pixel_m")
    if isinstance(pixel_m, bool) or not isinstance(pixel_m, int | float) or not math.isfinite(pixel_m) or pixel_m <= 0:
        raise InputError(det_path, "missing or bad 'pixel_m' (not written by sbsc detect?)")
    images = detect_out / "orthoimages"
    out: dict[str, Surface] = {}
    for w in model.walls:
        out[w.id] = Surface(w.id, "wall", WallFrame.from_dict(w.model_dump()), float(pixel_m), images)
    for s in model.surfaces or ():
        out[s.id] = Surface(s.id, s.kind, WallFrame.from_dict(s.model_dump()), float(pixel_m), images)
    return out


# --------------------------------------------------------------------------- placing


def locate(label: str, position: np.ndarray, surfaces: dict[str, Surface]) -> tuple[Surface, float, float]:
    """The surface an example at ``position`` is on and its (u, v) there: the nearest plane
    whose extent (with :data:`EDGE_SLACK_M`) holds it, at most :data:`MAX_OFF_SURFACE_M` away."""
    best: tuple[float, Surface, float, float] | None = None
    nearest = math.inf
    for s in surfaces.values():
        u, v, d = (float(x) for x in s.frame.to_uvd(position[None, :])[0])
        inside = -EDGE_SLACK_M <= u <= s.frame.width_m + EDGE_SLACK_M and -EDGE_SLACK_M <= v <= s.frame.height_m + EDGE_SLACK_M
        if not inside:
            continue
        nearest = min(nearest, abs(d))
        if abs(d) <= MAX_OFF_SURFACE_M and (best is None or abs(d) < best[0]):
            best = (abs(d), s, u, v)
    if best is None:
        why = (f"the nearest surface is {nearest:.2f} m away (at most {MAX_OFF_SURFACE_M:g} m)"
               if math.isfinite(nearest) else "no wall or surface of the detect output holds it")
        raise InputError(label, f"off the surface: {why}")
    return best[1], best[2], best[3]


def relief_blob(depth: np.ndarray, surface_height_m: float, pixel_m: float, u: float, v: float
                ) -> tuple[float, float, float, float] | None:
    """(u, v, width_m, height_m) of the relief blob at (u, v): the connected pixels standing
    out of the surface level by :data:`BLOB_MIN_RELIEF_M` that reach within
    :data:`BLOB_SEARCH_M` of the click; None when there is none (a flat object)."""
    half = int(math.ceil(BLOB_MAX_M / pixel_m))
    r = int(round((surface_height_m - v) / pixel_m - 0.5))
    c = int(round(u / pixel_m - 0.5))
    R0, C0 = max(0, r - half), max(0, c - half)
    R1, C1 = min(depth.shape[0], r + half + 1), min(depth.shape[1], c + half + 1)
    if R1 <= R0 or C1 <= C0:
        return None
    region = depth[R0:R1, C0:C1]
    if not np.isfinite(region).any():
        return None
    level = float(np.nanmedian(region))
    up = np.nan_to_num(region - level, nan=0.0)
    reach = int(math.ceil(BLOB_SEARCH_M / pixel_m))
    rr, cc = r - R0, c - C0
    around = up[max(0, rr - reach):rr + reach + 1, max(0, cc - reach):cc + reach + 1]
    peak = float(around.max()) if around.size else 0.0
    if peak < BLOB_MIN_RELIEF_M:
        return None
    # the object's own relief: a share of its peak near the click (mixed pixels at its rim and a
    # flatter neighbour, such as a door frame under an exit light, stay out)
    up = (up >= max(BLOB_MIN_RELIEF_M, BLOB_PEAK_SHARE * peak)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(up, connectivity=8)
    near = labels[max(0, rr - reach):rr + reach + 1, max(0, cc - reach):cc + reach + 1]
    ids = [k for k in np.unique(near) if k != 0]
    if not ids:
        return None
    k = max(ids, key=lambda k: int(stats[k, cv2.CC_STAT_AREA]))
    x, y, w, h = (int(stats[k, i]) for i in (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT))
    if w * pixel_m > BLOB_MAX_M * 1.6 or h * pixel_m > BLOB_MAX_M * 1.6:
        return None
    cu = (C0 + x + w / 2.0) * pixel_m
    cv = surface_height_m - (R0 + y + h / 2.0) * pixel_m
    return cu, cv, w * pixel_m, h * pixel_m


def snap_known(s: Surface, models: list[np.ndarray], u: float, v: float) -> tuple[float, float, float | None]:
    """(u, v, rho) of the best match of any of ``models`` (depth templates at the surface's
    pixels) within :data:`SNAP_RADIUS_M`; the click and None when none matches."""
    best = (u, v, None)
    for t in models:
        snap = snap_to_relief(s.depth(), s.pixel_m, s.frame.height_m, t, u=u, v=v, radius_m=SNAP_RADIUS_M)
        if snap.snapped and (best[2] is None or snap.rho > best[2]):
            best = (snap.u, snap.v, snap.rho)
    return best


def trust_snap(s: Surface, u: float, v: float, *, su: float, sv: float, rho: float | None, width_m: float,
               height_m: float, min_rho: float) -> bool:
    """Whether a library class's example moves from its click (u, v) to its snap (su, sv): the
    match correlates ``min_rho`` or more, and it agrees (within :data:`SNAP_AGREE_M`) with the
    relief blob under the click when that blob has about the class's size (within
    :data:`SIZE_TOLERANCE`). A model of another design fits a new product a few centimetres off
    (a tall sign's model on a square plate); two examples moved so would blur their median."""
    if rho is None or rho < min_rho:
        return False
    blob = relief_blob(s.depth(), s.frame.height_m, s.pixel_m, u, v)
    if blob is None or abs(blob[2] - width_m) > SIZE_TOLERANCE * width_m \
            or abs(blob[3] - height_m) > SIZE_TOLERANCE * height_m:
        return True
    return math.hypot(su - blob[0], sv - blob[1]) <= SNAP_AGREE_M


def cut(label: str, class_id: str, s: Surface, *, u: float, v: float, width_m: float, height_m: float,
        rho: float | None = None) -> Example:
    """The example's crops over its footprint; InputError when it leaves the surface or is not scanned."""
    depth = s.depth()
    win: Window | None = footprint(depth.shape, s.frame.height_m, s.pixel_m, u=u, v=v,
                                   width_m=width_m, height_m=height_m)
    if win is None:
        raise InputError(label, f"off the surface: its {width_m:.2f} x {height_m:.2f} m footprint at "
                                f"u={u:.2f}, v={v:.2f} leaves {s.kind} {s.id}")
    seen = seen_share(depth, win)
    if seen < MIN_SEEN:
        raise InputError(label, f"not scanned: only {seen:.0%} of its footprint on {s.kind} {s.id} was seen "
                                f"(at least {MIN_SEEN:.0%} needed)")
    r0, c0, r1, c1 = win
    level = surface_level(depth, win, ring_px=max(2, (r1 - r0) // 4))
    colour = s.colour()[r0:r1, c0:c1].astype(np.float32)
    colour[~np.isfinite(depth[r0:r1, c0:c1])] = np.nan  # unseen: no colour either
    return Example(label, class_id, s, u, v, width_m, height_m, colour,
                   depth[r0:r1, c0:c1].astype(np.float32) - level, rho,
                   surface_colour(s.colour(), depth, win, ring_px=max(2, (r1 - r0) // 4)))


def place(label: str, obj: ReviewedObject, surfaces: dict[str, Surface]) -> tuple[Surface, float, float, bool]:
    """(surface, u, v, given) of a reviewed object; ``given``: the object named its surface
    and (u, v) (placed already, not to be snapped)."""
    if obj.rotation_deg is not None and not upright(float(obj.rotation_deg)):
        raise InputError(label, f"turned by {obj.rotation_deg:g} degrees: only upright (or upside down) "
                                "objects give a front view")
    if obj.wall is not None and obj.u is not None and obj.v is not None:
        if obj.wall not in surfaces:
            raise InputError(label, f"off the surface: the detect output has no wall or surface {obj.wall!r}")
        return surfaces[obj.wall], float(obj.u), float(obj.v), True
    s, u, v = locate(label, np.asarray(obj.position, float), surfaces)
    return s, u, v, False
