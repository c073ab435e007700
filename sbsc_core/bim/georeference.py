"""Georeferencing of the as-is IFC: a local engineering frame near the IFC origin and the
IfcMapConversion + IfcProjectedCRS that take it back to the scan's map coordinates.

A scan in survey coordinates (UTM, a national grid) has its points hundreds of kilometres
from the origin. Writing them as they are makes viewers jitter (single precision on the
GPU) and Revit warn about distant geometry. The export therefore places the model in a
local frame (a "project base point" at the building's plan centre rounded to the metre,
X along the building's main wall direction) and records the conversion:

    E = Eastings  + cos(a) * x - sin(a) * y
    N = Northings + sin(a) * x + cos(a) * y        with cos(a) = XAxisAbscissa,
    H = OrthogonalHeight + z                            sin(a) = XAxisOrdinate, Scale 1

(IFC4 IfcMapConversion; in IFC2X3 the same values go into the ``ePSet_MapConversion`` and
``ePSet_ProjectedCRS`` property sets of the project, as buildingSMART's guide says).
Small local coordinates without a CRS are written as they are, with no georeferencing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import ifcopenshell
import ifcopenshell.api.georeference
import numpy as np

from ..io.crs import CRS
from ..types import WallFrame

LOCAL_LIMIT_M = 1000.0  # coordinates beyond this are moved to a local frame
UNKNOWN_CRS = "unknown"


@dataclass(frozen=True)
class Georeference:
    """Map coordinates of the local origin and the angle of the local X axis (radians,
    counter-clockwise from the map's east axis)."""

    eastings: float
    northings: float
    height: float
    angle: float
    crs: CRS | None

    @property
    def rotation(self) -> np.ndarray:
        """3x3: local -> map directions."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    @property
    def offset(self) -> np.ndarray:
        return np.array([self.eastings, self.northings, self.height])

    def to_local(self, p: np.ndarray) -> np.ndarray:
        return self.rotation.T @ (np.asarray(p, float) - self.offset)

    def to_map(self, p: np.ndarray) -> np.ndarray:
        return self.rotation @ np.asarray(p, float) + self.offset

    def local_frame(self, f: WallFrame) -> WallFrame:
        r = self.rotation.T
        return replace(f, origin=self.to_local(f.origin), axis_u=r @ f.axis_u, axis_v=r @ f.axis_v,
                       normal=r @ f.normal)


def main_direction(walls: dict[str, WallFrame]) -> float:
    """The building's main wall direction in [-45, 45) degrees (radians), from the walls'
    ``axis_u`` weighted by their width (directions modulo 90 degrees averaged on the circle)."""
    if not walls:
        return 0.0
    z = sum(f.width_m * np.exp(4j * math.atan2(f.axis_u[1], f.axis_u[0])) for f in walls.values())
    if abs(z) < 1e-9:
        return 0.0
    a = float(np.angle(z) / 4.0)
    return (a + math.pi / 4) % (math.pi / 2) - math.pi / 4


def plan_georeference(walls: dict[str, WallFrame], positions: list[np.ndarray],
                      crs: CRS | None) -> Georeference | None:
    """The local frame of a model, or None when it can stay where it is (near the origin and
    no CRS known)."""
    pts = [f.origin for f in walls.values()] + [f.origin + f.axis_u * f.width_m for f in walls.values()]
    pts += list(positions)
    if not pts:
        return None
    xyz = np.asarray(pts, float)
    far = bool(np.abs(xyz[:, :2]).max() > LOCAL_LIMIT_M)
    if crs is None and not far:
        return None
    if not far:  # already local: keep the coordinates, only say which CRS they are in
        return Georeference(0.0, 0.0, 0.0, 0.0, crs)
    centre = (xyz[:, :2].min(axis=0) + xyz[:, :2].max(axis=0)) / 2
    return Georeference(float(np.round(centre[0])), float(np.round(centre[1])), 0.0, main_direction(walls), crs)


def _metre(file: ifcopenshell.file):
    for u in file.by_type("IfcSIUnit"):
        if u.UnitType == "LENGTHUNIT" and u.Name == "METRE" and not u.Prefix:
            return u
    return None


def write_georeference(file: ifcopenshell.file, geo: Georeference) -> None:
    """Add IfcProjectedCRS + IfcMapConversion (IFC2X3: the ePSet_ property sets)."""
    crs = geo.crs
    name = crs.name if crs is not None else UNKNOWN_CRS
    ifcopenshell.api.georeference.add_georeferencing(file, ifc_class="IfcMapConversion", name=name)
    description = ("the scan's coordinate reference system" if crs is not None else
                   "the scan recorded no coordinate reference system (sbsc export-ifc --crs EPSG:NNNN)")
    projected: dict = {"Name": name, "Description": description}
    if crs is not None and crs.vertical_epsg:
        projected["VerticalDatum"] = f"EPSG:{crs.vertical_epsg}"
    operation = {"Eastings": geo.eastings, "Northings": geo.northings, "OrthogonalHeight": geo.height,
                 "XAxisAbscissa": math.cos(geo.angle), "XAxisOrdinate": math.sin(geo.angle), "Scale": 1.0}
    if file.schema != "IFC2X3":
        unit = _metre(file)
        if unit is not None:
            projected["MapUnit"] = unit
    ifcopenshell.api.georeference.edit_georeferencing(file, projected_crs=projected,
                                                      coordinate_operation=operation)


def projected_crs_name(file: ifcopenshell.file) -> str | None:
    """The name of the model's projected CRS (IFC2X3: ``ePSet_ProjectedCRS``), or None."""
    if file.schema == "IFC2X3":
        import ifcopenshell.util.element

        project = next(iter(file.by_type("IfcProject")), None)
        pset = ifcopenshell.util.element.get_pset(project, "ePSet_ProjectedCRS") if project else None
        return pset.get("Name") if pset else None
    crs = next(iter(file.by_type("IfcProjectedCRS")), None)
    return crs.Name if crs is not None else None
