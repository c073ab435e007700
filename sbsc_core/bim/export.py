"""As-is IFC export of a detections document (contract 4) with ifcopenshell.

The paper's output (section 6) is "the position (3D coordinates) of the objects
recognized", meant to augment the as-is BIM model. This module writes that model:

- IfcProject / IfcSite / IfcBuilding / IfcBuildingStorey, metres;
- one IfcWall per wall face of the document, placed in its frame (local X = ``axis_u``,
  Z = up, Y = -``normal`` so that the body lies behind the scanned face), a swept-solid
  body ``width_m`` x thickness x ``height_m``;
- each opening an IfcOpeningElement voiding its wall, filled by an IfcDoor / IfcWindow
  (an opening seen from both sides of a partition gets one filling);
- each object with the IFC class and predefined type of its library class (proxy with
  ObjectType where the schema lacks the class, e.g. IfcSign in IFC4), placed relative to
  its wall with the local origin at the footprint centre on the wall plane (the
  detection's ``position``), a box body footprint x depth standing out into the room,
  connected to its wall (IfcRelConnectsElements), contained in the storey, typed by one
  shared type object per class, with the property set ``SBSC_Recognition``;
- the sign-off as an IfcApproval associated with the project and the objects;
- beyond walls (contract 4 ``surfaces``, issue 11): each ceiling an IfcCovering (CEILING), a
  thin plate above its plane, and each column (from its faces, :mod:`.surfaces`) an IfcColumn,
  a rectangle or circle extruded floor to ceiling; an object on a ceiling or a column is
  placed relative to its IfcCovering / IfcColumn (its body standing out into the room) and
  connected to it;
- several storeys (contract 4 ``storeys``): one IfcBuildingStorey each, every wall, surface
  and object contained in its own;
- the project's name, and a header naming the file, the exporting user and organisation;
- GlobalIds that stay the same for the same object across exports and re-runs
  (:func:`stable_guid`: a UUID5 of the project's seed and the object, compressed as IFC
  does), so that what others keep referencing in the model goes on resolving.

:class:`IfcModelBuilder` is shared with :mod:`.design` (the as-designed writer).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import uuid
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import ifcopenshell
import ifcopenshell.api.aggregate
import ifcopenshell.api.context
import ifcopenshell.api.feature
import ifcopenshell.api.geometry
import ifcopenshell.api.owner
import ifcopenshell.api.project
import ifcopenshell.api.pset
import ifcopenshell.api.root
import ifcopenshell.api.spatial
import ifcopenshell.api.type
import ifcopenshell.api.unit
import ifcopenshell.guid
import numpy as np

from ..errors import InputError
from ..io.crs import CRS, parse_crs
from ..io.detections_model import parse_detections, show
from ..io.safe_json import load_json_file
from ..types import ModelLibrary, Surface, WallFrame
from . import DEFAULT_DEPTH_M, PSET_RECOGNITION, ClassTyping, class_typings, normalise_schema
from .georeference import Georeference, plan_georeference, projected_crs_name, write_georeference
from .surfaces import ColumnBody, ceiling_matrix, column_bodies, object_matrix, read_surfaces

WALL_THICKNESS_M = 0.20  # thickness given to a wall face with no partner face behind it
PARTNER_MAX_GAP_M = 0.60  # two opposite faces closer than this are one partition
OPENING_CLEARANCE_M = 0.01  # an opening body sticks out of its wall by this on both sides
DOOR_LEAF_M = 0.05  # thickness of the simple door / window body
CEILING_THICKNESS_M = 0.02  # an IfcCovering (CEILING) is a plate this thick above the scanned plane
REVIEW_STATUSES = ("pending", "accepted", "rejected")


# --------------------------------------------------------------------------- document


@dataclass
class DetectionsDocument:
    """A checked contract-4 document: walls by id, openings and detections as dicts."""

    walls: dict[str, WallFrame]
    openings: list[dict]
    detections: list[dict]
    signoff: dict | None = None
    crs: CRS | None = None  # the scan's coordinate reference system, when recorded
    surfaces: dict[str, Surface] = field(default_factory=dict)  # ceilings and column faces by id
    storeys: list[dict] = field(default_factory=list)  # contract 4 ``storeys`` ({id, floor_z, ceiling_z})
    wall_storeys: dict[str, str] = field(default_factory=dict)  # wall id -> storey id, where given

    def frames(self) -> dict[str, WallFrame]:
        """The frames of walls and surfaces by id (a detection's ``wall`` names one of them)."""
        return {**self.walls, **{k: s.frame for k, s in self.surfaces.items()}}


def review_status(det: dict) -> str:
    """A detection's review status; without a ``review`` key it is pending."""
    review = det.get("review") or {}
    return str(review.get("status", "pending")) if isinstance(review, dict) else "pending"


def parse_detections_document(doc: Any, where: str = "detections") -> DetectionsDocument:
    """Check a contract-4 document (:func:`~sbsc_core.io.detections_model.parse_detections`,
    the same path as ``evaluate``) plus what the BIM side needs: frames that are not
    degenerate, openings that are not empty and known review statuses."""
    model = parse_detections(doc, where)
    walls: dict[str, WallFrame] = {}
    for i, w in enumerate(model.walls):
        frame = WallFrame(origin=np.asarray(w.origin), axis_u=np.asarray(w.axis_u),
                          axis_v=np.asarray(w.axis_v), normal=np.asarray(w.normal),
                          width_m=w.width_m, height_m=w.height_m)
        if np.linalg.norm(frame.axis_u[:2]) < 1e-6:
            raise InputError(f"{where}: walls[{i}]", "degenerate frame (axis_u vertical or zero size)")
        walls[w.id] = frame
    for i, o in enumerate(model.openings):
        if o.u_max <= o.u_min or o.v_max <= o.v_min:
            raise InputError(f"{where}: openings[{i}]", "empty opening (u_max <= u_min or v_max <= v_min)")
    for i, d in enumerate(doc["detections"]):
        status = review_status(d)
        if status not in REVIEW_STATUSES:
            raise InputError(f"{where}: detections[{i}].review.status", f"unknown status {show(status)}")
    signoff = doc.get("signoff") if isinstance(doc.get("signoff"), dict) else None
    crs = CRS.from_dict(doc["crs"], f"{where}: crs") if doc.get("crs") is not None else None
    storeys = [st.model_dump() for st in model.storeys or ()]
    wall_storeys = {w.id: w.storey for w in model.walls if w.storey}
    return DetectionsDocument(walls, list(doc["openings"]), list(doc["detections"]), signoff, crs,
                              surfaces=read_surfaces(doc, where), storeys=storeys, wall_storeys=wall_storeys)


def load_json(path: Path) -> Any:
    """Read a JSON file (bounded depth, keys and size); InputError naming the file otherwise."""
    return load_json_file(path)


# --------------------------------------------------------------------------- geometry


def wall_matrix(frame: WallFrame) -> np.ndarray:
    """4x4 world matrix of a wall: X along the wall, Z up, Y = Z x X (behind the face when
    ``normal`` points into the room), origin at the frame's origin."""
    z = np.array([0.0, 0.0, 1.0])
    x = np.array([frame.axis_u[0], frame.axis_u[1], 0.0])
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, frame.origin
    return m


def face_sign(frame: WallFrame) -> float:
    """+1 when the wall's local Y points away from the room (the usual case), else -1."""
    return 1.0 if float(np.dot(wall_matrix(frame)[:3, 1], frame.normal)) <= 0 else -1.0


def wall_thicknesses(walls: dict[str, WallFrame], default: float = WALL_THICKNESS_M,
                     max_gap: float = PARTNER_MAX_GAP_M) -> dict[str, float]:
    """Thickness behind each face: half the gap to an opposite face behind it (the two
    faces of one partition), else ``default``."""
    out: dict[str, float] = {}
    for wid, f in walls.items():
        best = None
        for oid, g in walls.items():
            if oid == wid or float(np.dot(f.normal, g.normal)) > -0.97:
                continue
            gap = float(np.dot(f.origin - g.origin, f.normal))  # g lies behind f by gap
            if not 0.01 < gap <= max_gap:
                continue
            gu = f.to_uvd(np.stack([g.origin, g.to_world(g.width_m, 0.0)]))[:, 0]
            if min(gu.max(), f.width_m) - max(gu.min(), 0.0) <= 0.05:
                continue
            best = gap if best is None else min(best, gap)
        out[wid] = default if best is None else best / 2.0
    return out


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """3x3 rotation by ``angle`` (radians) about the unit vector ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


# --------------------------------------------------------------------------- builder


def _enum_items(schema: ifcopenshell.ifcopenshell_wrapper.schema_definition, name: str) -> tuple[str, ...]:
    try:
        return tuple(schema.declaration_by_name(name).enumeration_items())
    except (RuntimeError, AttributeError):
        return ()


class IfcModelBuilder:
    """Writes one storey: walls, openings, secondary components, types and approvals."""

    def __init__(self, schema: str = "IFC4", *, project_name: str = "sbsc as-is",
                 storey_elevation: float = 0.0, typings: dict[str, ClassTyping] | None = None,
                 description: str = "") -> None:
        self.schema = normalise_schema(schema)
        self.file = ifcopenshell.api.project.create_file(version=self.schema)
        self._schema_def = ifcopenshell.ifcopenshell_wrapper.schema_by_name(self.file.schema_identifier)
        f = self.file
        if self.schema == "IFC2X3":  # owner history is mandatory there: who and which application
            self._add_owner()
        self.project = ifcopenshell.api.root.create_entity(f, ifc_class="IfcProject", name=project_name)
        if description:
            self.project.Description = description
        units = [ifcopenshell.api.unit.add_si_unit(f, unit_type=t)
                 for t in ("LENGTHUNIT", "AREAUNIT", "VOLUMEUNIT", "PLANEANGLEUNIT")]
        ifcopenshell.api.unit.assign_unit(f, units=units)
        model = ifcopenshell.api.context.add_context(f, context_type="Model")
        self.body = ifcopenshell.api.context.add_context(
            f, context_type="Model", context_identifier="Body", target_view="MODEL_VIEW", parent=model)
        self.site = ifcopenshell.api.root.create_entity(f, ifc_class="IfcSite", name="Site")
        self.building = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuilding", name="Building")
        self.storey = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuildingStorey", name="Scanned floor")
        self.storey.Elevation = float(storey_elevation)
        ifcopenshell.api.aggregate.assign_object(f, products=[self.site], relating_object=self.project)
        ifcopenshell.api.aggregate.assign_object(f, products=[self.building], relating_object=self.site)
        ifcopenshell.api.aggregate.assign_object(f, products=[self.storey], relating_object=self.building)
        self.site.ObjectPlacement = self._placement(None, np.eye(4))
        self.building.ObjectPlacement = self._placement(self.site.ObjectPlacement, np.eye(4))
        self._storey_matrix = np.eye(4)
        self._storey_matrix[2, 3] = float(storey_elevation)
        self.storey.ObjectPlacement = self._placement(self.building.ObjectPlacement, self._storey_matrix)
        self.storeys: dict[str | None, tuple[Any, np.ndarray]] = {None: (self.storey, self._storey_matrix)}
        self.typings = dict(typings or {})
        self.walls: dict[str, Any] = {}
        self.wall_frames: dict[str, WallFrame] = {}
        self.element_storey: dict[str, str | None] = {}  # wall / surface id -> its storey key
        # surface id -> (host element: IfcCovering or IfcColumn, the host's world matrix, the surface)
        self.surface_hosts: dict[str, tuple[Any, np.ndarray, Surface]] = {}
        self.columns: dict[str, Any] = {}
        self._wall_thickness: dict[str, float] = {}
        self._types: dict[str, Any] = {}

    # -- low level ------------------------------------------------------------------

    def _add_owner(self) -> None:
        """The IfcPersonAndOrganization and IfcApplication that every IFC2X3 OwnerHistory names
        (ifcopenshell's ``owner.settings`` find them in the file)."""
        from .. import __version__

        f = self.file
        org = ifcopenshell.api.owner.add_organisation(f, identification="sbsc", name="sbsc")
        person = ifcopenshell.api.owner.add_person(f, identification="sbsc", family_name="sbsc", given_name=None)
        ifcopenshell.api.owner.add_person_and_organisation(f, person=person, organisation=org)
        ifcopenshell.api.owner.add_application(f, application_developer=org, version=__version__,
                                               application_full_name="sbsc", application_identifier="sbsc")

    def _axis2placement(self, m: np.ndarray) -> Any:
        f = self.file
        loc = f.createIfcCartesianPoint([float(x) for x in m[:3, 3]])
        if np.allclose(m[:3, :3], np.eye(3), atol=1e-12):
            return f.createIfcAxis2Placement3D(loc, None, None)
        return f.createIfcAxis2Placement3D(
            loc, f.createIfcDirection([float(x) for x in m[:3, 2]]),
            f.createIfcDirection([float(x) for x in m[:3, 0]]))

    def _placement(self, relative_to: Any, local: np.ndarray) -> Any:
        return self.file.createIfcLocalPlacement(relative_to, self._axis2placement(local))

    def _box_representation(self, size_x: float, size_y: float, size_z: float,
                            corner: tuple[float, float, float]) -> Any:
        """A swept-solid box ``size_x`` x ``size_y`` x ``size_z`` from ``corner`` (local)."""
        f = self.file
        profile = f.createIfcRectangleProfileDef(
            "AREA", None,
            f.createIfcAxis2Placement2D(f.createIfcCartesianPoint([corner[0] + size_x / 2,
                                                                  corner[1] + size_y / 2]), None),
            float(size_x), float(size_y))
        solid = f.createIfcExtrudedAreaSolid(
            profile, f.createIfcAxis2Placement3D(f.createIfcCartesianPoint([0.0, 0.0, float(corner[2])]),
                                                 None, None),
            f.createIfcDirection([0.0, 0.0, 1.0]), float(size_z))
        return f.createIfcShapeRepresentation(self.body, "Body", "SweptSolid", [solid])

    def _assign_body(self, product: Any, rep: Any) -> None:
        ifcopenshell.api.geometry.assign_representation(self.file, product=product, representation=rep)

    def _new_contained(self, ifc_class: str, predefined_type: str | None, name: str,
                       storey: str | None = None) -> Any:
        """A new element contained in the storey ``storey`` (a key of :attr:`storeys`; None or
        an unknown key: the first storey).

        Containment comes before the placement: ``spatial.assign_container`` rewrites an
        existing placement relative to the storey, which would undo "relative to its wall".
        """
        el = ifcopenshell.api.root.create_entity(self.file, ifc_class=ifc_class,
                                                 predefined_type=predefined_type, name=name)
        ifcopenshell.api.spatial.assign_container(self.file, products=[el],
                                                  relating_structure=self._storey(storey)[0])
        return el

    def _storey(self, key: str | None) -> tuple[Any, np.ndarray]:
        return self.storeys.get(key) or self.storeys[None]

    def add_storey(self, key: str, elevation: float, name: str | None = None) -> Any:
        """Another IfcBuildingStorey at ``elevation`` (world Z), looked up by ``key``.

        The first call names and moves the storey made by the constructor (while it holds
        nothing yet, or when it is at the same elevation) instead of adding one.
        """
        f = self.file
        default, matrix = self.storeys[None]
        first = len(self.storeys) == 1
        if first and (not default.ContainsElements or abs(matrix[2, 3] - elevation) < 1e-9):
            default.Name = name or key
            default.Elevation = float(elevation)
            matrix[2, 3] = float(elevation)
            default.ObjectPlacement.RelativePlacement = self._axis2placement(matrix)
            self.storeys[key] = (default, matrix)
            return default
        storey = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuildingStorey", name=name or key)
        storey.Elevation = float(elevation)
        ifcopenshell.api.aggregate.assign_object(f, products=[storey], relating_object=self.building)
        m = np.eye(4)
        m[2, 3] = float(elevation)
        storey.ObjectPlacement = self._placement(self.building.ObjectPlacement, m)
        self.storeys[key] = (storey, m)
        return storey

    def _storey_placement(self, storey: str | None, world: np.ndarray) -> Any:
        """A placement relative to a storey for the world matrix ``world``."""
        element, matrix = self._storey(storey)
        return self._placement(element.ObjectPlacement, np.linalg.inv(matrix) @ world)

    def _has_entity(self, name: str) -> bool:
        try:
            self._schema_def.declaration_by_name(name)
        except RuntimeError:
            return False
        return True

    # -- walls and openings ------------------------------------------------------

    def add_wall(self, wall_id: str, frame: WallFrame, thickness: float = WALL_THICKNESS_M, *,
                 storey: str | None = None) -> Any:
        """An IfcWall behind the face ``frame`` (contract-4 frame), named ``wall_id``."""
        f = self.file
        wall = self._new_contained("IfcWall", "NOTDEFINED", wall_id, storey)
        wall.Tag = wall_id
        wall.Description = f"wall behind the scanned face {wall_id}"
        wall.ObjectPlacement = self._storey_placement(storey, wall_matrix(frame))
        self.element_storey[wall_id] = storey
        offset = 0.0 if face_sign(frame) > 0 else -thickness
        rep = ifcopenshell.api.geometry.add_wall_representation(
            f, context=self.body, length=float(frame.width_m), height=float(frame.height_m),
            thickness=float(thickness), offset=offset)
        self._assign_body(wall, rep)
        self.walls[wall_id] = wall
        self.wall_frames[wall_id] = frame
        self._wall_thickness[wall_id] = float(thickness)
        return wall

    def add_opening(self, wall_id: str, kind: str, *, u_min: float, u_max: float, v_min: float,
                    v_max: float, fill: bool = True, name: str | None = None) -> tuple[Any, Any | None]:
        """An IfcOpeningElement through the wall, filled by an IfcDoor/IfcWindow if ``fill``."""
        f = self.file
        wall = self.walls[wall_id]
        frame = self.wall_frames[wall_id]
        t = self._wall_thickness[wall_id]
        w, h = float(u_max - u_min), float(v_max - v_min)
        opening = ifcopenshell.api.root.create_entity(f, ifc_class="IfcOpeningElement",
                                                      predefined_type="OPENING",
                                                      name=name or f"{kind} opening in {wall_id}")
        local = np.eye(4)
        local[:3, 3] = [float(u_min), 0.0, float(v_min)]
        opening.ObjectPlacement = self._placement(wall.ObjectPlacement, local)
        y0 = (-OPENING_CLEARANCE_M) if face_sign(frame) > 0 else (-t - OPENING_CLEARANCE_M)
        self._assign_body(opening, self._box_representation(w, t + 2 * OPENING_CLEARANCE_M, h, (0.0, y0, 0.0)))
        ifcopenshell.api.feature.add_feature(f, feature=opening, element=wall)
        if not fill:
            return opening, None
        cls = "IfcWindow" if kind == "window" else "IfcDoor"
        filling = self._new_contained(cls, cls[3:].upper(), f"{kind} in {wall_id}", self.element_storey.get(wall_id))
        filling.OverallWidth, filling.OverallHeight = w, h
        filling.ObjectPlacement = self._placement(opening.ObjectPlacement, np.eye(4))
        leaf = min(DOOR_LEAF_M, t)
        yc = (t / 2 if face_sign(frame) > 0 else -t / 2) - leaf / 2
        self._assign_body(filling, self._box_representation(w, leaf, h, (0.0, yc, 0.0)))
        ifcopenshell.api.feature.add_filling(f, opening=opening, element=filling)
        return opening, filling

    # -- ceilings and columns (issue 11) -------------------------------------------

    def add_ceiling(self, surface: Surface, *, storey: str | None = None,
                    thickness: float = CEILING_THICKNESS_M) -> Any:
        """An IfcCovering (CEILING) for a ceiling surface: a plate over its frame's rectangle,
        ``thickness`` thick above the scanned plane, placed in the frame (X = ``axis_u``,
        Z = ``normal``, down into the room)."""
        covering = self._new_contained("IfcCovering", "CEILING", f"ceiling {surface.id}", storey)
        covering.Tag = surface.id
        covering.Description = f"ceiling seen from below: scanned surface {surface.id}"
        m = ceiling_matrix(surface)
        covering.ObjectPlacement = self._storey_placement(storey, m)
        fr = surface.frame
        y0 = 0.0 if float(np.dot(m[:3, 1], fr.axis_v)) >= 0 else -fr.height_m
        self._assign_body(covering, self._box_representation(fr.width_m, fr.height_m, thickness,
                                                             (0.0, y0, -thickness)))
        self.surface_hosts[surface.id] = (covering, m, surface)
        self.element_storey[surface.id] = storey
        return covering

    def add_column(self, body: ColumnBody, surfaces: dict[str, Surface], *, storey: str | None = None) -> Any:
        """An IfcColumn: a rectangle or a circle extruded from the floor to the ceiling, its
        local origin at the centre on the floor; its faces (``surfaces`` by id) host objects."""
        f = self.file
        column = self._new_contained("IfcColumn", "COLUMN", f"column {body.id}", storey)
        column.Tag = body.id
        column.Description = f"free-standing {body.shape} column, scanned faces {', '.join(body.faces)}"
        m = body.matrix()
        column.ObjectPlacement = self._storey_placement(storey, m)
        origin2d = f.createIfcAxis2Placement2D(f.createIfcCartesianPoint([0.0, 0.0]), None)
        if body.shape == "round":
            profile = f.createIfcCircleProfileDef("AREA", None, origin2d, float(body.size_m[0] / 2))
        else:
            profile = f.createIfcRectangleProfileDef("AREA", None, origin2d, float(body.size_m[0]),
                                                     float(body.size_m[1]))
        solid = f.createIfcExtrudedAreaSolid(
            profile, f.createIfcAxis2Placement3D(f.createIfcCartesianPoint([0.0, 0.0, 0.0]), None, None),
            f.createIfcDirection([0.0, 0.0, 1.0]), float(body.height_m))
        self._assign_body(column, f.createIfcShapeRepresentation(self.body, "Body", "SweptSolid", [solid]))
        for sid in body.faces:
            if sid in surfaces:
                self.surface_hosts[sid] = (column, m, surfaces[sid])
                self.element_storey[sid] = storey
        self.columns[body.id] = column
        return column

    def add_surfaces(self, surfaces: dict[str, Surface], storey_of: dict[str, str | None] | None = None) -> None:
        """Every ceiling as an IfcCovering and every column (from its faces) as an IfcColumn."""
        storey_of = storey_of or {}
        for sid, s in surfaces.items():
            if s.kind == "ceiling":
                self.add_ceiling(s, storey=storey_of.get(sid))
        for body in column_bodies(surfaces.values()):
            self.add_column(body, surfaces, storey=storey_of.get(body.faces[0]))

    # -- secondary components ------------------------------------------------------

    def resolve_typing(self, typing: ClassTyping) -> tuple[str, str | None, str | None]:
        """(IFC class, PredefinedType, ObjectType) of a class in this schema.

        A class missing from the schema (IfcSign in IFC4) becomes IfcBuildingElementProxy
        USERDEFINED with the ObjectType; a predefined type missing from the class's enum
        becomes USERDEFINED with that name as ObjectType.
        """
        cls, pre, obj = typing.ifc_class, typing.predefined_type, typing.object_type
        if not self._has_entity(cls) or not self._has_entity(cls + "Type"):
            label = obj or pre or cls.removeprefix("Ifc").upper()
            return "IfcBuildingElementProxy", "USERDEFINED", label
        items = _enum_items(self._schema_def, cls + "TypeEnum")
        if pre is not None and items and pre not in items:
            return cls, "USERDEFINED", obj or pre
        if pre == "USERDEFINED" and not obj:
            obj = typing.class_id.upper()
        return cls, pre, obj

    def type_for(self, typing: ClassTyping) -> Any:
        """The one type object of a class (created on first use)."""
        if typing.class_id in self._types:
            return self._types[typing.class_id]
        cls, pre, obj = self.resolve_typing(typing)
        t = ifcopenshell.api.root.create_entity(self.file, ifc_class=cls + "Type", predefined_type=pre,
                                                name=typing.name)
        t.Tag = typing.class_id
        t.Description = f"sbsc library class {typing.class_id}"
        if obj:
            t.ElementType = obj
        self._types[typing.class_id] = t
        return t

    def typing_of(self, class_id: str, width_m: float = 0.1, height_m: float = 0.1) -> ClassTyping:
        """The library typing of a class, or a proxy typing for a class the library lacks."""
        if class_id in self.typings:
            return self.typings[class_id]
        t = ClassTyping(class_id, class_id, "IfcBuildingElementProxy", "USERDEFINED", class_id.upper(),
                        float(width_m), float(height_m), DEFAULT_DEPTH_M)
        self.typings[class_id] = t
        return t

    def add_component(self, class_id: str, position: np.ndarray, *, wall_id: str | None = None,
                      normal: np.ndarray | None = None, name: str | None = None, tag: str | None = None,
                      width_m: float | None = None, height_m: float | None = None,
                      psets: dict[str, dict[str, Any]] | None = None, rotation_deg: float = 0.0) -> Any:
        """One secondary component, its local origin at ``position`` (footprint centre on the
        wall plane), its body a box footprint x depth standing out into the room.

        On a ceiling or a column (``wall_id`` names a surface added by :meth:`add_surfaces`)
        it is placed relative to its IfcCovering / IfcColumn, turned by ``rotation_deg``
        counter-clockwise seen from the room (contract 4 ``rotation_deg``)."""
        f = self.file
        typing = self.typing_of(class_id, width_m or 0.1, height_m or 0.1)
        cls, pre, obj = self.resolve_typing(typing)
        element = self._new_contained(cls, pre, name or typing.name, self.element_storey.get(wall_id or ""))
        if tag:
            element.Tag = tag
        position = np.asarray(position, dtype=np.float64)
        host = self.surface_hosts.get(wall_id) if wall_id else None
        wall = self.walls.get(wall_id) if wall_id else None
        w, h, d = typing.width_m, typing.height_m, typing.depth_m
        if host is not None:  # on a ceiling or a column: relative to its IfcCovering / IfcColumn
            host_element, host_matrix, surface = host
            m = object_matrix(surface, position)
            if rotation_deg:  # about the normal, towards the room: local +Z on a ceiling, -Y on a column
                axis = np.array([0.0, 0.0, 1.0]) if surface.kind == "ceiling" else np.array([0.0, -1.0, 0.0])
                m[:3, :3] = m[:3, :3] @ _axis_rotation(axis, math.radians(float(rotation_deg)))
            element.ObjectPlacement = self._placement(host_element.ObjectPlacement, np.linalg.inv(host_matrix) @ m)
            if surface.kind == "ceiling":  # local Z points down into the room: the body hangs below
                self._assign_body(element, self._box_representation(w, h, d, (-w / 2, -h / 2, 0.0)))
            else:  # like on a wall: local Y into the column
                self._assign_body(element, self._box_representation(w, d, h, (-w / 2, -d, -h / 2)))
            wall = host_element
        elif wall is not None:
            frame = self.wall_frames[wall_id]
            m = wall_matrix(frame)
            local = np.eye(4)
            local[:3, 3] = m[:3, :3].T @ (position - m[:3, 3])
            element.ObjectPlacement = self._placement(wall.ObjectPlacement, local)
            into_room = -face_sign(frame)  # local Y of the room side
        else:
            m = np.eye(4)
            if normal is not None and np.linalg.norm(np.asarray(normal)[:2]) > 1e-6:
                n = np.array([normal[0], normal[1], 0.0]) / np.linalg.norm(normal[:2])
                m[:3, 0], m[:3, 1] = np.cross(n, [0.0, 0.0, 1.0]), -n
            m[:3, 3] = position
            element.ObjectPlacement = self._storey_placement(None, m)
            into_room = -1.0
        if host is None:
            y0 = -d if into_room < 0 else 0.0
            self._assign_body(element, self._box_representation(w, d, h, (-w / 2, y0, -h / 2)))
        # assign_type moves the predefined type to the type object (IFC4: the occurrence's
        # PredefinedType is only used without a type); ObjectType is kept on both.
        ifcopenshell.api.type.assign_type(f, related_objects=[element], relating_type=self.type_for(typing))
        if obj:
            element.ObjectType = obj
        if wall is not None:
            ifcopenshell.api.geometry.connect_element(f, relating_element=wall, related_element=element,
                                                      description="mounted on")
        for pset_name, props in (psets or {}).items():
            values = {k: v for k, v in props.items() if v is not None}
            if values:
                pset = ifcopenshell.api.pset.add_pset(f, product=element, name=pset_name)
                ifcopenshell.api.pset.edit_pset(f, pset=pset, properties=values)
        return element

    # -- approval and finishing -----------------------------------------------------

    def add_approval(self, signoff: dict, related: Iterable[Any]) -> Any:
        """The sign-off as an IfcApproval (Status APPROVED) given by its person, associated
        with the project and ``related`` objects."""
        f = self.file
        by = str(signoff.get("by") or "unknown")
        counts = signoff.get("counts") or {}
        qualifier = "; ".join(f"{k}={v}" for k, v in sorted(counts.items())) if isinstance(counts, dict) else str(counts)
        if self.schema == "IFC2X3":  # IfcApproval there needs a dated actor relationship: a property set
            pset = ifcopenshell.api.pset.add_pset(f, product=self.project, name="SBSC_SignOff")
            values = {"Status": "APPROVED", "By": by, "At": str(signoff.get("at") or "") or None,
                      "Comment": str(signoff.get("comment") or "") or None, "Counts": qualifier or None}
            ifcopenshell.api.pset.edit_pset(f, pset=pset, properties={k: v for k, v in values.items() if v})
            return pset
        person = ifcopenshell.api.owner.add_person(f, identification=by, family_name=by, given_name=None)
        approval = f.createIfcApproval(
            Identifier="sbsc-signoff", Name="Sign-off of recognized secondary components",
            Description=str(signoff.get("comment") or "") or None,
            TimeOfApproval=str(signoff.get("at")) if signoff.get("at") else None,
            Status="APPROVED", Level=None, Qualifier=qualifier or None,
            RequestingApproval=None, GivingApproval=person)
        f.createIfcRelAssociatesApproval(ifcopenshell.guid.new(), None, "sign-off", None,
                                         [self.project, *related], approval)
        return approval

    def finish(self) -> ifcopenshell.file:
        if self.schema == "IFC2X3":  # relationships made without the API have none yet
            roots = [e for e in self.file.by_type("IfcRoot") if e.OwnerHistory is None]
            if roots:
                history = ifcopenshell.api.owner.create_owner_history(self.file)
                for e in roots:
                    e.OwnerHistory = history
        return self.file


# --------------------------------------------------------------------------- openings


def _same_opening(a: dict, fa: WallFrame, b: dict, fb: WallFrame, tol: float = 0.15) -> bool:
    """Two openings on opposite faces that are one hole through a partition."""
    if a.get("kind") != b.get("kind") or float(np.dot(fa.normal, fb.normal)) > -0.97:
        return False
    ca = fa.to_world((a["u_min"] + a["u_max"]) / 2, (a["v_min"] + a["v_max"]) / 2)
    cb = fb.to_world((b["u_min"] + b["u_max"]) / 2, (b["v_min"] + b["v_max"]) / 2)
    lateral = (ca - cb) - np.dot(ca - cb, fa.normal) * fa.normal
    return (np.linalg.norm(lateral) < tol and abs(float(np.dot(ca - cb, fa.normal))) <= PARTNER_MAX_GAP_M
            and abs((a["u_max"] - a["u_min"]) - (b["u_max"] - b["u_min"])) < tol)


def add_walls_and_openings(builder: IfcModelBuilder, walls: dict[str, WallFrame], openings: list[dict],
                           storey_of: dict[str, str | None] | None = None) -> None:
    """Walls (thickness from partner faces) and their openings; one filling per hole.
    ``storey_of``: the storey key (of ``builder.storeys``) of each wall, where known."""
    thickness = wall_thicknesses(walls)
    storey_of = storey_of or {}
    for wid, frame in walls.items():
        builder.add_wall(wid, frame, thickness[wid], storey=storey_of.get(wid))
    filled: list[dict] = []
    for o in openings:
        frame = walls[o["wall"]]
        twin = any(_same_opening(o, frame, p, walls[p["wall"]]) for p in filled)
        builder.add_opening(o["wall"], str(o.get("kind", "door")), u_min=o["u_min"], u_max=o["u_max"],
                            v_min=o["v_min"], v_max=o["v_max"], fill=not twin)
        if not twin:
            filled.append(o)


def storey_elevation(walls: dict[str, WallFrame]) -> float:
    return float(min(f.origin[2] for f in walls.values())) if walls else 0.0


def storey_of_height(storeys: list[dict], z: float, tol: float = 0.05) -> str | None:
    """The storey (contract 4 ``storeys``) a height belongs to: the highest whose floor is
    below ``z`` (within ``tol``); None without storeys."""
    below = [st for st in storeys if float(st["floor_z"]) <= z + tol]
    if not below:
        return storeys[0]["id"] if storeys else None
    return max(below, key=lambda st: float(st["floor_z"]))["id"]


def add_storeys_and_surfaces(builder: IfcModelBuilder, doc: DetectionsDocument) -> dict[str, str | None]:
    """The document's storeys (one IfcBuildingStorey each), its walls and openings, its
    ceilings and columns; returns each wall's and surface's storey key."""
    for st in sorted(doc.storeys, key=lambda st: float(st["floor_z"])):
        builder.add_storey(st["id"], float(st["floor_z"]), f"storey {st['id']}")
    storey_of: dict[str, str | None] = {}
    if doc.storeys:
        for wid, f in doc.walls.items():
            storey_of[wid] = doc.wall_storeys.get(wid) or storey_of_height(doc.storeys, float(f.origin[2]))
        for sid, s in doc.surfaces.items():
            storey_of[sid] = s.storey or storey_of_height(doc.storeys, float(s.frame.origin[2]))
    add_walls_and_openings(builder, doc.walls, doc.openings, storey_of)
    builder.add_surfaces(doc.surfaces, storey_of)
    return storey_of


# --------------------------------------------------------------------------- export

GUID_NAMESPACE = uuid.UUID("6b0e1c52-6d1e-5b8a-9a51-5b5c0f1e2d29")  # sbsc's namespace of IFC GlobalIds
ASIS_NAME = "sbsc as-is model"


def stable_guid(seed: str, key: str) -> str:
    """The IFC GlobalId of object ``key`` of the project ``seed``: the same on every export.

    A UUID5 (namespace :data:`GUID_NAMESPACE`) of ``seed`` and ``key``, compressed to the
    22 characters of an IFC GlobalId. Objects found by recognition use ``object/<ref>``
    (the reference the review shows, e.g. ``D0007``), the project ``project``.
    """
    return ifcopenshell.guid.compress(uuid.uuid5(GUID_NAMESPACE, f"{seed}|{key}").hex)


def object_guid(seed: str, ref: str) -> str:
    """The GlobalId of the as-is element of the detection ``ref`` (what BCF topics select)."""
    return stable_guid(seed, f"object/{ref}")


def default_guid_seed(document: dict) -> str:
    """A seed for a document without a project: its walls (the same scan gives the same seed)."""
    walls = [[w.get("id"), w.get("origin")] for w in document.get("walls") or [] if isinstance(w, dict)]
    return "doc-" + hashlib.sha1(json.dumps(walls, sort_keys=True, default=str).encode()).hexdigest()[:20]


def _stable_guids(file: ifcopenshell.file, seed: str, fixed: set[int]) -> None:
    """Give every rooted entity not in ``fixed`` (entity ids) a GlobalId from its class, name
    and rank among the entities of that class and name (the file's order is the build order,
    the same for the same document)."""
    seen: Counter[tuple[str, str]] = Counter()
    for e in sorted(file.by_type("IfcRoot"), key=lambda e: e.id()):
        if e.id() in fixed:
            continue
        if e.is_a("IfcProject"):
            e.GlobalId = stable_guid(seed, "project")
            continue
        k = (e.is_a(), str(e.Name or ""))
        e.GlobalId = stable_guid(seed, f"{k[0]}/{k[1]}/{seen[k]}")
        seen[k] += 1


def _header(file: ifcopenshell.file, file_name: str | None, author: str | None,
            organisation: str | None) -> None:
    from .. import __version__

    h = file.header.file_name
    h.name = file_name or "sbsc-as-is.ifc"
    h.author = (author or "sbsc",)
    h.organization = (organisation or "",)
    h.originating_system = f"sbsc {__version__}"
    h.authorization = author or ""


def _recognition_pset(det: dict) -> dict[str, Any]:
    review = det.get("review") if isinstance(det.get("review"), dict) else {}
    def num(key: str) -> float | None:
        v = det.get(key)
        return float(v) if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) else None
    return {
        "Class": det["class"], "DetectionId": str(det["id"]) if det.get("id") is not None else None,
        "Wall": det.get("wall"), "U": num("u"), "V": num("v"),
        "Alpha": num("alpha"), "RhoDepth": num("rho_depth"), "RhoColour": num("rho_colour"),
        "Source": det.get("source"), "ReviewStatus": review_status(det),
        "ReviewedBy": str(review["by"]) if review.get("by") else None,
        "ReviewedAt": str(review["at"]) if review.get("at") else None,
        "ReviewVersion": int(review["version"]) if isinstance(review.get("version"), int) else None,
    }


def _rotation(obj: dict) -> float:
    r = obj.get("rotation_deg")
    return float(r) if isinstance(r, int | float) and not isinstance(r, bool) and math.isfinite(r) else 0.0


def selected_detections(detections: list[dict], accepted_only: bool) -> list[dict]:
    """Accepted only, or everything not rejected (pending ones included)."""
    keep = ("accepted",) if accepted_only else ("accepted", "pending")
    return [d for d in detections if review_status(d) in keep]


def export_ifc(document: dict, *, library: ModelLibrary | None = None, schema: str = "IFC4",
               accepted_only: bool = False, signoff: dict | None = None,
               typings: dict[str, ClassTyping] | None = None, crs: str | CRS | None = None,
               project_name: str | None = None, author: str | None = None, organisation: str | None = None,
               file_name: str | None = None, guid_seed: str | None = None) -> ifcopenshell.file:
    """The as-is IFC model of a detections document (contract 4).

    ``project_name`` (default: the document's ``project_name``) names the IfcProject;
    ``file_name``, ``author`` and ``organisation`` go into the file's header. GlobalIds
    derive from ``guid_seed`` (default: :func:`default_guid_seed`) and each object
    (:func:`stable_guid`): two exports of the same project give the same GlobalIds.

    Rejected detections are never written; ``accepted_only`` drops pending ones too.
    ``signoff`` (``{"by", "at", "comment", "counts"}``, default: the document's
    ``"signoff"``) becomes an IfcApproval (IFC2X3: the property set ``SBSC_SignOff``).
    ``crs`` (``"EPSG:NNNN"``, default: the document's ``crs``) is the scan's coordinate
    system; with it, or with coordinates beyond 1 km, the model is georeferenced (see
    :mod:`.georeference`): local coordinates near the origin and an IfcMapConversion.

    Parameters
    ----------
    document
        A detections document (contract 4), with ``review`` when it comes from the review app.
    library
        The model library whose ``model.json`` give each class its IFC class and type.
    schema
        ``IFC4`` (default), ``IFC4X3`` or ``IFC2X3``.

    Returns
    -------
    ifcopenshell.file
        Walls, openings, storeys, ceilings, columns and the (accepted) objects.
    """
    schema = normalise_schema(schema)
    doc = parse_detections_document(document)
    doc = localised(doc, crs)
    typings = typings if typings is not None else class_typings(library)
    seed = guid_seed or default_guid_seed(document)
    name = project_name or (document.get("project_name") if isinstance(document.get("project_name"), str) else None)
    builder = IfcModelBuilder(schema, project_name=name or ASIS_NAME, typings=typings,
                              storey_elevation=storey_elevation(doc.walls),
                              description="secondary building service components recognized in a scan")
    add_storeys_and_surfaces(builder, doc)
    elements = []
    fixed: set[int] = set()
    for det in selected_detections(doc.detections, accepted_only):
        wall_id = det.get("wall") if det.get("wall") in doc.walls or det.get("wall") in doc.surfaces else None
        normal = None
        if wall_id in doc.surfaces and doc.surfaces[wall_id].kind == "pendant":  # hangs free, facing its normal
            wall_id, normal = None, doc.surfaces[wall_id].frame.normal
        label = str(det.get("id") or "")
        typing = builder.typing_of(det["class"], det.get("width_m") or 0.1, det.get("height_m") or 0.1)
        element = builder.add_component(
            det["class"], np.asarray(det["position"], float), wall_id=wall_id, normal=normal,
            name=f"{typing.name} {label}".strip(), tag=label or None,
            width_m=det.get("width_m"), height_m=det.get("height_m"),
            psets={PSET_RECOGNITION: _recognition_pset(det)}, rotation_deg=_rotation(det))
        if label:
            element.GlobalId = object_guid(seed, label)
            fixed.add(element.id())
        elements.append(element)
    signoff = signoff if signoff is not None else doc.signoff
    if signoff:
        builder.add_approval(signoff, elements)
    if doc.georeference is not None:
        write_georeference(builder.file, doc.georeference)
    model = builder.finish()
    _stable_guids(model, seed, fixed)
    _header(model, file_name, author, organisation)
    return model


@dataclass
class LocalDocument(DetectionsDocument):
    georeference: Georeference | None = None


def localised(doc: DetectionsDocument, crs: str | CRS | None = None) -> LocalDocument:
    """``doc`` in the local frame of its georeference (unchanged when it needs none)."""
    if isinstance(crs, str):
        crs = parse_crs(crs)
    crs = crs or doc.crs
    if crs is not None and not crs.projected:
        crs = None  # degrees are no map coordinates; IfcMapConversion needs a projected CRS
    positions = [np.asarray(d["position"], float) for d in doc.detections]
    geo = plan_georeference(doc.walls, positions, crs)
    same = {"surfaces": doc.surfaces, "storeys": doc.storeys, "wall_storeys": doc.wall_storeys}
    if geo is None:
        return LocalDocument(doc.walls, doc.openings, doc.detections, doc.signoff, doc.crs, **same, georeference=None)
    walls = {k: geo.local_frame(f) for k, f in doc.walls.items()}
    dets = [{**d, "position": [float(c) for c in geo.to_local(p)]} for d, p in zip(doc.detections, positions, strict=True)]
    surfaces = {k: replace(s, frame=geo.local_frame(s.frame),
                           centre=None if s.centre is None else
                           tuple(float(c) for c in geo.to_local([*s.centre, 0.0])[:2]))
                for k, s in doc.surfaces.items()}
    return LocalDocument(walls, doc.openings, dets, doc.signoff, crs, **{**same, "surfaces": surfaces},
                         georeference=geo)


def write_ifc_atomic(model: ifcopenshell.file, out: Path) -> None:
    """Write ``model`` to ``out`` via a temporary file and an atomic rename."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.partial-", suffix=".ifc", dir=out.parent)
    os.close(fd)
    try:
        model.write(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def export_ifc_file(detections: Path, out: Path, *, schema: str = "IFC4", accepted_only: bool = False,
                    models: Path | None = None, crs: str | None = None) -> dict[str, Any]:
    """``sbsc export-ifc``: read ``detections``, write ``out`` (nothing on error).

    Parameters
    ----------
    detections
        A detections document (contract 4).
    out
        The IFC file to write (atomically).
    schema
        ``IFC4``, ``IFC4X3`` or ``IFC2X3``.
    accepted_only
        Only the detections a reviewer accepted.
    models
        The model library whose ``model.json`` give each class's IFC class; None: the bundled one.
    crs
        The scan's coordinate system (``"EPSG:NNNN"``) to georeference the model in; None:
        the document's ``crs``, if any.

    Returns
    -------
    dict
        A summary: the schema, the coordinate system and how many walls, openings, ceilings,
        columns and objects were written.
    """
    detections = Path(detections)
    schema = normalise_schema(schema, where="--schema")
    typings = class_typings(models=Path(models)) if models is not None else class_typings()
    raw = load_json(detections)
    parse_detections_document(raw, where=str(detections))
    model = export_ifc(raw, schema=schema, accepted_only=accepted_only, typings=typings,
                       crs=parse_crs(crs, "--crs") if crs else None, file_name=Path(out).name,
                       author=os.environ.get("USER") or None)
    write_ifc_atomic(model, out)
    return {"schema": schema, "crs": projected_crs_name(model), "walls": len(model.by_type("IfcWall")),
            "openings": len(model.by_type("IfcOpeningElement")),
            "ceilings": len(model.by_type("IfcCovering")), "columns": len(model.by_type("IfcColumn")),
            "objects": len(selected_detections(raw.get("detections", []), accepted_only))}
