"""Objects that hang from the ceiling (pendants): exit signs and the like on a rod or a wire.

A pendant object is neither on a wall nor on a ceiling: it is an upright panel of its own in
the room's free space, a few centimetres to a metre below the ceiling. It is found as a
surface, then searched like a column's face (:mod:`sbsc_core.scene.columns`).

**Finding pendants.** In each storey, the segmentation sample's points between ``reach_m``
below the ceiling and ``gap_m`` below it, that are not on a wall (``wall_clear_m`` from its
plane) nor on a column, are binned into plan cells of ``cell_m``; connected groups of cells
are the candidates. A group is a pendant panel when

- its points lie on an upright plane: seen in plan they are at most ``max_thickness_m``
  thick across their main direction, and they rise at least ``upright_ratio`` times that;
- it is as wide and as tall as an object that may be mounted on a ceiling could be: between
  ``size_slack`` times less and more than the smallest and the largest such class of the
  library (so the library, not a rule about one design, says what size to look for);
- it hangs: under it, down to ``below_m`` above the floor, there are (almost) no points
  (furniture stands on the floor; a pendant has free space below).

**Faces.** A panel becomes one surface (``kind`` ``pendant``, ``hangs_from`` the storey's
ceiling): an upright frame framed like a wall (origin at the lower-left corner seen from the
side the scanner saw, ``axis_v`` up, ``normal`` towards that side). Its plane is the panel's
back (the far side of its points from where it was seen), so that the panel stands out of
it as an object stands out of its wall. A double-sided sign seen from both sides still gives
one surface (the side with more points on it), so it is found once. The surface reaches
``margin_m`` beyond the panel on each side, and at the top no closer than ``gap_m`` to the
ceiling (whose points would cross the image).

Objects found on a pendant's surface are objects on the ceiling (``surface: ceiling``); the
classes searched there are those whose ``mount`` has ``ceiling``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..imaging.orthoimage import near_walls
from ..settings import PendantSettings
from ..types import PointCloud, Segmentation, WallFrame
from .ceilings import CeilingLevels
from .columns import ColumnFace, FoundColumn

_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class PendantFace(ColumnFace):
    """The surface of a panel hanging from the ceiling (see the module docstring)."""

    hangs_from: str | None = None  # the ceiling's storey id (None: the scan's only ceiling)

    def surface(self) -> dict:
        doc = {"id": self.id, "kind": "pendant", **self.frame.to_dict()}
        if self.hangs_from is not None:
            doc["hangs_from"] = self.hangs_from
        if self.storey is not None:
            doc["storey"] = self.storey
        return doc


def _panel_face(xyz: np.ndarray, ceiling_z: float, s: PendantSettings, *, size_m: tuple[float, float]
                ) -> WallFrame | None:
    """The frame of a group of points (world, float64) when they are an upright panel whose width
    and height lie within ``size_m`` (smallest, largest), else None."""
    xy = xyz[:, :2]
    centre = xy.mean(axis=0)
    cov = np.cov((xy - centre).T)
    _, v = np.linalg.eigh(cov)
    along, across = v[:, 1], v[:, 0]
    a = (xy - centre) @ along
    n = (xy - centre) @ across
    a0, a1 = np.percentile(a, [1.0, 99.0])
    n0, n1 = np.percentile(n, [1.0, 99.0])
    z0, z1 = np.percentile(xyz[:, 2], [1.0, 99.0])
    thick, wide, tall = float(n1 - n0), float(a1 - a0), float(z1 - z0)
    if thick > s.max_thickness_m or tall < s.upright_ratio * max(thick, 1e-3):
        return None
    if not (size_m[0] <= wide <= size_m[1] and size_m[0] <= tall <= size_m[1]):
        return None
    # the side seen: the one with more points on it (within 1 cm of its extreme)
    plus = int(np.count_nonzero(n > n1 - 0.01))
    minus = int(np.count_nonzero(n < n0 + 0.01))
    normal2 = across if plus >= minus else -across
    back = n0 if plus >= minus else -n1  # the panel's back, along normal2
    normal = np.array([normal2[0], normal2[1], 0.0])
    u = np.cross(_UP, normal)
    top = min(float(z1) + s.margin_m, ceiling_z - s.gap_m)
    bottom = float(z0) - s.margin_m
    mid = np.array([centre[0], centre[1], 0.0]) + back * normal + ((a0 + a1) / 2) * np.array([along[0], along[1], 0.0])
    width = wide + 2 * s.margin_m
    origin = mid - width / 2 * u
    origin[2] = bottom
    return WallFrame(origin, u, _UP.copy(), normal, float(width), float(top - bottom))


def _taken(seg: Segmentation, columns: list[FoundColumn], *, storey: str | None, shape: tuple[int, int],
           lo: np.ndarray, s: PendantSettings) -> np.ndarray:
    """A plan grid (``shape`` = (nx, ny) cells of ``cell_m`` from ``lo``) with the cells within
    ``wall_clear_m`` of a wall of the storey or of a column's footprint set (uint8)."""
    import cv2

    nx, ny = shape
    grid = np.zeros((ny, nx), np.uint8)
    scale = 1.0 / s.cell_m
    thick = max(1, int(math.ceil(2 * s.wall_clear_m * scale)))
    for w in seg.walls:
        if storey is not None and w.storey not in (storey, None):
            continue
        f = w.frame
        a = (np.asarray(f.origin[:2], np.float64) - lo) * scale
        b = a + np.asarray(f.axis_u[:2], np.float64) * f.width_m * scale
        cv2.line(grid, (int(round(a[0])), int(round(a[1]))), (int(round(b[0])), int(round(b[1]))), 1, thick)
    for c in columns:
        if c.storey in (storey, None):
            r = (max(c.size_m) / 2 * math.sqrt(2) + s.wall_clear_m) * scale
            centre = (np.asarray(c.centre, np.float64) - lo) * scale
            cv2.circle(grid, (int(round(centre[0])), int(round(centre[1]))), int(math.ceil(r)), 1, -1)
    return grid


def _hangs(cloud: PointCloud, seg: Segmentation, pts: np.ndarray, *, storey: str | None, floor_z: float,
           s: PendantSettings) -> bool:
    """Whether (almost) nothing stands under the panel ``pts`` (world), from ``below_m`` above
    the floor to ``margin_m`` under the panel, over its plan box grown by ``margin_m``; the
    walls' points do not count (a panel may hang near a wall)."""
    pmin, pmax = pts[:, :2].min(axis=0) - s.margin_m, pts[:, :2].max(axis=0) + s.margin_m
    zmin = float(np.percentile(pts[:, 2], 1.0))
    origin = np.asarray(cloud.origin, np.float64)
    x = cloud.xyz[:, 0]
    idx = np.flatnonzero((x > pmin[0] - origin[0]) & (x < pmax[0] - origin[0]))
    y = cloud.xyz[idx, 1].astype(np.float64) + origin[1]
    z = cloud.xyz[idx, 2].astype(np.float64) + origin[2]
    idx = idx[(y > pmin[1]) & (y < pmax[1]) & (z > floor_z + s.below_m) & (z < zmin - s.margin_m)]
    if len(idx) <= s.max_under_share * len(pts):
        return True
    walls = [w.frame for w in seg.walls if storey is None or w.storey in (storey, None)]
    on_walls = near_walls(cloud.xyz[idx], walls, s.wall_clear_m, cloud.origin)
    return int(np.count_nonzero(~on_walls)) <= s.max_under_share * len(pts)


def find_pendants(cloud: PointCloud, seg: Segmentation, s: PendantSettings, *,
                  sizes: list[tuple[float, float]], columns: list[FoundColumn] = (),
                  levels: list[CeilingLevels] | None = None) -> list[PendantFace]:
    """The surfaces of the panels hanging from the ceilings of every storey (see the module).

    Parameters
    ----------
    cloud
        The segmentation sample (any regular sample of the scan).
    seg
        Its storeys (or floor and ceiling) and walls.
    s
        The search's settings.
    sizes
        (width, height) in metres of every class that may be mounted on a ceiling: a panel
        is searched for between the smallest and the largest of them (``size_slack``).
    columns
        The free-standing columns found: their points are not panels.
    levels
        The storeys' lower ceilings (:func:`~sbsc_core.scene.ceilings.ceiling_levels`): a
        panel hangs from the ceiling above it.

    Returns
    -------
    list of PendantFace
        One surface per panel, ids ``P1``, ``P2`` ... (``S2-P1`` with several storeys).
    """
    import cv2

    if not sizes:
        return []
    lo_m = min(min(w, h) for w, h in sizes) / s.size_slack
    hi_m = max(max(w, h) for w, h in sizes) * s.size_slack
    storeys = [(st.id, st.floor_z, st.ceiling_z) for st in seg.storeys] or [(None, seg.floor_z, seg.ceiling_z)]
    origin = np.asarray(cloud.origin, np.float64)
    zr = cloud.xyz[:, 2]  # float32, relative to the origin: compared with thresholds made so
    out: list[PendantFace] = []
    for sid, fz, cz in storeys:
        level = next((lv for lv in levels or [] if lv.storey == sid), None)
        lowest = min([cz, *(level.z if level is not None else ())])
        z_lo, z_hi = max(fz + s.below_m, lowest - s.reach_m), cz - s.gap_m
        band = np.flatnonzero((zr > np.float32(z_lo - origin[2])) & (zr < np.float32(z_hi - origin[2])))
        xy = np.take(cloud.xyz, band, axis=0)[:, :2].astype(np.float64) + origin[:2]  # take: as xyz[band], faster
        z_band = zr[band].astype(np.float64) + origin[2]
        # the ceiling over each point: the storey's or a lower one
        top = np.r_[cz, level.z][level.label(xy)] if level is not None else np.full(len(band), cz)
        inside = (z_band > top - s.reach_m) & (z_band < top - s.gap_m)
        band, xy, z_band, top = band[inside], xy[inside], z_band[inside], top[inside]
        if len(band) < s.min_points:
            continue
        lo = np.array([xy[:, 0].min(), xy[:, 1].min()])  # xy.min(axis=0), without its slow reduction of 2 columns
        ij = np.floor((xy - lo) / s.cell_m).astype(np.int64)
        nx, ny = int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1
        cell = ij[:, 1] * nx + ij[:, 0]
        occ = (np.bincount(cell, minlength=nx * ny) >= s.min_cell_points).reshape(ny, nx).astype(np.uint8)
        taken = _taken(seg, list(columns), storey=sid, shape=(nx, ny), lo=lo, s=s) > 0  # walls' and columns' cells
        occ[taken] = 0
        grown = cv2.dilate(occ, np.ones((3, 3), np.uint8))
        grown[taken] = 0
        n, labels = cv2.connectedComponents(grown, connectivity=8)
        lab = labels.ravel()[cell]
        mine = np.flatnonzero(lab > 0)
        order = mine[np.argsort(lab[mine], kind="stable")]
        starts = np.searchsorted(lab[order], np.arange(1, n + 1))
        for k in range(1, n):
            idx = order[starts[k - 1]:starts[k]]
            if len(idx) < s.min_points:
                continue
            pts = np.column_stack([xy[idx], z_band[idx]])
            frame = _panel_face(pts, float(top[idx].min()), s, size_m=(lo_m, hi_m))
            if frame is None:
                continue
            if not _hangs(cloud, seg, pts, storey=sid, floor_z=fz, s=s):
                continue
            pid = (f"{sid}-" if sid and len(storeys) > 1 else "") + f"P{len(out) + 1}"
            out.append(PendantFace(pid, pid, sid, frame, hangs_from=sid))
    return out
