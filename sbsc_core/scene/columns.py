"""Objects on free-standing columns (issue 11, item 2): find columns, recognize on their faces.

**Finding columns.** In each storey, the segmentation sample's points between 0.3 m above
the floor and 0.3 m below the ceiling that are not on a wall (``wall_clear_m`` from a wall's
plane over the wall) are binned into plan cells of ``cell_m``; a cell is *tall* when its
points cover at least ``min_cover`` of that height. Connected groups of tall cells between
``min_side_m`` and ``max_side_m`` across are columns: round when a circle fits their points
within ``round_rms_m``, else rectangles turned like their faces (:func:`_face_angle`) around
the points, their sides then put on their faces' points. A wall
(its points are removed) and furniture (not tall) are never columns, and a column never
cuts a wall (walls are segmented before and without it). One exception: segmentation takes
a column's widest face, seen square-on, for a short wall. A lone short wall (its points span
at most ``max_side_m`` and meet no other wall, :func:`lone_short_walls`) keeps its points in
the search, and when a column is found there the wall is dropped for the column's faces
(:func:`walls_on_columns`).

**Faces.** A rectangular column has four faces, each framed like a wall seen from outside the
column (origin at its lower-left corner, ``axis_v`` up, ``normal`` out), ids
``COL1-N`` ... by the compass side their normal is nearest to. A round column is one face
unrolled around its axis: ``u`` is the arc length counter-clockwise from +x (radius times
the angle), ``v`` the height above the floor, depth the distance out of the cylinder; its
``surfaces`` entry gives ``radius_m`` and ``centre``, and a detection's ``position`` is put
back on the cylinder. So that an object on the seam (at +x, where the angle wraps) is whole
somewhere, the image is ``wrap_m`` longer than the circumference: its first ``wrap_m`` are
repeated at its end. Only candidates centred between ``wrap_m / 2`` and the circumference
plus ``wrap_m / 2`` are kept (each place of the cylinder once: no duplicates), and a
detection's ``u`` is given modulo the circumference.

The scan is read once more: points near a column are binned into its faces' partitions;
each face goes through the walls' stages with the classes whose ``mount`` has ``column``
and joins the walls in the consensus (see :mod:`sbsc_core.scene.ceilings`, which does the same
for ceilings).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..imaging.orthoimage import near_walls, ortho_pixels, orthoimage_from_pixels, wall_coordinates
from ..imaging.partition import ScanPart, append_records, folder_records
from ..settings import ColumnSettings, OrthoimageSettings
from ..types import CylinderFrame, Orthoimage, PointCloud, Segmentation, Wall, WallFrame
from .ceilings import MemoryPart, part_chunks

_UP = np.array([0.0, 0.0, 1.0])
_COMPASS = (("E", 0.0), ("N", 90.0), ("W", 180.0), ("S", 270.0))


@dataclass(frozen=True)
class FoundColumn:
    """A free-standing column found in the scan (world coordinates)."""

    id: str
    storey: str | None
    shape: str  # "rect" | "round"
    centre: tuple[float, float]
    size_m: tuple[float, float]  # rect: side lengths along angle_deg and across; round: the diameter twice
    angle_deg: float  # rect: direction of the first side
    floor_z: float
    height_m: float

    def to_dict(self) -> dict:
        return {"id": self.id, "shape": self.shape, "centre": [round(c, 4) for c in self.centre],
                "size_m": [round(s, 4) for s in self.size_m], "angle_deg": round(self.angle_deg, 2),
                "floor_z": round(self.floor_z, 4), "height_m": round(self.height_m, 4),
                **({"storey": self.storey} if self.storey else {})}


@dataclass(frozen=True)
class ColumnFace:
    """One face of a column as a surface: planar (a rectangle's side) or unrolled (round)."""

    id: str
    column: str
    storey: str | None
    frame: WallFrame
    radius_m: float | None = None  # round: the frame is unrolled around the axis
    centre: tuple[float, float] | None = None
    wrap_m: float = 0.0  # round: the image repeats this much of its start at its end

    @property
    def circumference_m(self) -> float | None:
        return None if self.radius_m is None else 2 * math.pi * self.radius_m

    def arc_u(self, u: float) -> float:
        """``u`` of the unrolled image as the arc length in [0, circumference) (planar: as is)."""
        return u if self.radius_m is None else float(u % self.circumference_m)

    def owns(self, u: float) -> bool:
        """Whether a candidate centred at ``u`` is kept: a round face keeps one circumference,
        from ``wrap_m / 2`` on, so that an object on the seam is found once and whole."""
        if self.radius_m is None:
            return True
        return self.wrap_m / 2 <= u < self.circumference_m + self.wrap_m / 2

    def coords(self, xyz: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """(N, 3) float32 u, v, d of float32 points given relative to ``origin``."""
        if self.radius_m is None:
            return wall_coordinates(xyz, self.frame, origin)
        rel = xyz.astype(np.float64) + np.asarray(origin, np.float64)
        f = self.frame
        cylinder = CylinderFrame(f.origin, f.axis_u, f.axis_v, f.normal, f.width_m, f.height_m,
                                 centre=self.centre, radius_m=self.radius_m)
        return cylinder.to_uvd(rel).astype(np.float32)

    def to_world(self, u: float, v: float) -> np.ndarray:
        """The point (u, v) of the face, on its plane or on the cylinder."""
        if self.radius_m is None:
            return self.frame.to_world(u, v)
        a = u / self.radius_m
        return np.array([self.centre[0] + self.radius_m * math.cos(a), self.centre[1] + self.radius_m * math.sin(a),
                         self.frame.origin[2] + v])

    def surface(self) -> dict:
        doc = {"id": self.id, "kind": "column", "column": self.column, **self.frame.to_dict()}
        if self.radius_m is not None:
            doc["radius_m"] = round(self.radius_m, 4)
            doc["centre"] = [round(c, 4) for c in self.centre]
        if self.storey is not None:
            doc["storey"] = self.storey
        return doc


def find_columns(cloud: PointCloud, seg: Segmentation, s: ColumnSettings, *,
                 lone_walls: Collection[str] = ()) -> list[FoundColumn]:
    """The free-standing columns of every storey (see the module docstring).

    ``lone_walls`` (:func:`lone_short_walls`) are walls that may be a column's face: their
    points are not removed from the search.
    """
    import cv2

    storeys = [(st.id, st.floor_z, st.ceiling_z) for st in seg.storeys] or [(None, seg.floor_z, seg.ceiling_z)]
    origin = np.asarray(cloud.origin, np.float64)
    out: list[FoundColumn] = []
    for sid, fz, cz in storeys:
        z0, z1 = fz + 0.3, cz - 0.3
        if z1 - z0 < 0.5:
            continue
        z = cloud.xyz[:, 2].astype(np.float64) + origin[2]
        idx = np.flatnonzero((z > z0) & (z < z1))
        walls = [w for w in seg.walls if sid is None or w.storey in (sid, None)]
        if not len(idx) or not walls:
            continue
        xyz = np.take(cloud.xyz, idx, axis=0)  # as cloud.xyz[idx], without fancy indexing's slow path
        # a lone short "wall" may be a column's face: its points stay
        keep = ~near_walls(xyz, [w.frame for w in walls if w.id not in lone_walls], s.wall_clear_m, origin)
        xy = np.compress(keep, xyz, axis=0)[:, :2].astype(np.float64) + origin[:2]
        zz = z[idx[keep]]
        if len(xy) < 50:
            continue
        lo = xy.min(axis=0)
        ij = np.floor((xy - lo) / s.cell_m).astype(np.int64)
        nx, ny = int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1
        nb = max(1, int((z1 - z0) / s.band_m))
        zb = np.clip(((zz - z0) / s.band_m).astype(np.int64), 0, nb - 1)
        cell = ij[:, 1] * nx + ij[:, 0]
        pairs = np.unique(cell * nb + zb)
        cover = np.bincount(pairs // nb, minlength=nx * ny)
        tall = (cover >= s.min_cover * nb).reshape(ny, nx).astype(np.uint8)
        grown = cv2.dilate(tall, np.ones((3, 3), np.uint8))
        n, labels, stats, _ = cv2.connectedComponentsWithStats(grown, connectivity=8)
        for lab in range(1, n):
            w_c, h_c = stats[lab, cv2.CC_STAT_WIDTH], stats[lab, cv2.CC_STAT_HEIGHT]
            span = (np.array([w_c, h_c]) - 2) * s.cell_m  # the dilation grew it by a cell each side
            if span.min() < s.min_side_m or span.max() > s.max_side_m:
                continue
            mine = (labels.ravel()[cell] == lab) & (tall.ravel()[cell] == 1)
            pts = xy[mine]
            if len(pts) < 50:
                continue
            col = _fit(pts, s)
            if col is None:
                continue
            shape, centre, size, angle = col
            k = len(out) + 1
            cid = (f"{sid}-" if sid and len(storeys) > 1 else "") + f"COL{k}"
            out.append(FoundColumn(cid, sid, shape, centre, size, angle, float(fz), float(cz - fz)))
    return out


_EXTENT_Q = 0.5  # a wall's extent: between these percentiles of its points (a few stray points beyond its ends)
_EXTENT_POINTS = 20_000  # a regular subsample of a wall's points this big measures it


def _wall_extent(cloud: PointCloud, wall: Wall) -> tuple[np.ndarray, np.ndarray] | None:
    """Plan ends (world x, y) of where a wall's points lie along it, or None without points."""
    idx = np.asarray(wall.point_index)
    if not len(idx):
        return None
    idx = idx[:: max(1, len(idx) // _EXTENT_POINTS)]
    u = wall_coordinates(cloud.xyz[idx], wall.frame, cloud.origin)[:, 0].astype(np.float64)
    lo, hi = np.percentile(u, [_EXTENT_Q, 100.0 - _EXTENT_Q])
    o, a = np.asarray(wall.frame.origin[:2], np.float64), np.asarray(wall.frame.axis_u[:2], np.float64)
    return o + lo * a, o + hi * a


def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Plan distance from point ``p`` to the segment ``a``-``b``."""
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def lone_short_walls(cloud: PointCloud, walls: list[Wall], s: ColumnSettings) -> list[str]:
    """Ids of the walls that may be a column's face: their points (``cloud`` is the one their
    point indices refer to) span at most ``s.max_side_m`` along them, and neither end comes
    within ``s.wall_clear_m`` of another wall of their storey (a wall stub meets the wall it
    stands out of; a column's face meets none).

    Segmentation takes a column's widest face, seen square-on, for a short wall; its points
    then must not be removed from the column search (:func:`find_columns`), and a column
    found there replaces that wall (:func:`walls_on_columns`)."""
    spans = {w.id: (np.asarray(w.frame.origin[:2], np.float64),
                    np.asarray(w.frame.origin[:2], np.float64) + w.frame.width_m * np.asarray(w.frame.axis_u[:2]))
             for w in walls}
    out = []
    for w in walls:
        ends = _wall_extent(cloud, w)
        if ends is None or float(np.linalg.norm(ends[1] - ends[0])) > s.max_side_m:
            continue
        others = [o for o in walls if o.id != w.id and o.storey == w.storey]  # walls of its own storey
        if all(_to_segment(e, *spans[o.id]) > s.wall_clear_m for e in ends for o in others):
            out.append(w.id)
    return out


def walls_on_columns(cloud: PointCloud, seg: Segmentation, columns: list[FoundColumn], s: ColumnSettings,
                     lone_walls: Collection[str]) -> list[str]:
    """Ids of the lone short walls (:func:`lone_short_walls`) that are a found column's face:
    the middle of their points lies within ``s.wall_clear_m`` of the column's outline. The
    column's faces are searched instead (each face once, with the classes a column may hold).
    ``cloud`` is the one the walls' point indices refer to."""
    out = []
    for w in seg.walls:
        if w.id not in lone_walls:
            continue
        ends = _wall_extent(cloud, w)
        mid = (ends[0] + ends[1]) / 2
        for c in columns:
            if c.storey != w.storey and w.storey is not None:
                continue
            a = math.radians(c.angle_deg)
            local = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]]) @ (mid - c.centre)
            half = np.asarray(c.size_m, np.float64) / 2
            inside = (float(np.linalg.norm(local)) <= half[0] + s.wall_clear_m if c.shape == "round"
                      else bool(np.all(np.abs(local) <= half + s.wall_clear_m)))
            if inside:
                out.append(w.id)
                break
    return out


def _fit(pts: np.ndarray, s: ColumnSettings) -> tuple | None:
    """("round", centre, (d, d), 0) or ("rect", centre, (a, b), angle) for a column's plan points.

    The fits run on the points relative to their mean: at survey coordinates (5.6e6 m) the
    circle's normal equations lose every digit and float32 (the rectangle's) has 0.5 m steps.
    """
    c0 = pts.mean(axis=0)
    fit = _fit_local(pts - c0, s)
    if fit is None:
        return None
    shape, centre, size, angle = fit
    return shape, (float(centre[0] + c0[0]), float(centre[1] + c0[1])), size, angle


def _fit_local(pts: np.ndarray, s: ColumnSettings) -> tuple | None:
    """:func:`_fit` on points near the origin."""

    a = np.column_stack([pts[:, 0], pts[:, 1], np.ones(len(pts))])
    b = -(pts[:, 0] ** 2 + pts[:, 1] ** 2)
    (d_, e_, f_), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = -d_ / 2, -e_ / 2
    r2 = cx * cx + cy * cy - f_
    if r2 > 0:
        r = math.sqrt(r2)
        rms = float(np.sqrt(np.mean((np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) - r) ** 2)))
        if rms < s.round_rms_m and s.min_side_m / 2 <= r <= s.max_side_m / 2:
            return "round", (float(cx), float(cy)), (2 * r, 2 * r), 0.0
    ang = _face_angle(pts)
    a = math.radians(ang)
    axes = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
    q = pts @ axes.T
    lo, hi = q.min(axis=0), q.max(axis=0)
    centre, size, ang = _refine_rect(pts, axes.T @ ((lo + hi) / 2), hi - lo, ang)
    if min(size) < s.min_side_m or max(size) > s.max_side_m:
        return None
    return "rect", (float(centre[0]), float(centre[1])), (float(size[0]), float(size[1])), float(ang)


_PROFILE_BIN_M = 0.01  # the projection profiles' bins: about the scanner's noise on a face
_PROFILE_MAX_POINTS = 20_000  # a regular subsample of this many points is enough for the profiles


def _face_angle(pts: np.ndarray) -> float:
    """The turn (degrees, 0-90) of a rectangular column's sides, from its plan points.

    A face seen edge-on from above is a line of points: along the right directions the
    points' projection profiles (histograms of their coordinates) have sharp peaks where the
    faces are. The turn maximises the profiles' sum of squares, searched every half degree,
    then every twentieth around the best. Unlike the smallest enclosing rectangle, this holds
    for a column seen from one side only (an L of two faces, whose smallest rectangle is
    diagonal) and does not turn for an object standing out of a face.
    """
    p = pts[:: max(1, len(pts) // _PROFILE_MAX_POINTS)]
    p = p - p.mean(axis=0)

    def sharpness(deg: float) -> float:
        a = math.radians(deg)
        score = 0.0
        for axis in ((math.cos(a), math.sin(a)), (-math.sin(a), math.cos(a))):
            c = p @ np.asarray(axis)
            h = np.bincount(np.floor((c - c.min()) / _PROFILE_BIN_M).astype(np.int64))
            score += float(np.dot(h, h))
        return score

    coarse = np.arange(0.0, 90.0, 0.5)
    best = float(coarse[int(np.argmax([sharpness(d) for d in coarse]))])
    fine = best + np.arange(-0.5, 0.5001, 0.05)
    return float(fine[int(np.argmax([sharpness(d) for d in fine]))]) % 90.0


def _refine_rect(pts: np.ndarray, centre: np.ndarray, size: np.ndarray, angle_deg: float, band_m: float = 0.04
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """The rectangle's sides put on their faces (objects on a face and stray points move the
    rectangle around the points out, and turn it), its turn from the faces' slopes.

    A side's face is the densest line of points (projection profile, :data:`_PROFILE_BIN_M`)
    in the rectangle's half on that side, away from the corners; the side is put on the median
    of the points within ``band_m / 2`` of it. A side with no face seen (fewer than 10 points
    there) stays where the points end.
    """
    for _ in range(2):
        a = math.radians(angle_deg)
        axes = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
        p = (pts - centre) @ axes.T  # coordinates along the two sides
        turns, lo_hi = [], np.zeros((2, 2))
        for k in range(2):
            t = 1 - k
            along = np.abs(p[:, t]) < 0.8 * size[t] / 2
            for j, sign in enumerate((-1.0, 1.0)):
                half = along & (sign * p[:, k] > 0)
                on = half
                if half.sum() >= 10:
                    c = p[half, k]
                    h = np.bincount(np.floor((c - c.min()) / _PROFILE_BIN_M).astype(np.int64))
                    face = c.min() + (int(np.argmax(h)) + 0.5) * _PROFILE_BIN_M
                    on = half & (np.abs(p[:, k] - face) < band_m / 2)
                if on.sum() < 10:
                    lo_hi[k, j] = sign * size[k] / 2
                    continue
                lo_hi[k, j] = float(np.median(p[on, k]))
                slope = np.polyfit(p[on, t], p[on, k], 1)[0]
                turns.append(math.degrees(math.atan(slope)) * (-1 if k == 0 else 1))
        centre = centre + axes.T @ lo_hi.mean(axis=1)
        size = lo_hi[:, 1] - lo_hi[:, 0]
        angle_deg += float(np.median(turns)) if turns else 0.0
    return centre, size, angle_deg


def column_faces(columns: list[FoundColumn], *, wrap_m: float = 0.0) -> list[ColumnFace]:
    """The faces of the columns as surfaces (see the module docstring); a round face's image
    is ``wrap_m`` longer than the circumference."""
    faces: list[ColumnFace] = []
    for c in columns:
        cx, cy = c.centre
        if c.shape == "round":
            r = c.size_m[0] / 2
            frame = WallFrame(np.array([cx + r, cy, c.floor_z]), np.array([0.0, 1.0, 0.0]), _UP.copy(),
                              np.array([1.0, 0.0, 0.0]), 2 * math.pi * r + wrap_m, c.height_m)
            faces.append(ColumnFace(c.id, c.id, c.storey, frame, r, (cx, cy), wrap_m))
            continue
        used: set[str] = set()
        for k in range(4):
            a = math.radians(c.angle_deg + 90.0 * k)
            n = np.array([math.cos(a), math.sin(a), 0.0])
            half = (c.size_m[0] if k % 2 == 0 else c.size_m[1]) / 2  # the side along n
            width = c.size_m[1] if k % 2 == 0 else c.size_m[0]
            u = np.cross(_UP, n)
            mid = np.array([cx, cy, c.floor_z]) + half * n
            deg = math.degrees(math.atan2(n[1], n[0])) % 360.0
            side = min((x for x in _COMPASS if x[0] not in used),
                       key=lambda x: min(abs(deg - x[1]), 360 - abs(deg - x[1])))[0]
            used.add(side)
            frame = WallFrame(mid - width / 2 * u, u, _UP.copy(), n, float(width), c.height_m)
            faces.append(ColumnFace(f"{c.id}-{side}", c.id, c.storey, frame))
    return faces


def _face_dir(scratch: Path, k: int) -> Path:
    return scratch / "columns" / f"{k:05d}"


def column_part(part: ScanPart | MemoryPart, origin: np.ndarray, faces: list[ColumnFace], reach_m: list[float], scratch: str,
                *, ortho: OrthoimageSettings) -> list[int]:
    """Stream one part and append each face's binned points to its partition (records per face)."""
    root = Path(scratch)
    written = [0] * len(faces)
    centres = np.array([f.centre if f.centre is not None else _face_centre(f) for f in faces])
    for chunk in part_chunks(part, origin):
        xy = chunk.xyz[:, :2].astype(np.float64) + origin[:2]
        for k, f in enumerate(faces):
            near = np.flatnonzero(np.hypot(xy[:, 0] - centres[k, 0], xy[:, 1] - centres[k, 1]) < reach_m[k])
            if not len(near):
                continue
            uvd = f.coords(chunk.xyz[near], origin)
            if f.radius_m is not None and f.wrap_m > 0:  # the seam: the start again at the end
                again = np.flatnonzero(uvd[:, 0] < f.wrap_m)
                uvd = np.vstack([uvd, uvd[again] + np.array([f.circumference_m, 0, 0], np.float32)])
                near = np.concatenate([near, near[again]])
            keep, pixel = ortho_pixels(uvd, f.frame, ortho)
            if not len(pixel):
                continue
            written[k] += append_records(_face_dir(root, k), part.key, pixel, uvd[keep, 2], chunk.rgb[near[keep]])
    return written


def _face_centre(f: ColumnFace) -> tuple[float, float]:
    mid = f.frame.origin + f.frame.width_m / 2 * f.frame.axis_u
    return float(mid[0]), float(mid[1])


def face_orthoimage(scratch: str | Path, k: int, face: ColumnFace, ortho: OrthoimageSettings) -> Orthoimage:
    rec = folder_records(_face_dir(Path(scratch), k))
    return orthoimage_from_pixels(face.id, face.frame, rec["pixel"].astype(np.int64), rec["depth"], rec["rgb"], settings=ortho)


@dataclass
class ColumnResults:
    walls: dict
    templates: dict
    classes: list[str]
    columns: list[FoundColumn]
    faces: list[ColumnFace]

    def surfaces(self) -> list[dict]:
        return [f.surface() for f in self.faces]


