"""Plain data passed between the stages of the method.

Conventions (contract 4 of ``CONTRACTS.md``): metres, Z up. A wall frame has its
origin at the wall's lower-left corner seen from the room, ``axis_u`` horizontal along
the wall, ``axis_v`` = +Z, ``normal`` into the room. Orthoimages are stored with row 0
at the *top* of the wall (v = height) so that they look natural as images:
pixel (r, c) has its centre at u = (c + 0.5) * pixel_m, v = height_m - (r + 0.5) * pixel_m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# Surfaces an object may be mounted on (contract 2 "mount", contract 4/5 "surface").
SURFACE_KINDS: tuple[str, ...] = ("wall", "ceiling", "column")


@dataclass
class PointCloud:
    """A coloured point cloud held compactly.

    ``xyz`` is float32 relative to ``origin`` (float64), ``rgb`` is uint8.
    """

    xyz: np.ndarray  # (N, 3) float32, relative to origin
    rgb: np.ndarray  # (N, 3) uint8
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) float64
    sources: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    def world(self) -> np.ndarray:
        """Absolute coordinates as float64 (allocates N x 3 doubles)."""
        return self.xyz.astype(np.float64) + self.origin

    @property
    def nbytes(self) -> int:
        return int(self.xyz.nbytes + self.rgb.nbytes)


@dataclass(frozen=True)
class WallFrame:
    """A wall's local frame (contract 4). All vectors are world-frame float64 arrays."""

    origin: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    normal: np.ndarray
    width_m: float
    height_m: float

    def to_uvd(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) to (N, 3) columns u, v, d (d = signed distance along normal)."""
        rel = np.asarray(points, dtype=np.float64) - self.origin
        basis = np.stack([self.axis_u, self.axis_v, self.normal], axis=1)
        return rel @ basis

    def to_world(self, u: np.ndarray | float, v: np.ndarray | float, d: np.ndarray | float = 0.0) -> np.ndarray:
        """Wall coordinates back to world points; broadcasts like numpy."""
        u_, v_, d_ = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float), np.asarray(d, float))
        return (
            self.origin
            + u_[..., None] * self.axis_u
            + v_[..., None] * self.axis_v
            + d_[..., None] * self.normal
        )

    def to_dict(self) -> dict:
        return {
            "origin": [float(x) for x in self.origin],
            "axis_u": [float(x) for x in self.axis_u],
            "axis_v": [float(x) for x in self.axis_v],
            "normal": [float(x) for x in self.normal],
            "width_m": float(self.width_m),
            "height_m": float(self.height_m),
        }

    @classmethod
    def from_dict(cls, d: dict) -> WallFrame:
        return cls(
            origin=np.asarray(d["origin"], dtype=np.float64),
            axis_u=np.asarray(d["axis_u"], dtype=np.float64),
            axis_v=np.asarray(d["axis_v"], dtype=np.float64),
            normal=np.asarray(d["normal"], dtype=np.float64),
            width_m=float(d["width_m"]),
            height_m=float(d["height_m"]),
        )


@dataclass(frozen=True)
class CylinderFrame(WallFrame):
    """The unrolled frame of a round column face, usable where a wall's frame is: ``to_uvd``
    and ``to_world`` go around the cylinder (``u`` the arc length counter-clockwise from +x,
    ``v`` the height above ``origin``, ``d`` the distance out of the cylinder)."""

    centre: tuple[float, float] = (0.0, 0.0)
    radius_m: float = 1.0

    def to_uvd(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        dx, dy = p[:, 0] - self.centre[0], p[:, 1] - self.centre[1]
        theta = np.mod(np.arctan2(dy, dx), 2 * math.pi)
        return np.column_stack([theta * self.radius_m, p[:, 2] - self.origin[2], np.hypot(dx, dy) - self.radius_m])

    def to_world(self, u: np.ndarray | float, v: np.ndarray | float, d: np.ndarray | float = 0.0) -> np.ndarray:
        u_, v_, d_ = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float), np.asarray(d, float))
        a = u_ / self.radius_m
        r = self.radius_m + d_
        return np.stack([self.centre[0] + r * np.cos(a), self.centre[1] + r * np.sin(a), self.origin[2] + v_], axis=-1)


@dataclass(frozen=True)
class Surface:
    """A surface beyond walls (contract 4 ``surfaces``): a ceiling, a column face or a pendant.

    ``frame`` follows contract 4 (a ceiling's ``normal`` points down into the room). A round
    column's face is unrolled around its axis: ``u`` is the arc length counter-clockwise
    from +x around ``centre``, ``v`` the height above ``frame.origin``, and ``radius_m`` and
    ``centre`` are given. ``column`` names the column a face belongs to; ``room`` (the
    simulator's) and ``storey`` are optional. A pendant (:mod:`sbsc_core.scene.pendants`) is
    an upright panel hanging from the ceiling, framed like a wall; ``hangs_from`` names the
    ceiling's storey (or ceiling) it hangs from.
    """

    id: str
    kind: str  # "ceiling" | "column" | "pendant"
    frame: WallFrame
    room: str | None = None
    column: str | None = None
    radius_m: float | None = None
    centre: tuple[float, float] | None = None
    storey: str | None = None
    hangs_from: str | None = None

    @property
    def round(self) -> bool:
        return self.radius_m is not None and self.centre is not None

    def drawing_frame(self) -> WallFrame:
        """The frame the surface is drawn in like a wall: its own, or a :class:`CylinderFrame`."""
        if not self.round:
            return self.frame
        f = self.frame
        return CylinderFrame(f.origin, f.axis_u, f.axis_v, f.normal, f.width_m, f.height_m,
                             centre=(float(self.centre[0]), float(self.centre[1])), radius_m=float(self.radius_m))

    def to_dict(self, *, digits: int | None = None) -> dict:
        """The contract-4 ``surfaces`` entry; ``digits``: round the frame to that many decimals."""
        frame = self.frame.to_dict()
        if digits is not None:
            frame = {k: ([round(x, digits) + 0.0 for x in v] if isinstance(v, list) else round(v, digits))
                     for k, v in frame.items()}
        doc: dict = {"id": self.id, "kind": self.kind}
        if self.room is not None:
            doc["room"] = self.room
        doc.update(frame)
        if self.column:
            doc["column"] = self.column
        if self.radius_m is not None:
            doc["radius_m"] = round(float(self.radius_m), 4)
            doc["centre"] = [round(float(c), 4) for c in self.centre]
        if self.storey is not None:
            doc["storey"] = self.storey
        if self.hangs_from is not None:
            doc["hangs_from"] = self.hangs_from
        return doc

    @classmethod
    def from_dict(cls, d: dict) -> Surface:
        """A ``surfaces`` entry (already checked: ``id``, ``kind`` and the frame fields)."""
        centre = d.get("centre")
        radius = d.get("radius_m")
        return cls(id=str(d["id"]), kind=str(d["kind"]), frame=WallFrame.from_dict(d),
                   room=d.get("room"), column=d.get("column"),
                   radius_m=float(radius) if radius is not None else None,
                   centre=(float(centre[0]), float(centre[1])) if centre is not None else None,
                   storey=d.get("storey"), hangs_from=d.get("hangs_from"))


@dataclass
class Wall:
    """A segmented wall: its frame and the indices of its points in the cloud."""

    id: str
    frame: WallFrame
    point_index: np.ndarray  # (K,) int64 indices into PointCloud
    storey: str | None = None  # id of its storey (``S1``, ...)


@dataclass(frozen=True)
class Storey:
    """One storey of a scan: its floor and (highest) ceiling level, world Z (contract 4)."""

    id: str  # "S1", "S2", ... bottom up
    floor_z: float
    ceiling_z: float

    def to_dict(self) -> dict:
        return {"id": self.id, "floor_z": round(float(self.floor_z), 4),
                "ceiling_z": round(float(self.ceiling_z), 4)}


@dataclass
class Segmentation:
    """Result of floor / ceiling / wall segmentation: the walls of every storey in one list."""

    floor_z: float  # world Z of the lowest floor
    ceiling_z: float  # world Z of the highest ceiling
    walls: list[Wall]
    storeys: list[Storey] = field(default_factory=list)  # bottom up
    stray_points: int = 0  # points outside the dense part of the scan, ignored


def pixel_to_uv(frame: WallFrame, pixel_m: float, r: np.ndarray | float, c: np.ndarray | float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Continuous pixel coordinates (row, col; a pixel *centre* is an integer) of an image of
    ``frame`` with pixels of ``pixel_m`` to (u, v) in metres (see the module's convention)."""
    u = (np.asarray(c, float) + 0.5) * pixel_m
    v = frame.height_m - (np.asarray(r, float) + 0.5) * pixel_m
    return u, v


@dataclass
class Orthoimage:
    """The 4D orthoimage J_CD of one wall (paper, section 3.2).

    ``depth`` is the signed distance from the wall plane in metres (positive into the
    room), NaN where no point fell; ``colour`` is zero there and ``mask`` is False.
    """

    wall_id: str
    frame: WallFrame
    pixel_m: float
    colour: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32, NaN = no data
    mask: np.ndarray  # (H, W) bool, True = has data

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.depth.shape[0]), int(self.depth.shape[1]))

    def pixel_to_uv(self, r: np.ndarray | float, c: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Continuous pixel coordinates (row, col of a pixel *centre* = integer) to (u, v)."""
        return pixel_to_uv(self.frame, self.pixel_m, r, c)

    def uv_to_pixel(self, u: np.ndarray | float, v: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """(u, v) in metres to continuous (row, col)."""
        c = np.asarray(u, float) / self.pixel_m - 0.5
        r = (self.frame.height_m - np.asarray(v, float)) / self.pixel_m - 0.5
        return r, c


@dataclass(frozen=True)
class Opening:
    """A door or window found in a wall, in that wall's (u, v) metres."""

    wall_id: str
    kind: str  # "door" | "window"
    u_min: float
    u_max: float
    v_min: float
    v_max: float

    def to_dict(self) -> dict:
        return {
            "wall": self.wall_id,
            "kind": self.kind,
            "u_min": round(float(self.u_min), 4),
            "u_max": round(float(self.u_max), 4),
            "v_min": round(float(self.v_min), 4),
            "v_max": round(float(self.v_max), 4),
        }


@dataclass
class WallArea:
    """Visible wall area and openings of one orthoimage (paper, section 3.3)."""

    visible: np.ndarray  # (H, W) bool: plain wall surface (background for recognition)
    openings: list[Opening]
    opening_mask: np.ndarray  # (H, W) bool: pixels inside openings (excluded from recognition)
    wall_colour: np.ndarray  # (3,) float: mean RGB of the visible area


@dataclass(frozen=True)
class Box:
    """An axis-aligned pixel rectangle: rows r0..r1-1, cols c0..c1-1 (end exclusive)."""

    r0: int
    c0: int
    r1: int
    c1: int

    @property
    def height(self) -> int:
        return self.r1 - self.r0

    @property
    def width(self) -> int:
        return self.c1 - self.c0

    @property
    def area(self) -> int:
        return max(0, self.height) * max(0, self.width)

    @property
    def centre(self) -> tuple[float, float]:
        """(row, col) of the box centre in continuous pixel-centre coordinates."""
        return ((self.r0 + self.r1 - 1) / 2.0, (self.c0 + self.c1 - 1) / 2.0)

    def intersection(self, other: Box) -> int:
        h = min(self.r1, other.r1) - max(self.r0, other.r0)
        w = min(self.c1, other.c1) - max(self.c0, other.c0)
        return max(0, h) * max(0, w)

    def union_box(self, other: Box) -> Box:
        return Box(min(self.r0, other.r0), min(self.c0, other.c0), max(self.r1, other.r1), max(self.c1, other.c1))


@dataclass
class Candidate:
    """One candidate instance of a class found by one recognizer on one wall.

    ``box`` is the object's footprint in the orthoimage (pixels) at the matched
    position; ``centre`` its (row, col) centre, possibly sub-pixel. ``score`` is
    rho_D (cross-correlation, higher is better) for depth candidates and rho_C
    (descriptor distance, lower is better) for colour candidates.
    """

    class_id: str
    wall_id: str
    source: str  # "depth" | "colour"
    box: Box
    centre: tuple[float, float]
    score: float
    roi: Box | None = None  # the RoI the match came from
    rotation_deg: float = 0  # the model's in-plane rotation at the match (degrees, counter-clockwise)
    lookalike_margin: float | None = None  # print NCC of its class minus the best other look-alike's
    gain: float | None = None  # depth: least-squares relief amplitude of the scene over the model's
    relief_iou: float | None = None  # depth: IoU of where the scene and the model stand out
    face_gain: float | None = None  # depth: the scene's relief over the model's inside the footprint, off its outline
    position: tuple[float, float] | None = None  # depth: (row, col) from the relief's sharp edges, for placement


@dataclass
class Detection:
    """A recognized object after consensus, placed on its wall and in 3D (contract 4)."""

    id: str
    class_id: str
    wall_id: str
    u: float
    v: float
    position: np.ndarray  # (3,) world, centre of footprint on the wall plane
    width_m: float
    height_m: float
    alpha: float
    rho_depth: float | None
    rho_colour: float | None
    source: str  # "both" | "depth" | "colour"
    rotation_deg: float = 0.0  # the model's in-plane turn at the match, counter-clockwise seen from the room
    confidence: float | None = None  # calibrated probability that class and place are right
    surface: str | None = None  # "ceiling" or "column" when not on a wall (contract 4)

    def to_dict(self) -> dict:
        out = {
            "id": self.id,
            "class": self.class_id,
            "wall": self.wall_id,
            "position": [round(float(x), 5) for x in self.position],
            "u": round(float(self.u), 5),
            "v": round(float(self.v), 5),
            "width_m": round(float(self.width_m), 4),
            "height_m": round(float(self.height_m), 4),
            "alpha": round(float(self.alpha), 4),
            "rho_depth": None if self.rho_depth is None else round(float(self.rho_depth), 4),
            "rho_colour": None if self.rho_colour is None else round(float(self.rho_colour), 4),
            "source": self.source,
            "rotation_deg": round(float(self.rotation_deg), 2),
        }
        if self.confidence is not None:
            out["confidence"] = round(float(self.confidence), 4)
        if self.surface is not None:
            out["surface"] = self.surface
        return out


@dataclass
class ObjectModel:
    """One class of the model library (contract 2), as loaded from disk."""

    class_id: str
    name: str
    ifc_class: str
    predefined_type: str | None
    width_m: float
    height_m: float
    colour_views: list[np.ndarray]  # each (h, w, 4) uint8 RGBA, any pixel size
    depth: np.ndarray | None  # (h, w) float32 metres, NaN unknown
    extra: dict = field(default_factory=dict)  # other model.json keys (e.g. object_type)
    extra_depths: list[np.ndarray] = field(default_factory=list)  # depth_<k>.npy: further depth models
    mount: tuple[str, ...] = SURFACE_KINDS  # surface kinds the class may be on (model.json "mount")


@dataclass
class ModelLibrary:
    models: dict[str, ObjectModel]
    root: str = ""

    def __contains__(self, class_id: str) -> bool:
        return class_id in self.models

    def __getitem__(self, class_id: str) -> ObjectModel:
        return self.models[class_id]

    @property
    def class_ids(self) -> list[str]:
        return sorted(self.models)

    def classes_on(self, kind: str, classes: list[str] | None = None) -> list[str]:
        """``classes`` (default: all) that may be mounted on a surface of ``kind``."""
        return [c for c in (self.class_ids if classes is None else classes)
                if c not in self.models or kind in self.models[c].mount]
