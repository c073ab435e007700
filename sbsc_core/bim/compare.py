"""Scan-vs-BIM: the objects of an as-designed IFC against the detections of a scan.

This is the future work named in the paper's conclusions (section 6): objects of the
as-designed model that the scan does not show (possibly never built), and objects found
in the scan that the design does not hold.

Each designed object on a scanned wall is paired with at most one detection of its class
(optimal assignment on 3D distance, scipy's ``linear_sum_assignment``), in two rounds:
first pairs within ``tolerance_m`` (**found**, with the position deviation), then the rest
within ``max_displacement_m`` (**displaced**). A designed object left unpaired is
**missing**, a detection left unpaired is **unexpected**. A pair must face the same way
(the design's host face and the scanned wall), so objects back to back on the two faces
of a partition are not confused. Designed objects on no scanned wall are **not_scanned**
(the scan cannot tell) and are no finding. Rejected detections are ignored.

Objects on ceilings and columns (issue 11) are compared the same way: a designed object on
a ceiling or column lies on a scanned surface of the document's ``surfaces`` (a round
column's: on its cylinder), a pair faces the same way (the surface's normal at the object),
and :meth:`Comparison.summary_by_surface` counts the verdicts per kind of surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..errors import InputError
from ..types import Surface, WallFrame
from .design import (
    SCAN_WALL_MARGIN_M,
    SCAN_WALL_PLANE_TOL_M,
    AsDesigned,
    DesignedObject,
    locate_on_walls,
)
from .export import parse_detections_document, selected_detections
from .surfaces import drawing_frame, surface_coords, surface_normal

MAX_DISPLACEMENT_M = 1.0  # a designed object and a detection farther apart are two findings
FACING_MIN_COS = 0.5  # a pair's normals must agree at least this much
FINDING_KINDS = ("missing", "displaced", "unexpected")
STATUSES = ("found", "displaced", "missing", "unexpected", "not_scanned")
SURFACE_KINDS = ("wall", "ceiling", "column")


@dataclass
class ComparisonItem:
    """One designed object and/or one detection with the verdict."""

    status: str  # one of STATUSES
    class_id: str
    designed: DesignedObject | None = None
    detection: dict | None = None
    design_wall: str | None = None  # scanned wall the designed object lies on
    detection_wall: str | None = None  # scanned wall of the detection
    deviation: np.ndarray | None = None  # detection position - designed position, metres

    @property
    def wall(self) -> str | None:
        return self.design_wall or self.detection_wall

    @property
    def surface(self) -> str:
        """The kind of surface the object is on: wall, ceiling or column."""
        if self.designed is not None:
            return self.designed.surface
        kind = (self.detection or {}).get("surface")
        return str(kind) if kind else "wall"

    @property
    def deviation_m(self) -> float | None:
        return None if self.deviation is None else float(np.linalg.norm(self.deviation))

    @property
    def designed_position(self) -> np.ndarray | None:
        return None if self.designed is None else self.designed.position

    @property
    def detected_position(self) -> np.ndarray | None:
        return None if self.detection is None else np.asarray(self.detection["position"], float)

    def to_dict(self, walls: dict[str, WallFrame], surfaces: dict[str, Surface] | None = None) -> dict:
        surfaces = surfaces or {}

        def r(x: np.ndarray | None, n: int = 5) -> list[float] | None:
            return None if x is None else [round(float(c), n) for c in x]

        def uv(wid: str | None, p: np.ndarray | None) -> list[float] | None:
            if wid is None or p is None:
                return None
            if wid in surfaces:
                return r(surface_coords(surfaces[wid], p[None])[0][:2], 4)
            return r(walls[wid].to_uvd(p[None])[0][:2], 4) if wid in walls else None

        d = self.designed
        det = self.detection
        return {
            "status": self.status, "class": self.class_id, "wall": self.wall, "surface": self.surface,
            "designed": None if d is None else {
                "guid": d.guid, "name": d.name, "position": r(d.position), "design_wall": d.wall_name,
                "design_wall_guid": d.wall_guid, "scan_wall": self.design_wall,
                "uv": uv(self.design_wall, d.position), "matched_by": d.matched_by},
            "detection": None if det is None else {
                "id": det.get("id"), "position": r(self.detected_position), "wall": self.detection_wall,
                "uv": uv(self.detection_wall, self.detected_position), "alpha": det.get("alpha"),
                "source": det.get("source"), "review": (det.get("review") or {}).get("status", "pending")},
            "deviation_m": None if self.deviation is None else round(self.deviation_m, 4),
            "deviation": r(self.deviation, 4),
        }


@dataclass
class Comparison:
    """The verdicts of one as-designed file against one detections document."""

    design: AsDesigned
    walls: dict[str, WallFrame]
    openings: list[dict]
    items: list[ComparisonItem]
    tolerance_m: float
    max_displacement_m: float
    detections_path: str | None = None
    extra: dict = field(default_factory=dict)
    surfaces: dict[str, Surface] = field(default_factory=dict)  # the scan's ceilings and column faces

    @property
    def findings(self) -> list[ComparisonItem]:
        """Missing, displaced and unexpected objects (what the BCF file holds)."""
        return [it for it in self.items if it.status in FINDING_KINDS]

    def summary(self) -> dict[str, int]:
        return {s: sum(it.status == s for it in self.items) for s in STATUSES}

    def summary_by_surface(self) -> dict[str, dict[str, int]]:
        """The verdicts per kind of surface (wall, ceiling, column) that has any item."""
        kinds = [k for k in SURFACE_KINDS if any(it.surface == k for it in self.items)]
        kinds += sorted({it.surface for it in self.items} - set(SURFACE_KINDS))
        return {k: {s: sum(it.status == s and it.surface == k for it in self.items) for s in STATUSES} for k in kinds}

    def to_dict(self) -> dict:
        return {
            "schema": "sbsc.comparison/1",
            "as_designed": self.design.path, "detections": self.detections_path,
            "tolerance_m": self.tolerance_m, "max_displacement_m": self.max_displacement_m,
            "summary": self.summary(), "summary_by_surface": self.summary_by_surface(),
            "expected_counts": self.design.expected_counts(),
            "expected_by_wall": self.design.expected_by_wall(self.walls),
            "wall_matches": self.design.wall_matches(self.walls),
            "items": [it.to_dict(self.walls, self.surfaces) for it in self.items],
            "unmapped_design_elements": self.design.unmapped,
        }


def locate_on_surfaces(position: np.ndarray, normal: np.ndarray | None, surfaces: dict[str, Surface],
                       plane_tol: float = SCAN_WALL_PLANE_TOL_M, margin: float = SCAN_WALL_MARGIN_M) -> str | None:
    """The scanned ceiling or column face ``position`` lies on (as :func:`~.design.locate_on_walls`;
    a round face: within ``plane_tol`` of its cylinder)."""
    best, best_d = None, np.inf
    p = np.asarray(position, float)
    for sid, sf in surfaces.items():
        if normal is not None and float(np.dot(normal, surface_normal(sf, p))) < 0.5:
            continue
        u, v, d = surface_coords(sf, p[None])[0]
        width = np.inf if sf.round else sf.frame.width_m
        if abs(d) > plane_tol or not (-margin <= u <= width + margin and -margin <= v <= sf.frame.height_m + margin):
            continue
        if abs(d) < best_d:
            best, best_d = sid, abs(d)
    return best


def _assign(dist: np.ndarray, feasible: np.ndarray) -> list[tuple[int, int]]:
    """Minimum-cost pairs among feasible entries of ``dist`` (rows x cols)."""
    if dist.size == 0 or not feasible.any():
        return []
    big = 1e6
    cost = np.where(feasible, dist, big)
    rows, cols = linear_sum_assignment(cost)
    return [(int(i), int(j)) for i, j in zip(rows, cols, strict=True) if feasible[i, j]]


def compare(design: AsDesigned, document: dict, tolerance_m: float = 0.10, *,
            max_displacement_m: float = MAX_DISPLACEMENT_M, accepted_only: bool = False,
            detections_path: str | None = None) -> Comparison:
    """Compare the designed objects with the detections of a contract-4 document.

    Parameters
    ----------
    design
        The as-designed model's objects (:func:`~sbsc_core.bim.design.read_as_designed`).
    document
        A detections document (contract 4), as written by ``sbsc detect`` or the review app.
    tolerance_m
        A detection within this of a designed object of its class is the same object.
    max_displacement_m
        Beyond ``tolerance_m`` and within this, the object is displaced; beyond, missing and
        unexpected.
    accepted_only
        Only the detections a reviewer accepted.
    detections_path
        Names the document in errors.

    Returns
    -------
    Comparison
        Every designed and detected object, matched, displaced, missing or unexpected.
    """
    if not tolerance_m > 0:
        raise InputError("tolerance", f"must be > 0, got {tolerance_m}")
    max_displacement_m = max(max_displacement_m, tolerance_m)
    doc = parse_detections_document(document, detections_path or "detections")
    walls = doc.walls
    surfaces = doc.surfaces
    dets = selected_detections(doc.detections, accepted_only)
    det_walls = [d.get("wall") if d.get("wall") in walls or d.get("wall") in surfaces else None for d in dets]
    det_pos = np.array([d["position"] for d in dets], dtype=np.float64).reshape(-1, 3)
    det_normal = [None if w is None else walls[w].normal if w in walls else surface_normal(surfaces[w], p)
                  for w, p in zip(det_walls, det_pos, strict=True)]

    items: list[ComparisonItem] = []
    scanned: list[int] = []
    design_walls: list[str | None] = []
    for k, o in enumerate(design.objects):
        if o.surface == "wall":
            wid = locate_on_walls(o.position, o.normal, walls) if walls else None
        else:
            wid = locate_on_surfaces(o.position, o.normal, {i: s for i, s in surfaces.items() if s.kind == o.surface})
        design_walls.append(wid)
        if (walls or surfaces) and wid is None:
            items.append(ComparisonItem("not_scanned", o.class_id, designed=o))
        else:
            scanned.append(k)

    used_det: set[int] = set()
    for cid in sorted({design.objects[k].class_id for k in scanned} | {d["class"] for d in dets}):
        rows = [k for k in scanned if design.objects[k].class_id == cid]
        cols = [j for j, d in enumerate(dets) if d["class"] == cid]
        if rows and cols:
            dpos = np.array([design.objects[k].position for k in rows])
            dist = np.linalg.norm(dpos[:, None, :] - det_pos[cols][None, :, :], axis=2)
            facing = np.ones_like(dist, dtype=bool)
            for a, k in enumerate(rows):
                n = design.objects[k].normal
                for b, j in enumerate(cols):
                    if n is not None and det_normal[j] is not None:
                        facing[a, b] = float(np.dot(n, det_normal[j])) >= FACING_MIN_COS
        else:
            dist = np.zeros((len(rows), len(cols)))
            facing = np.zeros_like(dist, dtype=bool)
        free_r, free_c = set(range(len(rows))), set(range(len(cols)))
        for status, limit in (("found", tolerance_m), ("displaced", max_displacement_m)):
            mask = facing & (dist <= limit)
            for a in range(len(rows)):
                if a not in free_r:
                    mask[a, :] = False
            for b in range(len(cols)):
                if b not in free_c:
                    mask[:, b] = False
            for a, b in _assign(dist, mask):
                k, j = rows[a], cols[b]
                o = design.objects[k]
                items.append(ComparisonItem(status, cid, designed=o, detection=dets[j],
                                            design_wall=design_walls[k], detection_wall=det_walls[j],
                                            deviation=det_pos[j] - o.position))
                free_r.discard(a)
                free_c.discard(b)
                used_det.add(j)
        for a in sorted(free_r):
            k = rows[a]
            items.append(ComparisonItem("missing", cid, designed=design.objects[k], design_wall=design_walls[k]))
    for j, d in enumerate(dets):
        if j not in used_det:
            items.append(ComparisonItem("unexpected", d["class"], detection=d, detection_wall=det_walls[j]))
    order = {s: i for i, s in enumerate(("missing", "displaced", "unexpected", "found", "not_scanned"))}
    items.sort(key=lambda it: (order[it.status], it.wall or "~", it.class_id))
    # the report draws surfaces like walls (a round column's face unrolled around it)
    frames = {**walls, **{i: drawing_frame(s) for i, s in surfaces.items()}}
    return Comparison(design=design, walls=frames, openings=doc.openings, items=items, tolerance_m=float(tolerance_m),
                      max_displacement_m=float(max_displacement_m), detections_path=detections_path,
                      surfaces=surfaces)


