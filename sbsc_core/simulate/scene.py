"""Declarative description of a virtual building floor: schema, loading and validation.

A description (YAML or JSON, ``schema: sbsc.scene/1``) lists rooms as axis-aligned
outlines, openings (doors, windows) on walls and objects placed on walls::

    schema: sbsc.scene/1
    name: one room
    ceiling_height_m: 2.8
    rooms:
      - id: R1
        outline: [[0, 0], [4, 0], [4, 3], [0, 3]]   # or rect: [x0, y0, x1, y1]
        paint: [214, 210, 200]                      # wall colour of the room
        wall_paint: {R1-N: [200, 205, 210]}         # optional per-wall colours
    openings:
      - {wall: R1-S, kind: door, u: 1.0, width_m: 0.9, height_m: 2.1}
      - {wall: R1-N, kind: window, u: 2.0, width_m: 1.2, height_m: 1.2, sill_m: 0.9}
    objects:
      - {class: socket_x1, wall: R1-N, u: 0.6, v: 0.3}
    stations:                                       # optional; default: planned per room
      - {room: R1, xy: [2.0, 1.5]}
    scanner: {angular_step_deg: 0.1}                # optional ScannerSettings fields
    ceiling_objects: true            # optional: objects on the ceilings (see surfaces.py)
    pendants: true                   # optional, with ceiling_objects: the exit lights hang on rods
    columns: true                    # optional: free-standing columns with objects on them
    # optional realism (all off by default; see realism.py, clutter.py, survey.py):
    realism: {}                      # the realistic scanner; {} = published defaults, or ScanEffects fields
    clutter: {per_metre: 0.4}        # wall clutter that is none of the classes
    furniture: {per_metre: 0.15}     # furniture against the walls
    survey_frame: {offset: [412000, 5612000, 100], rotation_deg: 23.5}

Rooms are the free space; the solid between two rooms is a wall whose thickness is the
gap between their outlines. Every edge of a room outline is one wall (contract 4): its id
is ``<room>-<side>`` where side is the compass side of the room it bounds (N = +y), with a
number appended when a room has several walls on one side (numbered west to east or
south to north). The frame's origin is the lower-left corner seen from the room, ``u``
runs to the right, ``v`` up and the normal into the room. An opening given on one wall is
cut through the wall behind it too (the partner face of a partition).

Objects are placed by ``u`` (centre along the wall, metres from the wall's left end seen
from the room) and ``v`` (centre height above the floor); their footprint is the
catalogue size. :func:`load_scene` refuses anything that does not fit with an
:class:`~sbsc_core.errors.InputError` naming the file and the item.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import InputError
from ..types import WallFrame
from .catalogue import CATALOGUE, ObjectSpec
from .realism import ScanEffects
from .scanner import ScannerSettings

SCHEMA = "sbsc.scene/1"
RGB = tuple[int, int, int]

DEFAULT_COLOURS: dict[str, RGB] = {
    "floor": (128, 120, 110),
    "ceiling": (240, 240, 236),
    "door_frame": (96, 70, 50),
    "window_frame": (70, 74, 80),
}
OPENING_KINDS = ("door", "window")
_EPS = 1e-6


@dataclass(frozen=True)
class RoomSpec:
    id: str
    outline: tuple[tuple[float, float], ...]  # counter-clockwise, axis-aligned edges
    paint: RGB
    wall_paint: dict[str, RGB] = field(default_factory=dict)


@dataclass(frozen=True)
class OpeningSpec:
    index: int
    wall: str
    kind: str  # "door" | "window"
    u: float  # centre along the wall
    width_m: float
    height_m: float
    sill_m: float  # bottom above the floor (0 for doors)


@dataclass(frozen=True)
class ObjectPlacement:
    index: int
    class_id: str
    wall: str
    u: float  # footprint centre along the wall
    v: float  # footprint centre above the floor
    rotation_deg: float = 0.0  # in-plane turn seen from the room, counter-clockwise


# classes hung by gravity or round: never turned by ``object_rotation``
UNROTATABLE = frozenset({"fire_extinguisher", "radiator", "smoke_detector"})


def turn_objects(objects: list[ObjectPlacement], fraction: float, seed: int,
                 rotatable: Callable[[str], bool] = lambda c: c not in UNROTATABLE) -> list[ObjectPlacement]:
    """``round(fraction x n)`` of the ``n`` rotatable, unturned objects turned by random angles
    (uniform in +-180 degrees, at least 5 degrees from a multiple of 90), chosen with ``seed``."""
    rng = np.random.default_rng(seed)
    idx = [k for k, o in enumerate(objects) if rotatable(o.class_id) and o.rotation_deg == 0.0]
    pick = rng.permutation(idx)[: int(round(fraction * len(idx)))] if idx else []
    out = list(objects)
    for k in sorted(int(i) for i in pick):
        while True:
            deg = float(rng.uniform(-180.0, 180.0))
            if abs(deg - 90.0 * round(deg / 90.0)) >= 5.0:
                break
        out[k] = replace(out[k], rotation_deg=round(deg, 2))
    return out


def _fitting_turns(scene: SceneDescription, upright: list[ObjectPlacement]) -> list[ObjectPlacement]:
    """``scene.objects`` with each turn kept only if the scene with that turn alone validates."""
    turned = scene.objects
    out = list(upright)
    for k, (a, b) in enumerate(zip(upright, turned, strict=True)):
        if a == b:
            continue
        scene.objects = [*out[:k], b, *out[k + 1:]]
        try:
            validate_scene(scene)
        except InputError:
            continue
        out[k] = b
    scene.objects = turned
    return out


@dataclass(frozen=True)
class StationSpec:
    room: str
    xyz: tuple[float, float, float]


@dataclass
class SceneDescription:
    name: str
    source: str  # file name used in messages
    ceiling_height_m: float
    exterior_wall_thickness_m: float
    door_frame_width_m: float
    colours: dict[str, RGB]
    rooms: list[RoomSpec]
    openings: list[OpeningSpec]
    objects: list[ObjectPlacement]
    stations: list[StationSpec]  # empty: planned by the scanner
    scanner: ScannerSettings
    effects: ScanEffects | None = None  # the realistic scanner (None: off)
    clutter_per_metre: float = 0.0  # wall clutter items per metre of wall (0: none)
    furniture_per_metre: float = 0.0  # furniture pieces per metre of wall (0: none)
    survey_frame: SurveyFrameSpec | None = None  # write scan and truth in a survey frame
    ceiling_objects: bool = False  # smoke detectors and exit lights on the ceilings (surfaces.py)
    columns: bool = False  # free-standing columns with objects on them (surfaces.py)
    pendants: bool = False  # with ceiling_objects: the ceilings' exit lights hang on rods (surfaces.py)
    # sizes of the objects' designs: the design family's (see building.sized_for), the catalogue's by default
    specs: Mapping[str, ObjectSpec] = field(default_factory=lambda: CATALOGUE)

    @property
    def realistic(self) -> bool:
        """Any of the realism options on (the truth then records ``visible_fraction``)."""
        return bool(self.effects or self.clutter_per_metre or self.furniture_per_metre or self.survey_frame)


@dataclass(frozen=True)
class SurveyFrameSpec:
    """World = R_z(rotation_deg) * local + offset (a projected survey frame, e.g. UTM)."""

    offset: tuple[float, float, float]
    rotation_deg: float


@dataclass(frozen=True)
class WallFace:
    """One room-side face of a wall (contract 4)."""

    id: str
    room: str
    frame: WallFrame
    paint: RGB


@dataclass(frozen=True)
class OpeningPlacement:
    """An opening as a hole in one wall face, in that face's (u, v)."""

    wall: str
    kind: str
    u_min: float
    u_max: float
    v_min: float
    v_max: float
    depth_m: float  # reveal depth: thickness of the wall at the hole
    spec_index: int
    partner: str | None  # the face on the other side of a partition

    def to_dict(self) -> dict:
        return {"wall": self.wall, "kind": self.kind, "u_min": round(self.u_min, 4),
                "u_max": round(self.u_max, 4), "v_min": round(self.v_min, 4),
                "v_max": round(self.v_max, 4)}


@dataclass
class Layout:
    """Walls and holes of a description (pure 2-D geometry, no mesh)."""

    walls: dict[str, WallFace]
    openings: list[OpeningPlacement]

    def openings_on(self, wall_id: str) -> list[OpeningPlacement]:
        return [o for o in self.openings if o.wall == wall_id]


# --------------------------------------------------------------------------- loading


def load_scene(path: str | Path) -> SceneDescription:
    """Read, parse and fully validate a scene description (YAML or JSON).

    Raises :class:`InputError` with one line naming the file and the item for a missing
    file, a syntax error, a bad field, an unknown class or wall, or an object or opening
    that does not fit on its wall.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "scene description not found")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path.name, f"cannot read: {exc}") from None
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        raise InputError(path.name, f"malformed {'JSON' if path.suffix.lower() == '.json' else 'YAML'}: "
                         f"{_first_line(exc)}") from None
    scene = parse_scene(data, source=path.name)
    validate_scene(scene)
    return scene


def parse_scene(data: Any, source: str = "scene") -> SceneDescription:
    """Turn a parsed mapping into a :class:`SceneDescription` (types and references only)."""
    r = _Reader(source)
    if not isinstance(data, Mapping):
        raise InputError(source, "expected a mapping at the top level")
    r.known_keys(data, "", {"schema", "name", "ceiling_height_m", "exterior_wall_thickness_m",
                            "door_frame_width_m", "colours", "rooms", "openings", "objects",
                            "stations", "scanner", "object_rotation", "realism", "clutter", "furniture",
                            "survey_frame", "ceiling_objects", "columns", "pendants"})
    schema = data.get("schema", SCHEMA)
    if schema != SCHEMA:
        raise InputError(f"{source}: schema", f"unsupported schema {schema!r} (expected {SCHEMA!r})")
    height = r.number(data, "ceiling_height_m", "", default=3.0, lo=1.5, hi=20.0)
    colours = dict(DEFAULT_COLOURS)
    col_data = data.get("colours", {}) or {}
    if not isinstance(col_data, Mapping):
        raise InputError(f"{source}: colours", "expected a mapping")
    for key, value in col_data.items():
        if key not in DEFAULT_COLOURS:
            raise InputError(f"{source}: colours.{key}", f"unknown colour (known: {', '.join(DEFAULT_COLOURS)})")
        colours[key] = r.rgb(value, f"colours.{key}")

    rooms = [r.room(item, i) for i, item in enumerate(r.seq(data, "rooms", required=True))]
    if not rooms:
        raise InputError(f"{source}: rooms", "at least one room is required")
    openings = [r.opening(item, i) for i, item in enumerate(r.seq(data, "openings"))]
    objects = [r.placement(item, i) for i, item in enumerate(r.seq(data, "objects"))]
    turn = data.get("object_rotation")
    upright = objects
    if turn is not None:  # {fraction, seed}: a share of the rotatable objects turned at random
        r.known_keys(r.mapping(turn, "object_rotation"), "object_rotation", {"fraction", "seed"})
        objects = turn_objects(objects, r.number(turn, "fraction", "object_rotation", lo=0.0, hi=1.0),
                               int(r.number(turn, "seed", "object_rotation", default=0.0, lo=0.0, hi=2.0**31)))
    stations = [r.station(item, i, height) for i, item in enumerate(r.seq(data, "stations"))]
    scanner = r.scanner(data.get("scanner", {}) or {})
    extras = r.realism_options(data)
    for key in ("ceiling_objects", "columns", "pendants"):
        if data.get(key) is not None:
            if not isinstance(data[key], bool):
                raise InputError(f"{source}: {key}", f"expected true or false, got {data[key]!r}")
            extras[key] = data[key]
    if extras.get("pendants") and not extras.get("ceiling_objects"):
        raise InputError(f"{source}: pendants", "needs ceiling_objects: true (the exit lights that hang are the ceilings')")
    scene = SceneDescription(
        name=str(data.get("name", source)), source=source, ceiling_height_m=height,
        exterior_wall_thickness_m=r.number(data, "exterior_wall_thickness_m", "", default=0.25,
                                           lo=0.02, hi=2.0),
        door_frame_width_m=r.number(data, "door_frame_width_m", "", default=0.07, lo=0.0, hi=0.3),
        colours=colours, rooms=rooms, openings=openings, objects=objects, stations=stations,
        scanner=scanner, **extras,
    )
    if objects is not upright:  # a turned object that no longer fits its wall stays upright
        scene.objects = _fitting_turns(scene, upright)
    return scene


def validate_scene(scene: SceneDescription) -> Layout:
    """Check the geometry: rooms, openings and objects all fit. Returns the layout."""
    src = scene.source
    ids = [room.id for room in scene.rooms]
    for i, room_id in enumerate(ids):
        if room_id in ids[:i]:
            raise InputError(f"{src}: rooms[{i}]", f"duplicate room id {room_id!r}")
    _check_rooms_disjoint(scene)
    layout = build_layout(scene)
    for room in scene.rooms:
        for wall_id in room.wall_paint:
            if wall_id not in layout.walls or layout.walls[wall_id].room != room.id:
                raise InputError(f"{src}: rooms[{ids.index(room.id)}].wall_paint",
                                 f"no wall {wall_id!r} in room {room.id}")
    _check_openings(scene, layout)
    _check_objects(scene, layout)
    for i, st in enumerate(scene.stations):
        if st.room not in ids:
            raise InputError(f"{src}: stations[{i}]", f"unknown room {st.room!r}")
        room = scene.rooms[ids.index(st.room)]
        if not point_in_outline(np.array([st.xyz[:2]]), room.outline)[0]:
            raise InputError(f"{src}: stations[{i}]", f"station at {list(st.xyz[:2])} is outside room {st.room}")
    return layout


# --------------------------------------------------------------------------- geometry


def point_in_outline(points: np.ndarray, outline: tuple[tuple[float, float], ...]) -> np.ndarray:
    """Even-odd test of (N, 2) points against a polygon (strictly inside for generic points)."""
    pts = np.asarray(points, float)
    poly = np.asarray(outline, float)
    x, y = pts[:, 0:1], pts[:, 1:2]
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return np.count_nonzero(crosses & (x < x_at), axis=1) % 2 == 1


def outline_cells(outline: tuple[tuple[float, float], ...]) -> list[tuple[float, float, float, float]]:
    """Split a rectilinear outline into axis-aligned rectangles (x0, y0, x1, y1)."""
    poly = np.asarray(outline, float)
    xs, ys = np.unique(poly[:, 0]), np.unique(poly[:, 1])
    cx, cy = (xs[:-1] + xs[1:]) / 2, (ys[:-1] + ys[1:]) / 2
    gx, gy = np.meshgrid(cx, cy, indexing="ij")
    inside = point_in_outline(np.column_stack([gx.ravel(), gy.ravel()]), outline).reshape(gx.shape)
    return [(xs[i], ys[j], xs[i + 1], ys[j + 1]) for i, j in zip(*np.nonzero(inside), strict=True)]


def room_walls(room: RoomSpec, height: float) -> list[WallFace]:
    """The walls bounding one room, one per outline edge, with contract-4 frames."""
    pts = np.asarray(room.outline, float)
    raw = []
    for k in range(len(pts)):
        a, b = pts[k], pts[(k + 1) % len(pts)]
        e = (b - a) / np.linalg.norm(b - a)
        normal = np.array([-e[1], e[0], 0.0])  # left of a counter-clockwise edge: into the room
        side = {(0, -1): "N", (0, 1): "S", (-1, 0): "E", (1, 0): "W"}[(round(normal[0]), round(normal[1]))]
        key = (a[0] + b[0]) / 2 if side in "NS" else (a[1] + b[1]) / 2
        frame = WallFrame(origin=np.array([b[0], b[1], 0.0]), axis_u=np.array([-e[0], -e[1], 0.0]) + 0.0,
                          axis_v=np.array([0.0, 0.0, 1.0]), normal=normal + 0.0,
                          width_m=float(np.linalg.norm(b - a)), height_m=float(height))
        raw.append((side, key, frame))
    walls = []
    for side in "NESW":
        same = sorted((r for r in raw if r[0] == side), key=lambda r: r[1])
        for n, (_, _, frame) in enumerate(same, start=1):
            wid = f"{room.id}-{side}" + (str(n) if len(same) > 1 else "")
            walls.append(WallFace(wid, room.id, frame, room.wall_paint.get(wid, room.paint)))
    return walls


def build_layout(scene: SceneDescription) -> Layout:
    """All walls of all rooms and the holes the openings cut into them."""
    walls: dict[str, WallFace] = {}
    for room in scene.rooms:
        for w in room_walls(room, scene.ceiling_height_m):
            walls[w.id] = w
    openings: list[OpeningPlacement] = []
    for op in scene.openings:
        where = f"{scene.source}: openings[{op.index}] ({op.kind} on wall {op.wall})"
        if op.wall not in walls:
            raise InputError(where, f"unknown wall {op.wall!r}")
        wall = walls[op.wall]
        u0, u1 = op.u - op.width_m / 2, op.u + op.width_m / 2
        v0, v1 = op.sill_m, op.sill_m + op.height_m
        partner, depth, pu = _partner_face(wall, u0, u1, walls=walls, scene=scene, where=where)
        openings.append(OpeningPlacement(op.wall, op.kind, u0, u1, v0, v1, depth, op.index,
                                         partner.id if partner else None))
        if partner is not None:
            openings.append(OpeningPlacement(partner.id, op.kind, pu[0], pu[1], v0, v1, depth,
                                             op.index, op.wall))
    return Layout(walls, openings)


def footprint(p: ObjectPlacement, specs: Mapping[str, ObjectSpec] = CATALOGUE) -> tuple[float, float, float, float]:
    """(u_min, u_max, v_min, v_max) of an object's footprint on its wall (of its turned outline).

    ``specs`` gives the sizes of the objects' designs (a scene's ``specs``).
    """
    spec = specs[p.class_id]
    a = np.deg2rad(p.rotation_deg)
    ca, sa = abs(np.cos(a)), abs(np.sin(a))
    w, h = spec.width_m * ca + spec.height_m * sa, spec.height_m * ca + spec.width_m * sa
    return (p.u - w / 2, p.u + w / 2, p.v - h / 2, p.v + h / 2)


# --------------------------------------------------------------------------- checks


def _partner_face(wall: WallFace, u0: float, u1: float, *, walls: dict[str, WallFace],
                  scene: SceneDescription, where: str) -> tuple[WallFace | None, float, tuple[float, float]]:
    """The face behind ``wall`` across the hole u0..u1 (a partition), its depth and hole range."""
    fr = wall.frame
    ends = fr.to_world(np.array([u0, u1]), 0.0)
    best = None
    max_gap = max(0.6, scene.exterior_wall_thickness_m)
    for other in walls.values():
        of = other.frame
        if other.id == wall.id or float(of.normal @ fr.normal) > -0.999:
            continue
        gap = float((fr.origin - of.origin) @ fr.normal)  # how far behind ``wall`` the face is
        if not _EPS < gap <= max_gap:
            continue
        pu = np.sort((ends - of.origin) @ of.axis_u)
        lo, hi = max(pu[0], 0.0), min(pu[1], of.width_m)
        if hi - lo <= _EPS:
            continue  # the hole is not behind this face at all
        if pu[0] < -_EPS or pu[1] > of.width_m + _EPS:
            raise InputError(where, f"the opening runs past the end of wall {other.id} behind it")
        if best is None or gap < best[1]:
            best = (other, gap, (float(pu[0]), float(pu[1])))
    if best is None:
        return None, scene.exterior_wall_thickness_m, (u0, u1)
    return best


def _check_rooms_disjoint(scene: SceneDescription) -> None:
    cells = [(room, outline_cells(room.outline)) for room in scene.rooms]
    for i, (ra, ca) in enumerate(cells):
        for rb, cb in cells[i + 1:]:
            for a in ca:
                for b in cb:
                    if min(a[2], b[2]) - max(a[0], b[0]) > _EPS and min(a[3], b[3]) - max(a[1], b[1]) > _EPS:
                        raise InputError(f"{scene.source}: rooms", f"rooms {ra.id} and {rb.id} overlap")


def _check_openings(scene: SceneDescription, layout: Layout) -> None:
    fw = scene.door_frame_width_m
    for o in layout.openings:
        wall = layout.walls[o.wall]
        where = f"{scene.source}: openings[{o.spec_index}] ({o.kind} on wall {o.wall})"
        top = o.v_max + fw
        if o.u_min - fw < -_EPS or o.u_max + fw > wall.frame.width_m + _EPS or top > wall.frame.height_m + _EPS:
            raise InputError(where, f"does not fit on its wall: u {o.u_min:.3f}-{o.u_max:.3f} m with "
                             f"{fw:.3f} m frame, wall is {wall.frame.width_m:.3f} x {wall.frame.height_m:.3f} m")
        if o.kind == "door" and o.v_min > _EPS:
            raise InputError(where, "a door must start at the floor (sill_m 0)")
    for i, a in enumerate(layout.openings):
        for b in layout.openings[i + 1:]:
            if a.wall == b.wall and a.spec_index != b.spec_index and _overlap(_grown(a, fw), _grown(b, fw)):
                raise InputError(f"{scene.source}: openings[{b.spec_index}] ({b.kind} on wall {b.wall})",
                                 f"overlaps openings[{a.spec_index}] ({a.kind})")


def _check_objects(scene: SceneDescription, layout: Layout) -> None:
    src, fw = scene.source, scene.door_frame_width_m
    boxes: list[tuple[ObjectPlacement, np.ndarray, np.ndarray]] = []
    for p in scene.objects:
        where = f"{src}: objects[{p.index}] ({p.class_id} on wall {p.wall})"
        if p.wall not in layout.walls:
            raise InputError(where, f"unknown wall {p.wall!r}")
        wall = layout.walls[p.wall]
        u0, u1, v0, v1 = footprint(p, scene.specs)
        W, H = wall.frame.width_m, wall.frame.height_m
        if u0 < -_EPS or u1 > W + _EPS or v0 < -_EPS or v1 > H + _EPS:
            raise InputError(where, f"does not fit on its wall: footprint u {u0:.3f}-{u1:.3f}, "
                             f"v {v0:.3f}-{v1:.3f} m is outside the wall (0-{W:.3f} x 0-{H:.3f} m)")
        for o in layout.openings_on(p.wall):
            if _overlap((u0, u1, v0, v1), _grown(o, fw)):
                raise InputError(where, f"does not fit on its wall: overlaps {o.kind} openings[{o.spec_index}] "
                                 f"(u {o.u_min:.3f}-{o.u_max:.3f}, v {o.v_min:.3f}-{o.v_max:.3f} m, "
                                 f"frame {fw:.3f} m)")
        for q, _, _ in boxes:
            if q.wall == p.wall and _overlap((u0, u1, v0, v1), footprint(q, scene.specs)):
                raise InputError(where, f"does not fit on its wall: overlaps objects[{q.index}] ({q.class_id})")
        depth = scene.specs[p.class_id].depth_m
        corners = wall.frame.to_world(np.array([u0, u1, u0, u1]), np.array([v0, v0, v1, v1]))
        corners = np.vstack([corners, corners + depth * wall.frame.normal])
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        for q, qlo, qhi in boxes:
            if q.wall != p.wall and np.all(np.minimum(hi, qhi) - np.maximum(lo, qlo) > _EPS):
                raise InputError(where, f"does not fit on its wall: collides with objects[{q.index}] "
                                 f"({q.class_id} on wall {q.wall})")
        boxes.append((p, lo, hi))


def _grown(o: OpeningPlacement, fw: float) -> tuple[float, float, float, float]:
    return (o.u_min - fw, o.u_max + fw, o.v_min - (fw if o.v_min > _EPS else 0.0), o.v_max + fw)


def _overlap(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> bool:
    return min(a[1], b[1]) - max(a[0], b[0]) > _EPS and min(a[3], b[3]) - max(a[2], b[2]) > _EPS


def _first_line(exc: Exception) -> str:
    return " ".join(str(exc).split())


# --------------------------------------------------------------------------- field reader


class _Reader:
    """Typed access to the parsed mapping with one-line errors naming file and field."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, reason: str) -> InputError:
        return InputError(f"{self.source}: {where}" if where else self.source, reason)

    def known_keys(self, d: Mapping, where: str, allowed: set[str]) -> None:
        for key in d:
            if key not in allowed:
                raise self.fail(f"{where}.{key}" if where else str(key),
                                f"unknown field (allowed: {', '.join(sorted(allowed))})")

    def seq(self, d: Mapping, key: str, required: bool = False) -> list:
        if key not in d or d[key] is None:
            if required:
                raise self.fail(key, "missing")
            return []
        if not isinstance(d[key], list):
            raise self.fail(key, "expected a list")
        return d[key]

    def number(self, d: Mapping, key: str, where: str, *, default: float | None = None,
               lo: float = -math.inf, hi: float = math.inf) -> float:
        name = f"{where}.{key}" if where else key
        if key not in d:
            if default is None:
                raise self.fail(name, "missing")
            return float(default)
        value = d[key]
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise self.fail(name, f"expected a number, got {value!r}")
        if not lo <= value <= hi:
            raise self.fail(name, f"{value} is outside {lo:g}..{hi:g}")
        return float(value)

    def string(self, d: Mapping, key: str, where: str) -> str:
        value = d.get(key)
        if not isinstance(value, str) or not value:
            raise self.fail(f"{where}.{key}", "missing" if value is None else "expected a non-empty string")
        return value

    def rgb(self, value: Any, where: str) -> RGB:
        if (not isinstance(value, list | tuple) or len(value) != 3
                or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in value)):
            raise self.fail(where, f"expected [r, g, b] with integers 0-255, got {value!r}")
        return (int(value[0]), int(value[1]), int(value[2]))

    def mapping(self, item: Any, where: str) -> Mapping:
        if not isinstance(item, Mapping):
            raise self.fail(where, "expected a mapping")
        return item

    def room(self, item: Any, i: int) -> RoomSpec:
        where = f"rooms[{i}]"
        d = self.mapping(item, where)
        self.known_keys(d, where, {"id", "outline", "rect", "paint", "wall_paint"})
        rid = self.string(d, "id", where)
        if "-" in rid:
            raise self.fail(f"{where}.id", "a room id must not contain '-'")
        if ("outline" in d) == ("rect" in d):
            raise self.fail(where, "give exactly one of outline or rect")
        if "rect" in d:
            r = d["rect"]
            if not isinstance(r, list) or len(r) != 4 or not all(_is_num(x) for x in r) or r[2] <= r[0] or r[3] <= r[1]:
                raise self.fail(f"{where}.rect", "expected [x0, y0, x1, y1] with x1 > x0 and y1 > y0")
            pts = [(r[0], r[1]), (r[2], r[1]), (r[2], r[3]), (r[0], r[3])]
        else:
            pts = d["outline"]
            if not isinstance(pts, list) or len(pts) < 4 or not all(
                    isinstance(p, list | tuple) and len(p) == 2 and all(_is_num(x) for x in p) for p in pts):
                raise self.fail(f"{where}.outline", "expected a list of at least 4 [x, y] points")
        outline = _normalise_outline([(float(x), float(y)) for x, y in pts])
        if outline is None:
            raise self.fail(f"{where}.outline", "edges must be axis-aligned, non-zero and not self-intersecting")
        paint = self.rgb(d.get("paint", [220, 218, 212]), f"{where}.paint")
        wp = d.get("wall_paint", {}) or {}
        if not isinstance(wp, Mapping):
            raise self.fail(f"{where}.wall_paint", "expected a mapping wall id -> [r, g, b]")
        return RoomSpec(rid, outline, paint, {str(k): self.rgb(v, f"{where}.wall_paint.{k}") for k, v in wp.items()})

    def opening(self, item: Any, i: int) -> OpeningSpec:
        where = f"openings[{i}]"
        d = self.mapping(item, where)
        self.known_keys(d, where, {"wall", "kind", "u", "width_m", "height_m", "sill_m"})
        kind = self.string(d, "kind", where)
        if kind not in OPENING_KINDS:
            raise self.fail(f"{where}.kind", f"unknown kind {kind!r} (door or window)")
        return OpeningSpec(
            i, self.string(d, "wall", where), kind, self.number(d, "u", where),
            self.number(d, "width_m", where, lo=0.2, hi=10.0), self.number(d, "height_m", where, lo=0.2, hi=10.0),
            self.number(d, "sill_m", where, default=0.0 if kind == "door" else None, lo=0.0, hi=10.0))

    def placement(self, item: Any, i: int) -> ObjectPlacement:
        where = f"objects[{i}]"
        d = self.mapping(item, where)
        self.known_keys(d, where, {"class", "wall", "u", "v", "rotation_deg"})
        cls = self.string(d, "class", where)
        if cls not in CATALOGUE:
            raise self.fail(f"{where}.class", f"unknown class {cls!r} (known: {', '.join(sorted(CATALOGUE))})")
        wall = self.string(d, "wall", where)
        v = self.number(d, "v", where, default=CATALOGUE[cls].mount_height_m)
        rot = self.number(d, "rotation_deg", where, default=0.0, lo=-360.0, hi=360.0)
        return ObjectPlacement(i, cls, wall, self.number(d, "u", where), v, rot)

    def station(self, item: Any, i: int, ceiling: float) -> StationSpec:
        where = f"stations[{i}]"
        d = self.mapping(item, where)
        self.known_keys(d, where, {"room", "xy", "height_m"})
        room = self.string(d, "room", where)
        xy = d.get("xy")
        if not isinstance(xy, list | tuple) or len(xy) != 2 or not all(_is_num(x) for x in xy):
            raise self.fail(f"{where}.xy", "expected [x, y]")
        h = self.number(d, "height_m", where, default=ScannerSettings().height_m, lo=0.1, hi=ceiling - 0.05)
        return StationSpec(room, (float(xy[0]), float(xy[1]), h))

    def scanner(self, d: Any) -> ScannerSettings:
        d = self.mapping(d, "scanner")
        known = {f.name: f for f in fields(ScannerSettings)}
        kwargs = {}
        for key in d:
            if key not in known:
                raise self.fail(f"scanner.{key}", f"unknown setting (known: {', '.join(known)})")
            kwargs[key] = self.number(d, key, "scanner")
        try:
            return ScannerSettings(**kwargs)
        except ValueError as exc:
            raise self.fail("scanner", str(exc)) from None


    def realism_options(self, data: Mapping) -> dict:
        """``realism``, ``clutter``, ``furniture`` and ``survey_frame`` (each optional)."""
        out: dict[str, Any] = {}
        if data.get("realism") is not None:
            d = {} if data["realism"] is True else self.mapping(data["realism"], "realism")
            known = {f.name for f in fields(ScanEffects)}
            for key in d:
                if key not in known:
                    raise self.fail(f"realism.{key}", f"unknown setting (known: {', '.join(sorted(known))})")
            try:
                out["effects"] = ScanEffects(**{k: self.number(d, k, "realism") for k in d})
            except ValueError as exc:
                raise self.fail("realism", str(exc)) from None
        for key, default in (("clutter", 0.4), ("furniture", 0.15)):
            if data.get(key) is not None:
                d = {} if data[key] is True else self.mapping(data[key], key)
                self.known_keys(d, key, {"per_metre"})
                out[f"{key}_per_metre"] = self.number(d, "per_metre", key, default=default, lo=0.0, hi=5.0)
        if data.get("survey_frame") is not None:
            d = self.mapping(data["survey_frame"], "survey_frame")
            self.known_keys(d, "survey_frame", {"offset", "rotation_deg"})
            off = d.get("offset", [0, 0, 0])
            if not isinstance(off, list | tuple) or len(off) != 3 or not all(_is_num(x) and abs(x) < 1e8 for x in off):
                raise self.fail("survey_frame.offset", "expected [x, y, z] with |values| < 1e8")
            out["survey_frame"] = SurveyFrameSpec(tuple(float(x) for x in off),
                                                  self.number(d, "rotation_deg", "survey_frame", default=0.0,
                                                              lo=-360.0, hi=360.0))
        return out


def _is_num(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


def _normalise_outline(pts: list[tuple[float, float]]) -> tuple[tuple[float, float], ...] | None:
    """Counter-clockwise, without repeated or collinear vertices; None if not rectilinear."""
    if len(pts) > 1 and pts[0] == pts[-1]:
        pts = pts[:-1]
    p = np.asarray(pts, float)
    keep = np.ones(len(p), bool)
    for k in range(len(p)):
        if np.allclose(p[k], p[(k + 1) % len(p)]):
            keep[k] = False
    p = p[keep]
    changed = True
    while changed and len(p) >= 3:  # drop vertices in the middle of a straight run
        changed = False
        for k in range(len(p)):
            a, b, c = p[k - 1], p[k], p[(k + 1) % len(p)]
            if abs((b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0])) < 1e-12:
                p = np.delete(p, k, axis=0)
                changed = True
                break
    if len(p) < 4:
        return None
    d = np.roll(p, -1, axis=0) - p
    if not np.all((np.abs(d[:, 0]) < 1e-12) ^ (np.abs(d[:, 1]) < 1e-12)):
        return None
    area2 = float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))
    if area2 < 0:
        p = p[::-1]
    if _self_intersects(p):
        return None
    return tuple((float(x), float(y)) for x, y in p)


def _self_intersects(p: np.ndarray) -> bool:
    n = len(p)
    segs = [(p[k], p[(k + 1) % n]) for k in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue
            (a0, a1), (b0, b1) = segs[i], segs[j]
            if (min(a0[0], a1[0]) <= max(b0[0], b1[0]) and min(b0[0], b1[0]) <= max(a0[0], a1[0])
                    and min(a0[1], a1[1]) <= max(b0[1], b1[1]) and min(b0[1], b1[1]) <= max(a0[1], a1[1])):
                return True
    return False


def axis_positions(a: float, b: float, spacing_m: float, clearance_m: float) -> list[float]:
    """About (b - a) / spacing_m positions evenly over a..b, kept ``clearance_m`` from the ends."""
    n = max(1, round((b - a) / spacing_m))
    pos = a + (np.arange(n) + 0.5) * (b - a) / n
    if b - a > 2 * clearance_m:
        pos = np.clip(pos, a + clearance_m, b - clearance_m)
    return [float(x) for x in pos]


def merged_cells(room: RoomSpec) -> list[tuple[float, float, float, float]]:
    """The room split into few rectangles: grid cells merged along x, then runs along y."""
    cells = outline_cells(room.outline)
    rows: dict[tuple[float, float], list[tuple[float, float]]] = {}
    for x0, y0, x1, y1 in cells:
        rows.setdefault((y0, y1), []).append((x0, x1))
    strips = []
    for (y0, y1), xs in rows.items():
        xs.sort()
        cur = list(xs[0])
        for a, b in xs[1:]:
            if abs(a - cur[1]) < 1e-9:
                cur[1] = b
            else:
                strips.append((cur[0], y0, cur[1], y1))
                cur = [a, b]
        strips.append((cur[0], y0, cur[1], y1))
    strips.sort(key=lambda s: (s[0], s[2], s[1]))
    merged: list[list[float]] = []
    for s in strips:
        if merged and merged[-1][0] == s[0] and merged[-1][2] == s[2] and abs(merged[-1][3] - s[1]) < 1e-9:
            merged[-1][3] = s[3]
        else:
            merged.append(list(s))
    return [(m[0], m[1], m[2], m[3]) for m in merged]
