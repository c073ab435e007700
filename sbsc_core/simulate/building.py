"""A scene description turned into a coloured triangle mesh plus its ground truth.

The mesh holds the floor and ceiling slabs, every room-side wall face with its holes, the
reveals of the openings (in the frame colour), door casings on both faces of a door, a
window frame inside each window reveal, and the objects built by
:func:`sbsc_core.simulate.objects.build_object` placed on their walls. Objects carry their
index as triangle label; the building carries -1.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from ..types import WallFrame
from . import mesh as M
from .catalogue import CATALOGUE, CLASS_ORDER, ObjectSpec
from .mesh import ColouredMesh
from .realism import CLASS_GLOSS
from .scene import (
    Layout,
    OpeningPlacement,
    RoomSpec,
    SceneDescription,
    WallFace,
    axis_positions,
    merged_cells,
    validate_scene,
)

ObjectBuilder = Callable[[str], ColouredMesh]

CASING_DEPTH_M = 0.015  # how far a door casing stands out of the wall
WINDOW_PROFILE_M = 0.06  # width and depth of a window frame's profile


@dataclass
class PlacedObject:
    """One object of the scene in the world (contract 5 plus its wall and u, v)."""

    index: int
    class_id: str
    wall: str
    u: float
    v: float
    position: np.ndarray  # (3,) centre of the footprint on the wall plane
    normal: np.ndarray  # (3,) wall normal, into the room
    width_m: float
    height_m: float
    rotation_deg: float = 0.0  # in-plane turn seen from the room, counter-clockwise
    surface: str = "wall"  # the kind of surface it is on: wall, ceiling or column
    frame: WallFrame | None = None  # the plane it sits on, when not its wall's (ceilings, columns)

    def to_truth(self) -> dict:
        return {
            "class": self.class_id,
            "position": [round(float(x), 5) for x in self.position],
            "normal": [round(float(x), 6) for x in self.normal],
            "width_m": round(self.width_m, 4),
            "height_m": round(self.height_m, 4),
            "wall": self.wall,
            "u": round(self.u, 5),
            "v": round(self.v, 5),
            "rotation_deg": round(float(self.rotation_deg), 3),
        }


@dataclass
class Building:
    scene: SceneDescription
    layout: Layout
    mesh: ColouredMesh
    objects: list[PlacedObject]
    stations: np.ndarray  # (S, 3) scanner origins, world
    distractors: list = field(default_factory=list)  # clutter.Distractor: clutter and furniture
    surfaces: list = field(default_factory=list)  # types.Surface: ceilings and column faces
    columns: list = field(default_factory=list)  # surfaces.Column

    def frame_of(self, obj: PlacedObject) -> WallFrame:
        """The plane ``obj`` sits on (its wall's frame, or its ceiling's or column's)."""
        return obj.frame if obj.frame is not None else self.layout.walls[obj.wall].frame

    def truth_document(self) -> dict:
        """``ground_truth.json`` (contract 5, extended with walls and openings; with clutter or
        furniture, the top-level ``distractors``; with ceiling objects or columns, each object's
        ``surface`` and the top-level ``surfaces`` and ``columns``)."""
        doc = {
            "schema": "sbsc.truth/1",
            "scene": self.scene.name,
            "objects": [o.to_truth() for o in self.objects],
            "walls": [{"id": w.id, "room": w.room, **w.frame.to_dict()} for w in self.layout.walls.values()],
            "openings": [o.to_dict() for o in self.layout.openings],
            "stations": [[round(float(x), 4) for x in s] for s in self.stations],
        }
        if self.scene.clutter_per_metre or self.scene.furniture_per_metre or self.distractors:
            doc["distractors"] = [d.to_truth(self.layout) for d in self.distractors]
        if self.surfaces or self.columns:
            for o, d in zip(self.objects, doc["objects"], strict=True):
                d["surface"] = o.surface
            doc["surfaces"] = [s.to_dict(digits=6) for s in self.surfaces]
            doc["columns"] = [c.to_truth() for c in self.columns]
        return doc

    def expected_document(self) -> dict:
        """``expected.json`` (contract 3): instances per class present in the scene."""
        counts = {c: 0 for c in CLASS_ORDER}
        for o in self.objects:
            counts[o.class_id] = counts.get(o.class_id, 0) + 1
        return {"schema": "sbsc.expected/1", "counts": {c: n for c, n in counts.items() if n}}


def build_building(scene: SceneDescription, object_builder: ObjectBuilder | None = None,
                   seed: int = 0) -> Building:
    """Mesh and truth of a (validated) description.

    With the description's ``clutter`` / ``furniture`` options, distractors are laid out
    for ``seed`` (:mod:`clutter`) and added to the mesh (label -2).
    """
    if object_builder is None:
        from .objects import build_object as object_builder
    scene = sized_for(scene, object_builder)
    layout = validate_scene(scene)
    parts: list[ColouredMesh] = [_slabs(scene)]
    for wall in layout.walls.values():
        parts.append(wall_face_mesh(wall, layout.openings_on(wall.id)))
    first = {}
    for o in layout.openings:
        first.setdefault(o.spec_index, o)
    for o in layout.openings:
        parts.append(_casing(layout.walls[o.wall].frame, o, scene))
    for o in first.values():
        parts.append(_reveal(layout.walls[o.wall].frame, o, scene))
    objects = []
    for p in scene.objects:
        wall = layout.walls[p.wall]
        spec = scene.specs[p.class_id]
        local = object_builder(p.class_id)
        local = local.glossy(CLASS_GLOSS.get(p.class_id, 0.0))
        turn = _rotation(wall.frame) @ _in_plane(p.rotation_deg)
        parts.append(local.transformed(turn, wall.frame.to_world(p.u, p.v)).labelled(p.index))
        objects.append(PlacedObject(p.index, p.class_id, p.wall, p.u, p.v, wall.frame.to_world(p.u, p.v),
                                    wall.frame.normal.copy(), spec.width_m, spec.height_m, p.rotation_deg))
    stations = station_positions(scene)
    surfaces, columns = add_surface_objects(scene, layout, stations, object_builder, parts=parts, objects=objects)
    distractors = add_distractors(scene, layout, stations, seed, parts)
    return Building(scene, layout, M.merge(parts), objects, stations, distractors, surfaces, columns)


def sized_for(scene: SceneDescription, object_builder: ObjectBuilder | None) -> SceneDescription:
    """``scene`` with the object sizes of ``object_builder``'s design family.

    A builder whose designs have sizes of their own (a random family,
    :mod:`~sbsc_core.simulate.designs_random`) carries them as ``specs``; the fixed design
    sets build every class in its catalogue footprint, and their scenes keep the catalogue.
    """
    specs = builder_specs(object_builder)
    return scene if specs is scene.specs else dataclasses.replace(scene, specs=specs)


def builder_specs(object_builder: ObjectBuilder | None) -> Mapping[str, ObjectSpec]:
    """The sizes of ``object_builder``'s designs: its ``specs`` if it has any, else the catalogue."""
    return getattr(object_builder, "specs", CATALOGUE)


def add_distractors(scene: SceneDescription, layout: Layout, stations: np.ndarray, seed: int | tuple[int, ...],
                    parts: list[ColouredMesh]) -> list:
    """Wall clutter and furniture of the scene's ``clutter`` / ``furniture`` options (:mod:`clutter`).

    Laid out for ``seed`` (an int, or ``(seed, storey)`` in a building) around the scene's
    objects, openings and ``stations``; appends their meshes (label -2) to ``parts`` and
    returns the distractors. Nothing when both options are off.
    """
    if not (scene.clutter_per_metre or scene.furniture_per_metre):
        return []
    from .clutter import distractor_mesh, place_clutter, place_furniture

    distractors = []
    if scene.clutter_per_metre:
        distractors += place_clutter(scene, layout, seed, scene.clutter_per_metre)
    if scene.furniture_per_metre:
        distractors += place_furniture(scene, layout, stations, seed, per_metre=scene.furniture_per_metre,
                                       existing=distractors)
    parts += [distractor_mesh(d, layout) for d in distractors]
    return distractors


def add_surface_objects(scene: SceneDescription, layout: Layout, stations: np.ndarray,
                        object_builder: ObjectBuilder, *, parts: list[ColouredMesh],
                        objects: list[PlacedObject],
                        ceilings: dict[str, float] | None = None) -> tuple[list, list]:
    """Columns and objects on ceilings and columns (the scene's options; :mod:`surfaces`).

    Appends their meshes to ``parts`` and the objects to ``objects`` (indices after the
    scene's), returns the surfaces and columns. Nothing when both options are off.
    """
    from .surfaces import plan_surfaces

    plan = plan_surfaces(scene, layout, stations, ceilings=ceilings)
    parts += [c.mesh() for c in plan.columns] + plan.pendant_meshes()
    index = max((o.index for o in objects), default=-1) + 1
    for k, so in enumerate(plan.objects):
        spec = scene.specs[so.class_id]
        local = object_builder(so.class_id).glossy(CLASS_GLOSS.get(so.class_id, 0.0))
        turn = _rotation(so.frame) @ _in_plane(so.rotation_deg)
        where = so.frame.to_world(so.u, so.v)
        parts.append(local.transformed(turn, where).labelled(index + k))
        objects.append(PlacedObject(index + k, so.class_id, so.surface, so.u, so.v, where, so.frame.normal.copy(),
                                    spec.width_m, spec.height_m, so.rotation_deg, so.kind, so.frame))
    return plan.surfaces, plan.columns


def station_positions(scene: SceneDescription) -> np.ndarray:
    """The description's stations, or a plan of about one per ``station_spacing_m`` per room."""
    if scene.stations:
        return np.array([s.xyz for s in scene.stations], float)
    out = []
    for room in scene.rooms:
        for xy in plan_stations(room, scene.scanner.station_spacing_m):
            out.append((xy[0], xy[1], scene.scanner.height_m))
    return np.array(out, float).reshape(-1, 3)


def plan_stations(room: RoomSpec, spacing_m: float, clearance_m: float = 1.8) -> list[tuple[float, float]]:
    """Station positions for a room: a grid over each rectangle of the room.

    Stations keep ``clearance_m`` from the walls where the room allows (about the distance
    at which a scanner 1.5 m high with a -40 degree field still sees the foot of a wall)
    and are about ``spacing_m`` apart. In a narrow strip (a corridor) they zigzag across it
    so that each long wall is also seen from its far side.
    """
    out: list[tuple[float, float]] = []
    for x0, y0, x1, y1 in merged_cells(room):
        xs = axis_positions(x0, x1, spacing_m, clearance_m)
        ys = axis_positions(y0, y1, spacing_m, clearance_m)
        for i, x in enumerate(xs):
            for j, y in enumerate(ys):
                if len(ys) == 1 and len(xs) > 1 and y1 - y0 < 1.5 * clearance_m:
                    y += (y1 - y0) * (0.15 if i % 2 else -0.15)
                elif len(xs) == 1 and len(ys) > 1 and x1 - x0 < 1.5 * clearance_m:
                    x += (x1 - x0) * (0.15 if j % 2 else -0.15)
                out.append((round(x, 3), round(y, 3)))
    return out




def wall_face_mesh(wall: WallFace, holes: list[OpeningPlacement]) -> ColouredMesh:
    """The wall's rectangle minus its holes, as grid-cell quads in the wall's paint."""
    fr = wall.frame
    us = {0.0, fr.width_m}
    vs = {0.0, fr.height_m}
    for h in holes:
        us |= {min(max(h.u_min, 0.0), fr.width_m), min(max(h.u_max, 0.0), fr.width_m)}
        vs |= {min(max(h.v_min, 0.0), fr.height_m), min(max(h.v_max, 0.0), fr.height_m)}
    us_, vs_ = sorted(us), sorted(vs)
    quads = []
    for u0, u1 in zip(us_[:-1], us_[1:], strict=True):
        for v0, v1 in zip(vs_[:-1], vs_[1:], strict=True):
            uc, vc = (u0 + u1) / 2, (v0 + v1) / 2
            if any(h.u_min < uc < h.u_max and h.v_min < vc < h.v_max for h in holes):
                continue
            quads.append(M.quad(fr.to_world(u0, v0), (u1 - u0) * fr.axis_u, (v1 - v0) * fr.axis_v, wall.paint))
    return M.merge(quads)


def _in_plane(deg: float) -> np.ndarray:
    """Object-local turn by ``deg`` about the wall normal (counter-clockwise seen from the room)."""
    a = np.deg2rad(float(deg))
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def _rotation(fr: WallFrame) -> np.ndarray:
    """Object-local (x right, y up, z out of the wall) to world."""
    return np.column_stack([fr.axis_u, fr.axis_v, fr.normal])


def _local_box(fr: WallFrame, u0: float, u1: float, v0: float, v1: float, *, d0: float, d1: float,
               colour) -> ColouredMesh:
    """A box given in the wall's (u, v, d) coordinates."""
    b = M.box((u1 - u0, v1 - v0, d1 - d0), colour, ((u0 + u1) / 2, (v0 + v1) / 2, (d0 + d1) / 2))
    return b.transformed(_rotation(fr), fr.origin)


def _casing(fr: WallFrame, o: OpeningPlacement, scene: SceneDescription) -> ColouredMesh:
    """Door casing (a frame standing out of the wall) around a door on one face."""
    fw = scene.door_frame_width_m
    if o.kind != "door" or fw <= 0:
        return ColouredMesh.empty()
    c = scene.colours["door_frame"]
    top = o.v_max + fw
    return M.merge([
        _local_box(fr, o.u_min - fw, o.u_min, 0.0, top, d0=0.0, d1=CASING_DEPTH_M, colour=c),
        _local_box(fr, o.u_max, o.u_max + fw, 0.0, top, d0=0.0, d1=CASING_DEPTH_M, colour=c),
        _local_box(fr, o.u_min, o.u_max, o.v_max, top, d0=0.0, d1=CASING_DEPTH_M, colour=c),
    ])


def _reveal(fr: WallFrame, o: OpeningPlacement, scene: SceneDescription) -> ColouredMesh:
    """The faces inside the hole through the wall (and a window frame in a window)."""
    d = o.depth_m
    c = scene.colours["door_frame" if o.kind == "door" else "window_frame"]
    u0, u1, v0, v1 = o.u_min, o.u_max, o.v_min, o.v_max
    n, up, along = fr.normal, fr.axis_v, fr.axis_u
    parts = [
        M.quad(fr.to_world(u0, v0, -d), d * n, (v1 - v0) * up, c),
        M.quad(fr.to_world(u1, v0, -d), (v1 - v0) * up, d * n, c),
        M.quad(fr.to_world(u0, v1, -d), (u1 - u0) * along, d * n, c),
    ]
    if v0 > 0:
        parts.append(M.quad(fr.to_world(u0, v0, -d), d * n, (u1 - u0) * along, c))
    if o.kind == "window":
        p = min(WINDOW_PROFILE_M, (u1 - u0) / 4, (v1 - v0) / 4)
        dm0, dm1 = -d / 2 - p / 2, -d / 2 + p / 2
        parts += [
            _local_box(fr, u0, u0 + p, v0, v1, d0=dm0, d1=dm1, colour=c),
            _local_box(fr, u1 - p, u1, v0, v1, d0=dm0, d1=dm1, colour=c),
            _local_box(fr, u0 + p, u1 - p, v0, v0 + p, d0=dm0, d1=dm1, colour=c),
            _local_box(fr, u0 + p, u1 - p, v1 - p, v1, d0=dm0, d1=dm1, colour=c),
            _local_box(fr, (u0 + u1 - p) / 2, (u0 + u1 + p) / 2, v0 + p, v1 - p, d0=dm0, d1=dm1, colour=c),
        ]
    return M.merge(parts)


def _slabs(scene: SceneDescription) -> ColouredMesh:
    """Floor and ceiling over the whole floor plate (walls stand on / reach up to them)."""
    pts = np.concatenate([np.asarray(r.outline, float) for r in scene.rooms])
    t = scene.exterior_wall_thickness_m
    x0, y0 = pts.min(axis=0) - t
    x1, y1 = pts.max(axis=0) + t
    h = scene.ceiling_height_m
    floor = M.quad((x0, y0, 0.0), (x1 - x0, 0, 0), (0, y1 - y0, 0), scene.colours["floor"])
    ceiling = M.quad((x0, y0, h), (0, y1 - y0, 0), (x1 - x0, 0, 0), scene.colours["ceiling"])
    return M.merge([floor, ceiling])


