"""Objects beyond walls for the simulator (issue 11): on ceilings and on free-standing columns.

Both are options of a scene (``ceiling_objects``, ``columns`` in the description, or
``sbsc simulate --ceiling-objects --columns``), off by default; they are laid out from the
scene itself, deterministically, so that any floor can have them:

- **Ceilings.** Every room gets smoke detectors on its ceiling, on a grid of about one per
  ``SMOKE_SPACING_M`` in each rectangle of the room, kept off the walls and moved away from
  the scanner stations (a station does not see the ceiling right above it). Every door
  without an exit light above it gets an exit light on the ceiling in front of it, on the
  side of the room with more doors (the escape route), its width along the door's wall.
  With the scene's ``pendants`` option each such exit light hangs instead on a rod,
  ``PENDANT_DROP_M`` under the ceiling, upright and parallel to the door's wall, facing the
  room (a surface of kind ``pendant``, id ``<room>-C-P<k>``, ``hangs_from`` the ceiling,
  framed like a wall with the sign's back on its plane; the sign's back is closed by a plate).
  A room's ceiling is a surface (contract 4) with id ``<room>-C``: ``axis_u`` = +x,
  ``axis_v`` = -y, ``normal`` = -z (down into the room), origin at the corner of the
  room's bounding box where u and v are 0 (min x, max y), so an object seen from below is
  drawn like on a wall.
- **Columns.** Every room with a rectangle at least ``COLUMN_ROOM_MIN_M`` on both sides
  gets one column in it, where the stations see most of its sides and as far from the
  stations as the rectangle allows, rectangular and round in turn; a side that no station
  sees (at ``SEEN_COS`` or straighter) carries no object. A rectangular column has four
  faces (surfaces ``<room>-COL<k>-N/E/S/W``, each framed like a wall seen from outside the
  column) with an extinguisher and its sign,
  a call point and its sign, a socket and a switch. A round column is one surface
  ``<room>-COL<k>`` unrolled around it (``u`` = arc length counter-clockwise from +x,
  ``radius_m`` and ``centre`` given) with an extinguisher, a call point and a socket.

Objects keep the class's footprint and model: ``width_m`` along the surface's ``axis_u``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ..types import Surface, WallFrame
from . import mesh as M
from .catalogue import ObjectSpec
from .mesh import ColouredMesh
from .scene import (
    Layout,
    RoomSpec,
    SceneDescription,
    axis_positions,
    merged_cells,
    point_in_outline,
)

SMOKE_SPACING_M = 6.0  # about one ceiling smoke detector per this many metres each way
CEILING_MARGIN_M = 0.6  # ceiling objects keep this far from the walls
STATION_CLEAR_M = 1.0  # ... and this far (in plan) from a station below
EXIT_OFFSET_M = 0.6  # a ceiling exit light hangs this far in front of its door
PENDANT_DROP_M = 0.08  # a hanging exit light's top is this far under the ceiling (its rod)
PENDANT_BACK_RGB = (225, 225, 220)  # the plate closing a hanging sign's back
COLUMN_ROOM_MIN_M = 6.0  # a room gets a column if one of its rectangles is this big each way
COLUMN_RECT_M = 0.45  # side of a rectangular column
COLUMN_ROUND_M = 0.50  # diameter of a round column
COLUMN_WALL_CLEAR_M = 1.5  # a column stands at least this far from the walls
COLUMN_STATION_CLEAR_M = 1.0  # ... and from every station
SEEN_COS = 0.35  # a column's side carries objects only if a station sees it at least this straight
ROUND_SEGMENTS = 48  # facets of a round column (sagitta 0.5 mm at 0.25 m radius)

# (class, v) on the faces N, E, S, W of a rectangular column, and (class, angle_deg, v) around a round one
RECT_COLUMN_OBJECTS: dict[str, list[tuple[str, float]]] = {
    "N": [("fire_extinguisher", 1.2), ("extinguisher_sign", 1.95)],
    "E": [("fire_alarm_switch", 1.4), ("fire_alarm_switch_sign", 1.75)],
    "S": [("socket_x1", 0.3)],
    "W": [("switch", 1.1)],
}
ROUND_COLUMN_OBJECTS: list[tuple[str, float, float]] = [
    ("fire_extinguisher", 90.0, 1.2), ("fire_alarm_switch", 210.0, 1.4), ("socket_x1", 330.0, 0.3),
]
_SIDE_NORMALS = {"N": (0.0, 1.0), "E": (1.0, 0.0), "S": (0.0, -1.0), "W": (-1.0, 0.0)}
_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Column:
    """A free-standing column from floor to ceiling (contract 5 ``columns``)."""

    id: str
    room: str
    shape: str  # "rect" | "round"
    centre: tuple[float, float]
    size_m: tuple[float, float]  # x and y extent (the diameter twice for a round one)
    height_m: float
    paint: tuple[int, int, int]
    faces: tuple[str, ...]

    def mesh(self) -> ColouredMesh:
        cx, cy = self.centre
        if self.shape == "rect":
            return M.box((self.size_m[0], self.size_m[1], self.height_m), self.paint, (cx, cy, self.height_m / 2))
        return M.cylinder(self.size_m[0] / 2, self.height_m, self.paint, segments=ROUND_SEGMENTS,
                          centre=(cx, cy, self.height_m / 2))

    def to_truth(self) -> dict:
        doc = {"id": self.id, "room": self.room, "shape": self.shape,
               "centre": [round(c, 4) for c in self.centre], "height_m": round(self.height_m, 4),
               "faces": list(self.faces)}
        if self.shape == "rect":
            doc["size_m"] = [round(s, 4) for s in self.size_m]
        else:
            doc["diameter_m"] = round(self.size_m[0], 4)
        return doc


@dataclass(frozen=True)
class SurfaceObject:
    """An object on a surface: its class, the surface, where on it and the frame it sits in.

    ``frame`` is the plane the object's back lies on, with the object at (``u``, ``v``):
    the surface's own frame, or for a round column the tangent plane at the object.
    """

    class_id: str
    surface: str
    kind: str
    frame: WallFrame
    u: float
    v: float
    rotation_deg: float = 0.0


@dataclass
class SurfacePlan:
    surfaces: list[Surface] = field(default_factory=list)
    columns: list[Column] = field(default_factory=list)
    objects: list[SurfaceObject] = field(default_factory=list)
    pendants: list[tuple[WallFrame, float]] = field(default_factory=list)  # a hanging sign's frame, its ceiling's z

    def pendant_meshes(self) -> list[ColouredMesh]:
        """The plate closing each hanging sign's back and the rod it hangs on."""
        out = []
        for f, ceiling_z in self.pendants:
            out.append(M.quad(f.origin + f.width_m * f.axis_u, -f.width_m * f.axis_u, f.height_m * f.axis_v,
                              PENDANT_BACK_RGB))
            top = f.origin + f.width_m / 2 * f.axis_u + f.height_m * f.axis_v
            rod = ceiling_z - float(top[2])
            out.append(M.box((0.01, 0.01, rod), PENDANT_BACK_RGB, centre=top + np.array([0.0, 0.0, rod / 2])
                             - 0.01 * f.normal))
        return out


def plan_surfaces(scene: SceneDescription, layout: Layout, stations: np.ndarray, *,
                  ceilings: dict[str, float] | None = None) -> SurfacePlan:
    """Ceilings, columns and their objects for the scene's ``ceiling_objects`` / ``columns`` options.

    ``ceilings`` gives a room's ceiling height where it differs from the scene's.
    Deterministic: it depends on the scene and its stations only.
    """
    plan = SurfacePlan()
    if not (scene.ceiling_objects or scene.columns):
        return plan
    heights = {r.id: (ceilings or {}).get(r.id, scene.ceiling_height_m) for r in scene.rooms}
    st = np.asarray(stations, float).reshape(-1, 3)[:, :2]
    if scene.columns:
        _plan_columns(scene, st, heights, plan)
    if scene.ceiling_objects:
        _plan_ceilings(scene, layout, st, heights, plan)
    return plan


# --------------------------------------------------------------------------- ceilings


def ceiling_frame(room: RoomSpec, height_m: float) -> WallFrame:
    """The frame of a room's ceiling seen from below (see the module docstring)."""
    pts = np.asarray(room.outline, float)
    (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
    return WallFrame(origin=np.array([x0, y1, height_m]), axis_u=np.array([1.0, 0.0, 0.0]),
                     axis_v=np.array([0.0, -1.0, 0.0]), normal=np.array([0.0, 0.0, -1.0]),
                     width_m=float(x1 - x0), height_m=float(y1 - y0))


def _plan_ceilings(scene: SceneDescription, layout: Layout, stations: np.ndarray, heights: dict[str, float],
                   plan: SurfacePlan) -> None:
    taken: list[tuple[str, np.ndarray, np.ndarray]] = []  # room, footprint corners lo, hi in plan
    for col in plan.columns:
        c, s = np.asarray(col.centre), np.asarray(col.size_m) / 2 + 0.3
        taken.append((col.room, c - s, c + s))
    frames = {}
    for room in scene.rooms:
        frame = ceiling_frame(room, heights[room.id])
        frames[room.id] = frame
        plan.surfaces.append(Surface(f"{room.id}-C", "ceiling", frame, room=room.id))
        for x0, y0, x1, y1 in merged_cells(room):
            for x in axis_positions(x0, x1, SMOKE_SPACING_M, CEILING_MARGIN_M + 0.5):
                for y in axis_positions(y0, y1, SMOKE_SPACING_M, CEILING_MARGIN_M + 0.5):
                    xy = _away_from_stations(np.array([x, y]), stations, room, (x0, y0, x1, y1), plan.columns)
                    if xy is not None:
                        _try_ceiling(plan, taken, room, frame, class_id="smoke_detector", xy=xy,
                                     rotation_deg=0.0, specs=scene.specs)
    doors = [o for o in layout.openings if o.kind == "door"]
    n_doors: dict[str, int] = {}
    for o in doors:
        room = layout.walls[o.wall].room
        n_doors[room] = n_doors.get(room, 0) + 1
    rooms = {r.id: r for r in scene.rooms}
    lit = {p.wall for p in scene.objects if p.class_id == "exit_light"}
    done: set[int] = set()
    for o in sorted(doors, key=lambda o: (-n_doors[layout.walls[o.wall].room], o.wall, o.u_min)):
        if o.spec_index in done:
            continue
        done.add(o.spec_index)
        if o.wall in lit or (o.partner and o.partner in lit):
            continue
        wall = layout.walls[o.wall]  # the face in the room with more doors: the sort puts it first
        fr = wall.frame
        centre = fr.to_world((o.u_min + o.u_max) / 2, 0.0, EXIT_OFFSET_M)[:2]
        if scene.pendants:
            _try_pendant(plan, taken, rooms[wall.room], fr, xy=centre, ceiling_z=heights[wall.room], specs=scene.specs)
            continue
        turn = math.degrees(math.atan2(-fr.axis_u[1], fr.axis_u[0]))  # wall's u in the ceiling's (u, v)
        _try_ceiling(plan, taken, rooms[wall.room], frames[wall.room], class_id="exit_light",
                     xy=centre, rotation_deg=round(turn, 6),
                     specs=scene.specs)


def _away_from_stations(xy: np.ndarray, stations: np.ndarray, room: RoomSpec,
                        cell: tuple[float, float, float, float], columns: list[Column]) -> np.ndarray | None:
    """The point nearest ``xy`` (within 1.5 m, on a 0.1 m grid, inside ``cell`` kept off its
    sides) that no station stands under and no column stands near; None if there is none."""
    x0, y0, x1, y1 = cell
    m = CEILING_MARGIN_M
    d = np.arange(-1.5, 1.5001, 0.1)
    gx, gy = np.meshgrid(xy[0] + d, xy[1] + d)
    cand = np.column_stack([gx.ravel(), gy.ravel()])
    cand = cand[(cand[:, 0] >= x0 + m) & (cand[:, 0] <= x1 - m) & (cand[:, 1] >= y0 + m) & (cand[:, 1] <= y1 - m)]
    if len(stations) and len(cand):
        clear = np.min(np.linalg.norm(cand[:, None, :] - stations[None], axis=2), axis=1)
        cand = cand[clear >= STATION_CLEAR_M]
    for col in columns:
        if col.room == room.id and len(cand):
            cand = cand[np.linalg.norm(cand - col.centre, axis=1) >= STATION_CLEAR_M]
    if not len(cand):
        return None
    dist = np.linalg.norm(cand - xy, axis=1)
    best = np.lexsort((cand[:, 1], cand[:, 0], np.round(dist, 6)))[0]
    return np.round(cand[best], 3)


def _claim(taken: list, room: RoomSpec, xy: np.ndarray, half: np.ndarray) -> bool:
    """Take the plan footprint ``xy`` +- ``half`` for a ceiling object when it lies in the room
    (0.3 m inside its outline) and 0.2 m clear of every footprint ``taken`` there before."""
    lo, hi = xy - half, xy + half
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    grown = np.vstack([corners + d for d in ((-0.3, -0.3), (0.3, -0.3), (0.3, 0.3), (-0.3, 0.3))])
    if not point_in_outline(grown, room.outline).all():
        return False
    for r, tlo, thi in taken:
        if r == room.id and np.all(np.minimum(hi + 0.2, thi) - np.maximum(lo - 0.2, tlo) > 0):
            return False
    taken.append((room.id, lo, hi))
    return True


def _try_ceiling(plan: SurfacePlan, taken: list, room: RoomSpec, frame: WallFrame, *, class_id: str,
                 xy: np.ndarray, rotation_deg: float, specs: Mapping[str, ObjectSpec]) -> bool:
    """Add a ceiling object at plan position ``xy`` if its footprint (``specs``' size) fits the room and is free."""
    spec = specs[class_id]
    a = math.radians(rotation_deg)
    ca, sa = abs(math.cos(a)), abs(math.sin(a))
    half = np.array([spec.width_m * ca + spec.height_m * sa, spec.width_m * sa + spec.height_m * ca]) / 2
    if not _claim(taken, room, xy, half):
        return False
    uvd = frame.to_uvd(np.array([[xy[0], xy[1], frame.origin[2]]]))[0]
    plan.objects.append(SurfaceObject(class_id, f"{room.id}-C", "ceiling", frame, float(uvd[0]), float(uvd[1]),
                                      rotation_deg))
    return True


def _try_pendant(plan: SurfacePlan, taken: list, room: RoomSpec, wall: WallFrame, *, xy: np.ndarray,
                 ceiling_z: float, specs: Mapping[str, ObjectSpec]) -> bool:
    """Hang an exit light at plan position ``xy``, parallel to ``wall`` and facing the room,
    if its footprint fits the room and is free (see the module docstring)."""
    spec = specs["exit_light"]
    u, n = np.asarray(wall.axis_u, float), np.asarray(wall.normal, float)
    half = np.abs(u[:2]) * spec.width_m / 2 + np.abs(n[:2]) * 0.05
    if not _claim(taken, room, xy, half):
        return False
    bottom = ceiling_z - PENDANT_DROP_M - spec.height_m
    origin = np.array([xy[0], xy[1], bottom]) - spec.width_m / 2 * u
    frame = WallFrame(origin, u.copy(), np.array([0.0, 0.0, 1.0]), n.copy(), float(spec.width_m), float(spec.height_m))
    sid = f"{room.id}-C-P{sum(1 for s in plan.surfaces if s.kind == 'pendant') + 1}"
    plan.surfaces.append(Surface(sid, "pendant", frame, room=room.id, hangs_from=f"{room.id}-C"))
    plan.objects.append(SurfaceObject("exit_light", sid, "ceiling", frame, spec.width_m / 2, spec.height_m / 2))
    plan.pendants.append((frame, ceiling_z))
    return True


# --------------------------------------------------------------------------- columns


def _plan_columns(scene: SceneDescription, stations: np.ndarray, heights: dict[str, float],
                  plan: SurfacePlan) -> None:
    k = 0
    for room in scene.rooms:
        cells = [c for c in merged_cells(room)
                 if min(c[2] - c[0], c[3] - c[1]) >= COLUMN_ROOM_MIN_M]
        if not cells:
            continue
        x0, y0, x1, y1 = max(cells, key=lambda c: (c[2] - c[0]) * (c[3] - c[1]))
        m = COLUMN_WALL_CLEAR_M
        gx, gy = np.meshgrid(np.arange(x0 + m, x1 - m + 1e-9, 0.25), np.arange(y0 + m, y1 - m + 1e-9, 0.25))
        cand = np.column_stack([gx.ravel(), gy.ravel()])
        if not len(cand):
            continue
        clear = (np.min(np.linalg.norm(cand[:, None, :] - stations[None], axis=2), axis=1)
                 if len(stations) else np.full(len(cand), 9.0))
        off_centre = np.linalg.norm(cand - ((x0 + x1) / 2, (y0 + y1) / 2), axis=1)
        rect = (k + 1) % 2 == 1
        dirs = _object_directions(rect)
        seen = np.array([sum(_seen(c, n, half, stations) for n, half in dirs) for c in cand])
        best = int(np.lexsort((off_centre, -np.minimum(clear, 2.5), -seen))[0])
        if clear[best] < COLUMN_STATION_CLEAR_M:
            continue
        k += 1
        centre = (round(float(cand[best, 0]), 3), round(float(cand[best, 1]), 3))
        col_id = f"{room.id}-COL{k}"
        h = heights[room.id]
        if rect:
            _rect_column(plan, col_id, room, centre, h=h, stations=stations)
        else:
            _round_column(plan, col_id, room, centre, h=h, stations=stations)


def _object_directions(rect: bool) -> list[tuple[np.ndarray, float]]:
    """(outward normal in plan, distance of the surface from the axis) of each object-bearing side."""
    if rect:
        return [(np.asarray(_SIDE_NORMALS[side]), COLUMN_RECT_M / 2) for side in RECT_COLUMN_OBJECTS]
    return [(np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))]), COLUMN_ROUND_M / 2)
            for _, deg, _ in ROUND_COLUMN_OBJECTS]


def _seen(centre, normal: np.ndarray, half: float, stations: np.ndarray) -> bool:
    """Whether a station sees the column's side facing ``normal`` at SEEN_COS or straighter."""
    if not len(stations):
        return True
    p = np.asarray(centre, float) + half * np.asarray(normal, float)
    to = stations - p
    dist = np.linalg.norm(to, axis=1)
    return bool(np.any((to @ normal) >= SEEN_COS * np.maximum(dist, 1e-9)))


def _face_frame(centre: np.ndarray, normal_xy: tuple[float, float], half_depth: float, width: float,
                height: float) -> WallFrame:
    """A vertical face at ``half_depth`` from ``centre`` along ``normal_xy``, framed like a wall."""
    n = np.array([normal_xy[0], normal_xy[1], 0.0])
    u = np.cross(_UP, n)
    mid = np.array([centre[0], centre[1], 0.0]) + half_depth * n
    return WallFrame(origin=mid - width / 2 * u, axis_u=u + 0.0, axis_v=_UP.copy(), normal=n + 0.0,
                     width_m=float(width), height_m=float(height))


def _rect_column(plan: SurfacePlan, col_id: str, room: RoomSpec, centre: tuple[float, float], *, h: float,
                 stations: np.ndarray) -> None:
    """A rectangular column and its objects (none on a face that no station sees)."""
    s = COLUMN_RECT_M
    faces = []
    for side, objs in RECT_COLUMN_OBJECTS.items():
        frame = _face_frame(np.asarray(centre), _SIDE_NORMALS[side], s / 2, s, h)
        sid = f"{col_id}-{side}"
        faces.append(sid)
        plan.surfaces.append(Surface(sid, "column", frame, room=room.id, column=col_id))
        if not _seen(centre, np.asarray(_SIDE_NORMALS[side]), s / 2, stations):
            continue
        for cls, v in objs:
            plan.objects.append(SurfaceObject(cls, sid, "column", frame, s / 2, v))
    plan.columns.append(Column(col_id, room.id, "rect", centre, (s, s), h, room.paint, tuple(faces)))


def _round_column(plan: SurfacePlan, col_id: str, room: RoomSpec, centre: tuple[float, float], *, h: float,
                  stations: np.ndarray) -> None:
    """A round column and its objects (none where no station sees it)."""
    r = COLUMN_ROUND_M / 2
    c = np.asarray(centre)
    unrolled = _face_frame(c, (1.0, 0.0), r, 0.0, h)
    unrolled = WallFrame(unrolled.origin, unrolled.axis_u, unrolled.axis_v, unrolled.normal, 2 * math.pi * r, h)
    plan.surfaces.append(Surface(col_id, "column", unrolled, room=room.id, column=col_id, radius_m=r, centre=centre))
    for cls, deg, v in ROUND_COLUMN_OBJECTS:
        a = math.radians(deg)
        if not _seen(centre, np.array([math.cos(a), math.sin(a)]), r, stations):
            continue
        u = r * a
        tangent = _face_frame(c, (math.cos(a), math.sin(a)), r, 0.0, h)
        frame = WallFrame(tangent.origin - u * tangent.axis_u, tangent.axis_u, tangent.axis_v, tangent.normal,
                          2 * math.pi * r, h)  # the object at (u, v) of this frame touches the column
        plan.objects.append(SurfaceObject(cls, col_id, "column", frame, u, v))
    plan.columns.append(Column(col_id, room.id, "round", centre, (2 * r, 2 * r), h, room.paint, (col_id,)))

