"""How much of each object the scanner actually saw (ground truth ``visible_fraction``).

The object's footprint is cut into ``cell_m`` cells. For each cell a ray straight onto the
wall (from just in front of the object) finds the object's surface there. The cell counts
as seen when a ray from at least one station, aimed at that surface point or at the
object's front plane over the cell, first meets the object within one cell of the aimed
point, inside the scanner's vertical field, range limits and grazing limit. Furniture,
other objects, clutter and the room itself occlude, since the rays are cast against the
full mesh; deep grooves of a profiled front seen only obliquely count as unseen.
Cells where the object has no surface (a gap in its outline) do not count.
"""

from __future__ import annotations

import math

import numpy as np

from .building import Building
from .raycast import MeshRaycaster
from .scanner import ScannerSettings


def visible_fractions(building: Building, settings: ScannerSettings, raycaster: MeshRaycaster | None = None,
                      cell_m: float = 0.01) -> list[float]:
    """``visible_fraction`` (0..1) of every object of ``building``, in its order."""
    rc = raycaster or MeshRaycaster(building.mesh)
    stations = np.asarray(building.stations, np.float64).reshape(-1, 3)
    lo_el, hi_el = math.radians(settings.elevation_min_deg), math.radians(settings.elevation_max_deg)
    out = []
    for o in building.objects:
        fr = building.frame_of(o)
        nu = max(1, round(o.width_m / cell_m))
        nv = max(1, round(o.height_m / cell_m))
        us = o.u - o.width_m / 2 + (np.arange(nu) + 0.5) * o.width_m / nu
        vs = o.v - o.height_m / 2 + (np.arange(nv) + 0.5) * o.height_m / nv
        gu, gv = np.meshgrid(us, vs)
        # probe from just in front of the object's deepest point: furniture always stands
        # further out (its back clears the objects), so the probe meets the object first
        starts = fr.to_world(gu.ravel(), gv.ravel(), building.scene.specs[o.class_id].depth_m + 0.002)
        probe = rc.cast(starts, np.tile(-fr.normal, (len(starts), 1)).astype(np.float32))
        own = (probe.label == o.index) & np.isfinite(probe.t)
        surface = starts - np.where(own, probe.t, 0.0)[:, None] * fr.normal
        cells = np.nonzero(own)[0]
        if not len(cells):
            out.append(0.0)
            continue
        # two aim points per cell: the surface the probe found and the object's front plane
        # (a ray aimed there into a groove of a ribbed front meets the groove's walls)
        aims = [surface[cells], starts[cells] - 0.002 * fr.normal]
        seen = np.zeros(len(cells), bool)
        for st in stations:
            for pts in aims:
                todo = np.nonzero(~seen)[0]
                if not len(todo):
                    break
                vec = pts[todo] - st
                dist = np.linalg.norm(vec, axis=1)
                dirs = vec / dist[:, None]
                el = np.arcsin(np.clip(dirs[:, 2], -1, 1))
                hits = rc.cast(st, dirs)
                # the first hit is the object, inside the aimed footprint cell (+-1 cell)
                off = st + np.where(np.isfinite(hits.t), hits.t, 0.0)[:, None] * dirs - pts[todo]
                near = (np.abs(off @ fr.axis_u) <= cell_m) & (np.abs(off @ fr.axis_v) <= cell_m)
                ok = ((hits.label == o.index) & near & (el >= lo_el) & (el <= hi_el)
                      & (hits.t >= settings.min_range_m) & (hits.t <= settings.max_range_m)
                      & (np.abs(np.einsum("ij,ij->i", dirs, hits.normal)) >= settings.grazing_cos))
                seen[todo[ok]] = True
        out.append(float(seen.mean()))
    return out
