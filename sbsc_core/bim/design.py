"""As-designed IFC: read the secondary components it holds (writing one for the simulator is
:mod:`.design_writer`).

The paper (section 6) leaves open what to say about objects the as-designed model holds
but the scan does not show, and about found objects the design does not hold. Reading the
design gives the expected objects: per class (contract 3 counts, the ``expected.json`` of
``sbsc detect``) and, where a scanned wall can be matched by geometry, per wall.

Reading maps an element to a library class by, in order: the ``Class`` property of an
sbsc property set; the IFC class + predefined type + ObjectType of the library's
``model.json`` (an IfcBuildingElementProxy with the right ObjectType stands for a class the
schema lacks, e.g. IfcSign in IFC4); among several classes of one IFC typing (the sockets),
the type's or element's name/tag naming the class, then the footprint size closest to the
model's. Each object's position is the centre of its body's footprint projected onto the
face of its host wall (the wall it is connected to, else the nearest wall face in front of
which it stands), as in contract 4.

Beyond walls (issue 11): an IfcCovering is a ceiling (seen from below: the plane of its
body's underside) and an IfcColumn a free-standing column (four faces when its body is a
rectangle, a cylinder when it is round). An object connected to one, or else standing
close under a ceiling or beside a column, has its position on that surface (a round
column: on the cylinder) and ``surface`` ``ceiling`` or ``column``.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import ifcopenshell
import ifcopenshell.geom
import ifcopenshell.util.element
import ifcopenshell.util.placement
import ifcopenshell.util.shape
import ifcopenshell.util.unit
import numpy as np

from ..errors import InputError
from ..types import ModelLibrary, Surface, WallFrame
from . import PSET_DESIGN, PSET_RECOGNITION, ClassTyping, class_typings
from .surfaces import surface_coords, surface_normal, tangent_frame

READABLE_SCHEMAS = ("IFC2X3", "IFC4", "IFC4X3")
HOST_MAX_DISTANCE_M = 0.60  # an object's centre may stand this far in front of its wall face
HOST_MARGIN_M = 0.10  # ... and this far beyond the face's edges
SCAN_WALL_PLANE_TOL_M = 0.15  # a designed position is on a scanned wall within this distance
SCAN_WALL_MARGIN_M = 0.10  # ... and this far beyond its edges
DEFAULT_MOUNT_HEIGHT_M = 1.2  # an added designed object of a class that is not built, without a mount height
_SKIP_CLASSES = ("IfcWall", "IfcFeatureElement", "IfcDoor", "IfcWindow", "IfcSlab", "IfcSpace",
                 "IfcCovering", "IfcRoof", "IfcStair", "IfcColumn", "IfcBeam")


@dataclass
class DesignWall:
    """A wall of the design with its two faces as contract-4 frames (front: -local Y)."""

    guid: str
    name: str
    front: WallFrame
    back: WallFrame
    thickness_m: float

    @property
    def faces(self) -> tuple[WallFrame, WallFrame]:
        return (self.front, self.back)


@dataclass
class DesignedObject:
    """One secondary component of the design, mapped to a library class."""

    guid: str
    name: str
    class_id: str
    ifc_class: str
    predefined_type: str | None
    object_type: str | None
    position: np.ndarray  # (3,) world: footprint centre on the host wall face (else body centre)
    normal: np.ndarray | None  # the host face's normal (into the room), None without host
    wall_guid: str | None
    wall_name: str | None
    u: float | None  # in the host face's frame
    v: float | None
    width_m: float | None
    height_m: float | None
    matched_by: str  # pset | typing | name | size | ambiguous
    surface: str = "wall"  # the kind of its host: wall, ceiling or column (issue 11)

    def to_dict(self) -> dict:
        return {
            "guid": self.guid, "name": self.name, "class": self.class_id, "ifc_class": self.ifc_class,
            "predefined_type": self.predefined_type, "object_type": self.object_type,
            "position": [round(float(x), 5) for x in self.position],
            "normal": None if self.normal is None else [round(float(x), 5) for x in self.normal],
            "wall_guid": self.wall_guid, "wall_name": self.wall_name,
            "u": None if self.u is None else round(self.u, 5), "v": None if self.v is None else round(self.v, 5),
            "width_m": None if self.width_m is None else round(self.width_m, 4),
            "height_m": None if self.height_m is None else round(self.height_m, 4),
            "matched_by": self.matched_by, "surface": self.surface,
        }


@dataclass
class DesignHost:
    """A ceiling (IfcCovering) or column (IfcColumn) of the design with its surfaces: a
    ceiling's underside, a rectangular column's four faces or a round column's cylinder."""

    guid: str
    name: str
    kind: str  # "ceiling" | "column"
    surfaces: list[Surface]


@dataclass
class AsDesigned:
    """The secondary components of an as-designed IFC file."""

    path: str
    schema: str
    project_guid: str | None
    walls: list[DesignWall]
    objects: list[DesignedObject]
    unmapped: list[dict] = field(default_factory=list)  # {ifc_class, predefined_type, object_type, count}
    hosts: list[DesignHost] = field(default_factory=list)  # ceilings and columns (issue 11)

    def expected_counts(self) -> dict[str, int]:
        return dict(sorted(Counter(o.class_id for o in self.objects).items()))

    def expected_document(self) -> dict:
        """Contract 3 ``expected.json``."""
        return {"schema": "sbsc.expected/1", "counts": self.expected_counts()}

    def scan_walls_of_objects(self, walls: dict[str, WallFrame]) -> list[str | None]:
        """The scanned wall (contract-4 id) each object lies on, None when on none."""
        return [locate_on_walls(o.position, o.normal, walls) for o in self.objects]

    def expected_by_wall(self, walls: dict[str, WallFrame]) -> dict[str, dict[str, int]]:
        """Per scanned wall, how many objects of each class the design puts on it."""
        out: dict[str, Counter] = {}
        for o, wid in zip(self.objects, self.scan_walls_of_objects(walls), strict=True):
            if wid is not None:
                out.setdefault(wid, Counter())[o.class_id] += 1
        return {wid: dict(sorted(c.items())) for wid, c in sorted(out.items())}

    def wall_matches(self, walls: dict[str, WallFrame]) -> dict[str, list[str]]:
        """Design wall GUID -> scanned walls lying on one of its faces."""
        out: dict[str, list[str]] = {}
        for dw in self.walls:
            hits = [wid for wid, f in walls.items() if any(_faces_match(face, f) for face in dw.faces)]
            if hits:
                out[dw.guid] = sorted(hits)
        return out


# --------------------------------------------------------------------------- geometry helpers


def _faces_match(face: WallFrame, scan: WallFrame, angle_cos: float = 0.98) -> bool:
    """A scanned wall lies on a design face: parallel, same side, close plane, overlap."""
    if float(np.dot(face.normal, scan.normal)) < angle_cos:
        return False
    ends = np.stack([scan.origin + 0.5 * scan.height_m * scan.axis_v,
                     scan.to_world(scan.width_m, 0.5 * scan.height_m)])
    uvd = face.to_uvd(ends)
    if np.abs(uvd[:, 2]).max() > SCAN_WALL_PLANE_TOL_M:
        return False
    lo, hi = uvd[:, 0].min(), uvd[:, 0].max()
    return min(hi, face.width_m) - max(lo, 0.0) > 0.2 * min(scan.width_m, face.width_m)


def locate_on_walls(position: np.ndarray, normal: np.ndarray | None, walls: dict[str, WallFrame],
                    plane_tol: float = SCAN_WALL_PLANE_TOL_M, margin: float = SCAN_WALL_MARGIN_M) -> str | None:
    """The wall whose face ``position`` lies on (within ``plane_tol`` of its plane, inside its
    rectangle grown by ``margin``, facing the same way as ``normal`` when given)."""
    best, best_d = None, np.inf
    for wid, f in walls.items():
        if normal is not None and float(np.dot(normal, f.normal)) < 0.5:
            continue
        u, v, d = f.to_uvd(np.asarray(position, float)[None])[0]
        if abs(d) > plane_tol or not (-margin <= u <= f.width_m + margin and -margin <= v <= f.height_m + margin):
            continue
        if abs(d) < best_d:
            best, best_d = wid, abs(d)
    return best


def _horizontal(x: np.ndarray) -> np.ndarray | None:
    h = np.array([x[0], x[1], 0.0])
    n = np.linalg.norm(h)
    return h / n if n > 1e-9 else None


def _wall_faces(matrix: np.ndarray, verts_world: np.ndarray) -> tuple[WallFrame, WallFrame, float]:
    """Front/back face frames of a wall from its placement and world vertices."""
    x = _horizontal(matrix[:3, 0])
    if x is None:  # placement X vertical: take the main horizontal direction of the body
        xy = verts_world[:, :2] - verts_world[:, :2].mean(0)
        x = np.array([*np.linalg.svd(xy, full_matrices=False)[2][0], 0.0])
    z = np.array([0.0, 0.0, 1.0])
    y = np.cross(z, x)
    o = matrix[:3, 3]
    rel = verts_world - o
    a, b, c = rel @ x, rel @ y, verts_world[:, 2]
    a0, a1, b0, b1, c0, c1 = a.min(), a.max(), b.min(), b.max(), c.min(), c.max()
    width, height = float(a1 - a0), float(c1 - c0)
    front_o = o + a0 * x + b0 * y
    front_o[2] = c0
    back_o = o + a1 * x + b1 * y
    back_o[2] = c0
    front = WallFrame(front_o, x, z, -y, width, height)
    back = WallFrame(back_o, -x, z, y, width, height)
    return front, back, float(b1 - b0)


def _ceiling_surface(guid: str, matrix: np.ndarray, verts: np.ndarray) -> Surface:
    """The underside of a covering as a ceiling surface (contract 4: normal down, ``axis_u``
    along the placement's X, origin where u and v are smallest)."""
    x = _horizontal(matrix[:3, 0])
    if x is None:
        x = np.array([1.0, 0.0, 0.0])
    n = np.array([0.0, 0.0, -1.0])
    v_axis = np.cross(n, x)
    a, b = verts @ x, verts @ v_axis
    z = float(verts[:, 2].min())
    origin = a.min() * x + b.min() * v_axis
    origin[2] = z
    return Surface(guid, "ceiling", WallFrame(origin, x, v_axis, n, float(np.ptp(a)), float(np.ptp(b))))


def _column_surfaces(el: Any, matrix: np.ndarray, verts: np.ndarray) -> list[Surface]:
    """A column's faces: four (framed like walls seen from outside) or one round surface."""
    guid = el.GlobalId
    z0, z1 = float(verts[:, 2].min()), float(verts[:, 2].max())
    circle = any(it.is_a("IfcExtrudedAreaSolid") and it.SweptArea.is_a("IfcCircleProfileDef")
                 for rep in (el.Representation.Representations if el.Representation else ())
                 for it in rep.Items)
    xy = verts[:, :2]
    if circle:
        centre = (xy.min(axis=0) + xy.max(axis=0)) / 2
        r = float(np.linalg.norm(xy - centre, axis=1).max())
        frame = WallFrame(np.array([centre[0] + r, centre[1], z0]), np.array([0.0, 1.0, 0.0]),
                          np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), 2 * np.pi * r, z1 - z0)
        return [Surface(guid, "column", frame, column=guid, radius_m=r,
                        centre=(float(centre[0]), float(centre[1])))]
    x = _horizontal(matrix[:3, 0])
    if x is None:
        x = np.array([1.0, 0.0, 0.0])
    y = np.cross([0.0, 0.0, 1.0], x)
    a, b = verts @ x, verts @ y
    lo_a, hi_a, lo_b, hi_b = a.min(), a.max(), b.min(), b.max()
    out = []
    for side, n, (ua, ub), width in (("a+", x, (hi_a, lo_b), hi_b - lo_b), ("b+", y, (hi_a, hi_b), hi_a - lo_a),
                                     ("a-", -x, (lo_a, hi_b), hi_b - lo_b), ("b-", -y, (lo_a, lo_b), hi_a - lo_a)):
        u_axis = np.cross([0.0, 0.0, 1.0], n)
        origin = ua * x + ub * y
        origin[2] = z0
        frame = WallFrame(origin, u_axis, np.array([0.0, 0.0, 1.0]), n, float(width), z1 - z0)
        out.append(Surface(f"{guid}:{side}", "column", frame, column=guid))
    return out


def _norm_text(s: Any) -> str:
    return re.sub(r"[^a-z0-9]", "", str(s or "").lower())


# --------------------------------------------------------------------------- reading


def open_ifc(path: Path) -> ifcopenshell.file:
    """Open an IFC file; InputError (one line naming the file) for anything unusable."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(64)
            fh.seek(max(0, path.stat().st_size - 512))
            tail = fh.read()
    except OSError as exc:
        raise InputError(path, f"cannot read ({exc.strerror})") from None
    if not head.lstrip().startswith(b"ISO-10303-21"):
        raise InputError(path, "not an IFC file (expected an ISO-10303-21 STEP file)")
    if b"END-ISO-10303-21" not in tail:  # the parser reads a cut file up to the cut, silently
        raise InputError(path, "malformed IFC file: truncated (no END-ISO-10303-21; at its end)")
    # ifcopenshell.validate switches the parser's log to JSON for good: read "[error]" lines
    ifcopenshell.ifcopenshell_wrapper.set_log_format_text()
    ifcopenshell.ifcopenshell_wrapper.get_log()  # drop messages of earlier reads
    try:
        f = ifcopenshell.open(str(path))
    except ifcopenshell.SchemaError as exc:
        raise InputError(path, f"unsupported IFC schema ({exc}; expected IFC2X3, IFC4 or IFC4X3)") from None
    except Exception as exc:  # ifcopenshell raises several types for a broken file
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(path, f"not a readable IFC file ({msg})") from None
    # the parser skips what it cannot read and logs it: a broken file must not pass as a design
    errors = [ln for ln in ifcopenshell.ifcopenshell_wrapper.get_log().splitlines() if "[error]" in ln]
    if errors:
        first = re.sub(r"^\[error\]\s*(\[[^\]]*\]\s*)*", "", errors[0]).strip()
        more = f" (and {len(errors) - 1} more errors)" if len(errors) > 1 else ""
        raise InputError(path, f"malformed IFC file: {first}{more}")
    schema = str(f.schema).upper()
    if not any(schema.startswith(s) for s in READABLE_SCHEMAS):
        raise InputError(path, f"unsupported IFC schema '{f.schema}' (expected IFC2X3, IFC4 or IFC4X3)")
    if not f.by_type("IfcRoot"):
        raise InputError(path, "malformed IFC file: no entities in its DATA section")
    return f


class _Typer:
    """Maps IFC elements to library classes."""

    def __init__(self, typings: dict[str, ClassTyping], file: ifcopenshell.file) -> None:
        self.typings = typings
        self.file = file

    @staticmethod
    def typing_of_element(el: Any) -> tuple[str, str | None, str | None]:
        """(IFC class, predefined type, object type) with the type object's values first."""
        t = ifcopenshell.util.element.get_type(el)
        pre = getattr(t, "PredefinedType", None) if t is not None else None
        if not pre or pre == "NOTDEFINED":
            pre = getattr(el, "PredefinedType", None) or pre
        obj = getattr(el, "ObjectType", None) or (getattr(t, "ElementType", None) if t is not None else None)
        return el.is_a(), pre, obj

    def _schema_has(self, name: str) -> bool:
        try:
            ifcopenshell.ifcopenshell_wrapper.schema_by_name(self.file.schema_identifier).declaration_by_name(name)
        except RuntimeError:
            return False
        return True

    def _typing_matches(self, el: Any, t: ClassTyping, pre: str | None, obj: str | None) -> bool:
        labels = {_norm_text(x) for x in (obj, pre) if x}
        if el.is_a("IfcBuildingElementProxy") and t.ifc_class != "IfcBuildingElementProxy":
            # a proxy stands for the class through its ObjectType (IfcSign in IFC4)
            want = _norm_text(t.object_type or t.predefined_type or t.ifc_class.removeprefix("Ifc"))
            return bool(want) and want in labels
        if not el.is_a(t.ifc_class):
            return False
        if t.predefined_type and t.predefined_type not in ("USERDEFINED", "NOTDEFINED"):
            if pre != t.predefined_type and _norm_text(t.predefined_type) not in labels:
                return False
        if t.object_type and obj and _norm_text(obj) != _norm_text(t.object_type):
            return False
        if t.predefined_type == "USERDEFINED" and t.object_type and not obj:
            return False
        return True

    def candidates(self, el: Any) -> list[str]:
        _, pre, obj = self.typing_of_element(el)
        return [cid for cid, t in sorted(self.typings.items()) if self._typing_matches(el, t, pre, obj)]

    def pset_class(self, el: Any) -> str | None:
        psets = ifcopenshell.util.element.get_psets(el)
        for name in (PSET_RECOGNITION, PSET_DESIGN):
            cid = (psets.get(name) or {}).get("Class")
            if isinstance(cid, str) and cid in self.typings:
                return cid
        return None

    def by_name(self, el: Any, cands: list[str]) -> list[str]:
        t = ifcopenshell.util.element.get_type(el)
        texts = [_norm_text(getattr(x, a, None)) for x in (t, el) if x is not None
                 for a in ("Tag", "Name", "ObjectType", "ElementType")]
        texts = [s for s in texts if s]
        best, best_len = [], 0
        for cid in cands:
            keys = {_norm_text(cid), _norm_text(self.typings[cid].name)}
            hit = max((len(k) for k in keys for s in texts if k and k in s), default=0)
            if hit > best_len:
                best, best_len = [cid], hit
            elif hit and hit == best_len:
                best.append(cid)
        return best


def _shape_settings() -> ifcopenshell.geom.settings:
    s = ifcopenshell.geom.settings()
    s.set("disable-opening-subtractions", True)
    return s


def _world_vertices(settings: ifcopenshell.geom.settings, el: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """(4x4 placement matrix, (N, 3) world vertices) in metres, None without a body."""
    if not getattr(el, "Representation", None):
        return None
    try:
        shape = ifcopenshell.geom.create_shape(settings, el)
    except Exception:  # no body representation the geometry kernel can use
        return None
    m = np.asarray(ifcopenshell.util.shape.get_shape_matrix(shape), dtype=np.float64)
    v = np.asarray(ifcopenshell.util.shape.get_vertices(shape.geometry), dtype=np.float64).reshape(-1, 3)
    if v.size == 0:
        return None
    return m, v @ m[:3, :3].T + m[:3, 3]


def _host_walls(el: Any, classes: tuple[str, ...] = ("IfcWall",)) -> list[Any]:
    hosts = []
    for rel in list(getattr(el, "ConnectedFrom", None) or []) + list(getattr(el, "ConnectedTo", None) or []):
        for other in (rel.RelatingElement, rel.RelatedElement):
            if other is not None and other != el and any(other.is_a(c) for c in classes):
                hosts.append(other)
    return hosts


def _on_host(centre: np.ndarray, verts: np.ndarray | None, host: DesignHost,
             strict: bool) -> tuple[float, Surface, np.ndarray, float | None, float | None] | None:
    """(score, surface, position on it, width, height) of a body centre on a ceiling or
    column, None when (``strict``) it does not stand close to it."""

    best = None
    for sf in host.surfaces:
        u, v, d = surface_coords(sf, centre[None])[0]
        if d < -0.02:
            continue
        m = HOST_MARGIN_M
        width = sf.frame.width_m if not sf.round else np.inf
        inside = -m <= u <= width + m and -m <= v <= sf.frame.height_m + m
        if strict and (d > HOST_MAX_DISTANCE_M or not inside):
            continue
        score = d + (0.0 if inside else 10.0)
        if best is None or score < best[0]:
            plane = tangent_frame(sf, centre)
            pu, pv, _ = plane.to_uvd(centre[None])[0]
            position = plane.to_world(pu, pv, 0.0)
            w = h = None
            if verts is not None:
                fv = plane.to_uvd(verts)
                w, h = float(np.ptp(fv[:, 0])), float(np.ptp(fv[:, 1]))
            best = (score, sf, position, w, h)
    return best


def _pick_face(centre: np.ndarray, faces: list[tuple[DesignWall, WallFrame]], strict: bool) -> tuple[DesignWall, WallFrame] | None:
    """The face the body stands in front of: centre on its room side, nearest plane."""
    best, best_d = None, np.inf
    for dw, face in faces:
        u, v, d = face.to_uvd(centre[None])[0]
        if d < -0.02:
            continue
        inside = -HOST_MARGIN_M <= u <= face.width_m + HOST_MARGIN_M and -HOST_MARGIN_M <= v <= face.height_m + HOST_MARGIN_M
        if strict and (d > HOST_MAX_DISTANCE_M or not inside):
            continue
        score = d + (0.0 if inside else 10.0)
        if score < best_d:
            best, best_d = (dw, face), score
    return best


def read_as_designed(path: Path, library: ModelLibrary | None = None, *,
                     typings: dict[str, ClassTyping] | None = None) -> AsDesigned:
    """The secondary components of an as-designed IFC file that map to library classes.

    Parameters
    ----------
    path
        The as-designed IFC file (it needs an IfcBuildingStorey).
    library
        The model library whose classes are looked for; None: the bundled one.
    typings
        How each class is written in IFC, when already made from the library.

    Returns
    -------
    AsDesigned
        The designed walls, ceilings and columns, and the objects on them with their class
        and the surface they are on.
    """
    path = Path(path)
    f = open_ifc(path)
    if not f.by_type("IfcBuildingStorey"):
        raise InputError(path, "no IfcBuildingStorey (the design needs a storey holding the floor)")
    typings = typings if typings is not None else class_typings(library)
    settings = _shape_settings()
    scale = ifcopenshell.util.unit.calculate_unit_scale(f)

    walls: list[DesignWall] = []
    wall_by_id: dict[int, DesignWall] = {}
    for w in f.by_type("IfcWall"):
        geo = _world_vertices(settings, w)
        if geo is None:
            continue
        front, back, thick = _wall_faces(*geo)
        dw = DesignWall(w.GlobalId, w.Name or w.GlobalId, front, back, thick)
        walls.append(dw)
        wall_by_id[w.id()] = dw
    all_faces = [(dw, face) for dw in walls for face in dw.faces]
    hosts: list[DesignHost] = []
    host_by_id: dict[int, DesignHost] = {}
    for el in [*f.by_type("IfcCovering"), *f.by_type("IfcColumn")]:
        if el.is_a("IfcCovering") and ifcopenshell.util.element.get_predefined_type(el) not in (
                None, "CEILING", "NOTDEFINED"):
            continue  # flooring, cladding, ...
        geo = _world_vertices(settings, el)
        if geo is None:
            continue
        name = el.Name or el.GlobalId
        if el.is_a("IfcCovering"):
            host = DesignHost(el.GlobalId, name, "ceiling", [_ceiling_surface(el.GlobalId, *geo)])
        else:
            host = DesignHost(el.GlobalId, name, "column", _column_surfaces(el, *geo))
        hosts.append(host)
        host_by_id[el.id()] = host

    typer = _Typer(typings, f)
    objects: list[DesignedObject] = []
    unmapped_counts: Counter = Counter()
    for el in f.by_type("IfcElement"):
        if any(el.is_a(c) for c in _SKIP_CLASSES):
            continue
        ifc_class, pre, obj = typer.typing_of_element(el)
        cid, how = typer.pset_class(el), "pset"
        if cid is None:
            cands = typer.candidates(el)
            how = "typing"
            if len(cands) > 1:
                named = typer.by_name(el, cands)
                if named:
                    cands, how = named, "name"
            cid = cands[0] if len(cands) == 1 else None
            if cid is None and cands:
                cid, how = cands[0], "ambiguous"  # refined by size below when a body exists
        if cid is None:
            unmapped_counts[(ifc_class, pre, obj)] += 1
            continue

        geo = _world_vertices(settings, el)  # only for mapped elements: a design has many others
        if geo is not None:
            verts = geo[1]
            centre = (verts.min(0) + verts.max(0)) / 2
        else:
            m = ifcopenshell.util.placement.get_local_placement(el.ObjectPlacement) if el.ObjectPlacement else np.eye(4)
            verts, centre = None, m[:3, 3] * scale
        connected = [wall_by_id[h.id()] for h in _host_walls(el) if h.id() in wall_by_id]
        faces = [(dw, face) for dw in connected for face in dw.faces]
        on_hosts = [host_by_id[h.id()] for h in _host_walls(el, ("IfcCovering", "IfcColumn")) if h.id() in host_by_id]
        on = None
        if on_hosts:  # connected to a ceiling or a column
            on = min((r for h in on_hosts if (r := _on_host(centre, verts, h, False)) is not None),
                     key=lambda r: r[0], default=None)
            on = None if on is None else (on, next(h for h in on_hosts if on[1] in h.surfaces))
        picked = None
        if on is None:
            picked = _pick_face(centre, faces, strict=False) if faces else _pick_face(centre, all_faces, strict=True)
        if on is None and not faces and hosts:  # close under a ceiling or beside a column, nearer than a wall
            cands = [(r, h) for h in hosts if (r := _on_host(centre, verts, h, True)) is not None]
            on = min(cands, key=lambda c: c[0][0], default=None)
            if on is not None and picked is not None and picked[1].to_uvd(centre[None])[0][2] <= on[0][0]:
                on = None
        position, normal, u, v, width, height = centre, None, None, None, None, None
        wall_guid = wall_name = None
        surface = "wall"
        if on is not None:
            (_, sf, position, width, height), host = on
            normal = surface_normal(sf, position)
            u, v = (float(x) for x in surface_coords(sf, position[None])[0][:2])
            wall_guid, wall_name, surface = host.guid, host.name, host.kind
        elif picked is not None:
            dw, face = picked
            uvd = face.to_uvd(centre[None])[0]
            position, normal = face.to_world(uvd[0], uvd[1], 0.0), face.normal
            u, v = float(uvd[0]), float(uvd[1])
            wall_guid, wall_name = dw.guid, dw.name
            if verts is not None:
                fv = face.to_uvd(verts)
                width, height = float(np.ptp(fv[:, 0])), float(np.ptp(fv[:, 1]))
        elif verts is not None:
            ext = np.ptp(verts, axis=0)
            width, height = float(max(ext[0], ext[1])), float(ext[2])
        if how == "ambiguous" and width is not None:
            cands = typer.candidates(el)
            named = typer.by_name(el, cands) or cands
            cid = min(named, key=lambda c: abs(typings[c].width_m - width) + abs(typings[c].height_m - height))
            how = "size"
        objects.append(DesignedObject(
            guid=el.GlobalId, name=el.Name or "", class_id=cid, ifc_class=ifc_class, predefined_type=pre,
            object_type=obj, position=np.asarray(position, float),
            normal=None if normal is None else np.asarray(normal, float), wall_guid=wall_guid,
            wall_name=wall_name, u=u, v=v, width_m=width, height_m=height, matched_by=how, surface=surface))
    unmapped = [{"ifc_class": c, "predefined_type": p, "object_type": o, "count": n}
                for (c, p, o), n in sorted(unmapped_counts.items(), key=lambda kv: (-kv[1], str(kv[0])))]
    project = f.by_type("IfcProject")
    return AsDesigned(path=str(path), schema=f.schema, project_guid=project[0].GlobalId if project else None,
                      walls=walls, objects=objects, unmapped=unmapped, hosts=hosts)


# --------------------------------------------------------------------------- writing a design


