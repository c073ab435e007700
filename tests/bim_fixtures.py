"""Small hand-written documents for the BIM tests (no tests here).

A room 5 m x 4 m (x 0..5, y 0..4): W1 is its south wall (y = 0), W2 its east wall
(x = 5); W3 is the other face of the W1 partition, seen from the room behind it
(y < -0.15). Frames follow contract 4: origin at the lower-left corner seen from the
room, ``axis_u`` to the right, ``normal`` into the room (u x v = normal).
"""

from __future__ import annotations

import copy
import json
import math
import zipfile
from pathlib import Path

import ifcopenshell
import ifcopenshell.util.element
import ifcopenshell.util.placement
import numpy as np
from lxml import etree

from sbsc_core.types import WallFrame

HEIGHT = 2.7

WALLS = [
    {"id": "W1", "origin": [5.0, 0.0, 0.0], "axis_u": [-1.0, 0.0, 0.0], "axis_v": [0.0, 0.0, 1.0],
     "normal": [0.0, 1.0, 0.0], "width_m": 5.0, "height_m": HEIGHT},
    {"id": "W2", "origin": [5.0, 4.0, 0.0], "axis_u": [0.0, -1.0, 0.0], "axis_v": [0.0, 0.0, 1.0],
     "normal": [-1.0, 0.0, 0.0], "width_m": 4.0, "height_m": HEIGHT},
    {"id": "W3", "origin": [0.0, -0.15, 0.0], "axis_u": [1.0, 0.0, 0.0], "axis_v": [0.0, 0.0, 1.0],
     "normal": [0.0, -1.0, 0.0], "width_m": 5.0, "height_m": HEIGHT},
]

OPENINGS = [
    {"wall": "W1", "kind": "door", "u_min": 3.0, "u_max": 3.9, "v_min": 0.0, "v_max": 2.05},
    {"wall": "W3", "kind": "door", "u_min": 1.1, "u_max": 2.0, "v_min": 0.0, "v_max": 2.05},
    {"wall": "W2", "kind": "window", "u_min": 1.8, "u_max": 2.6, "v_min": 0.9, "v_max": 2.0},
]

# (class, wall, u, v, width, height)
OBJECTS = [
    ("socket_x1", "W1", 0.6, 0.3, 0.08, 0.08),
    ("switch", "W1", 2.2, 1.1, 0.08, 0.08),
    ("smoke_detector", "W1", 4.4, 2.3, 0.11, 0.11),
    ("socket_x4", "W2", 3.2, 0.3, 0.29, 0.08),
    ("fire_extinguisher", "W2", 1.0, 1.2, 0.20, 0.60),
    ("extinguisher_sign", "W2", 1.0, 1.95, 0.21, 0.30),
    ("radiator", "W2", 2.2, 0.45, 0.80, 0.60),
    ("socket_x1", "W3", 4.4, 0.3, 0.08, 0.08),  # back to back with the first socket
]


def frames() -> dict[str, WallFrame]:
    return {w["id"]: WallFrame.from_dict(w) for w in WALLS}


def world(wall: str, u: float, v: float) -> list[float]:
    return [float(x) for x in frames()[wall].to_world(u, v)]


def truth_document() -> dict:
    """Contract 5 extended with walls, openings and per-object wall/u/v."""
    f = frames()
    return {
        "schema": "sbsc.truth/1", "walls": copy.deepcopy(WALLS), "openings": copy.deepcopy(OPENINGS),
        "objects": [{"class": c, "position": world(w, u, v), "normal": [float(x) for x in f[w].normal],
                     "width_m": wd, "height_m": ht, "wall": w, "u": u, "v": v}
                    for c, w, u, v, wd, ht in OBJECTS],
    }


def detections_document(objects=None, *, noise_m: float = 0.0, seed: int = 0,
                        statuses: dict[int, str] | None = None) -> dict:
    """Contract 4 document of ``objects`` (default: all of OBJECTS), each reviewed
    ``accepted`` unless ``statuses`` says otherwise (``"none"``: no review key)."""
    rng = np.random.default_rng(seed)
    objects = OBJECTS if objects is None else objects
    dets = []
    for i, (c, w, u, v, wd, ht) in enumerate(objects):
        du, dv = rng.normal(0.0, noise_m, 2) if noise_m else (0.0, 0.0)
        det = {"id": f"D{i:04d}", "class": c, "wall": w, "position": world(w, u + du, v + dv),
               "u": u + du, "v": v + dv, "width_m": wd, "height_m": ht,
               "alpha": round(0.5 + 0.05 * i, 3), "rho_depth": round(0.7 + 0.01 * i, 3),
               "rho_colour": None if i % 2 else round(0.05 + 0.01 * i, 3),
               "source": "depth" if i % 2 else "both"}
        status = (statuses or {}).get(i, "accepted")
        if status != "none":
            det["review"] = {"status": status, "by": "ana", "at": f"2024-05-0{1 + i % 9}T10:00:00Z",
                             "version": 1 + i}
        dets.append(det)
    return {"schema": "sbsc.detections/1", "walls": copy.deepcopy(WALLS),
            "openings": copy.deepcopy(OPENINGS), "detections": dets}


UTM = np.array([412359.27, 5612351.81, 78.4])


def _turned(doc: dict, deg: float, shift: np.ndarray) -> dict:
    """The document turned by ``deg`` in plan and moved by ``shift`` (a survey's coordinates)."""
    a = math.radians(deg)
    r = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    doc = json.loads(json.dumps(doc))
    for w in doc["walls"]:
        w["origin"] = list(r @ np.asarray(w["origin"]) + shift)
        for k in ("axis_u", "axis_v", "normal"):
            w[k] = list(r @ np.asarray(w[k]))
    for d in doc["detections"]:
        d["position"] = list(r @ np.asarray(d["position"]) + shift)
    return doc


def map_conversion(model: ifcopenshell.file) -> tuple[str, np.ndarray, float, float]:
    """(CRS name, [E, N, H], XAxisAbscissa, XAxisOrdinate) as written (IFC4 entities or IFC2X3 psets)."""
    if model.schema == "IFC2X3":
        project = model.by_type("IfcProject")[0]
        crs = ifcopenshell.util.element.get_pset(project, "ePSet_ProjectedCRS")
        mc = ifcopenshell.util.element.get_pset(project, "ePSet_MapConversion")
        return crs["Name"], np.array([mc["Eastings"], mc["Northings"], mc["OrthogonalHeight"]]), \
            mc["XAxisAbscissa"], mc["XAxisOrdinate"]
    mc = model.by_type("IfcMapConversion")[0]
    assert mc.TargetCRS.is_a("IfcProjectedCRS") and mc.SourceCRS.is_a("IfcGeometricRepresentationContext")
    assert (mc.Scale or 1.0) == 1.0
    return mc.TargetCRS.Name, np.array([mc.Eastings, mc.Northings, mc.OrthogonalHeight]), \
        mc.XAxisAbscissa, mc.XAxisOrdinate


def world_positions(model: ifcopenshell.file) -> tuple[dict[str, np.ndarray], float]:
    """Each tagged object's placement origin taken to map coordinates by the file's own map
    conversion (formula of IfcMapConversion), and the largest local plan coordinate."""
    _, enh, ab, ord_ = map_conversion(model)
    scale = math.hypot(ab, ord_)
    c, s = ab / scale, ord_ / scale
    out, largest = {}, 0.0
    for e in model.by_type("IfcProduct"):
        if e.ObjectPlacement is None:
            continue
        p = ifcopenshell.util.placement.get_local_placement(e.ObjectPlacement)[:3, 3]
        largest = max(largest, float(np.abs(p[:2]).max()))
        tag = getattr(e, "Tag", None) if e.is_a("IfcElement") else None
        if (tag or "").startswith("D"):
            out[tag] = np.array([enh[0] + c * p[0] - s * p[1], enh[1] + s * p[0] + c * p[1], enh[2] + p[2]])
    return out, largest


SCHEMAS = {"markup.bcf": "markup.xsd", ".bcfv": "visinfo.xsd", "project.bcfp": "project.xsd",
           "bcf.version": "version.xsd"}


def _schema_for(name: str) -> str | None:
    for key, schema in SCHEMAS.items():
        if name.endswith(key):
            return schema
    return None


def bcf_errors(path: Path, xsd: dict[str, etree.XMLSchema]) -> tuple[list[str], dict[str, int]]:
    """XSD errors of every XML file of a BCF zip, and how many files of each schema were checked."""
    errors, checked = [], {}
    with zipfile.ZipFile(path) as z:
        for name in z.namelist():
            schema = _schema_for(name)
            if schema is None:
                continue
            checked[schema] = checked.get(schema, 0) + 1
            doc = etree.fromstring(z.read(name))
            if not xsd[schema].validate(doc):
                errors += [f"{name}:{e.line}: {e.message}" for e in xsd[schema].error_log]
    return errors, checked
