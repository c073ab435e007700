"""IFC export, as-designed IFC, Scan-vs-BIM and BCF for objects on ceilings and columns (issue 11)."""

from __future__ import annotations

import copy
from functools import cache
from pathlib import Path

import ifcopenshell
import ifcopenshell.geom
import ifcopenshell.util.element
import ifcopenshell.util.placement
import ifcopenshell.validate
import numpy as np
import pytest
import yaml

from sbsc_core.bim.design import open_ifc
from sbsc_core.bim.export import export_ifc
from sbsc_core.bim.surfaces import column_bodies, read_surfaces, surface_coords, surface_normal
from sbsc_core.errors import InputError
from sbsc_core.simulate.building import build_building
from sbsc_core.simulate.scene import parse_scene
from sbsc_core.types import Surface

TWO_HALLS = Path(__file__).resolve().parents[1] / "benchmarks" / "scenes" / "two_halls.yaml"
SCHEMAS = ("IFC4", "IFC2X3", "IFC4X3")


@cache
def _truth() -> dict:
    """Two halls with ceiling objects, a rectangular and a round column (no scan: fast)."""
    scene = yaml.safe_load(TWO_HALLS.read_text())
    scene.update(ceiling_objects=True, columns=True)
    return build_building(parse_scene(scene, str(TWO_HALLS))).truth_document()


def truth() -> dict:
    return copy.deepcopy(_truth())


def detections_of(t: dict) -> dict:
    """A detections document (contract 4) that finds every object of the truth where it is."""
    dets = []
    for k, o in enumerate(t["objects"]):
        d = {"id": f"D{k:04d}", "class": o["class"], "wall": o["wall"], "position": o["position"],
             "u": o["u"], "v": o["v"], "width_m": o["width_m"], "height_m": o["height_m"],
             "alpha": 0.9, "rho_depth": 0.9, "rho_colour": 0.1, "source": "both"}
        if o.get("surface", "wall") != "wall":
            d["surface"] = o["surface"]
        dets.append(d)
    keys = ("id", "origin", "axis_u", "axis_v", "normal", "width_m", "height_m")
    return {"schema": "sbsc.detections/1", "walls": [{k: w[k] for k in keys} for w in t["walls"]],
            "openings": t["openings"], "detections": dets,
            "surfaces": [{k: v for k, v in s.items() if k != "room"} for s in t["surfaces"]]}


def validate(path: Path) -> list:
    logger = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(str(path), logger, express_rules=True)
    return logger.statements


def world(el) -> np.ndarray:
    return ifcopenshell.util.placement.get_local_placement(el.ObjectPlacement)


def body_vertices(el) -> np.ndarray:
    s = ifcopenshell.geom.settings()
    s.set("use-world-coords", True)
    shape = ifcopenshell.geom.create_shape(s, el)
    return np.asarray(shape.geometry.verts, float).reshape(-1, 3)


def test_surfaces_read_and_columns_rebuilt():
    t = truth()
    surfaces = read_surfaces(detections_of(t))
    assert {s.kind for s in surfaces.values()} == {"ceiling", "column"}
    bodies = {b.id: b for b in column_bodies(surfaces.values())}
    for col in t["columns"]:
        b = bodies[col["id"]]
        assert b.shape == col["shape"] and np.allclose(b.centre, col["centre"], atol=1e-6)
        size = col.get("size_m") or [col["diameter_m"]] * 2
        assert np.allclose(sorted(b.size_m), sorted(size), atol=1e-6)
        assert b.floor_z == pytest.approx(0.0) and b.height_m == pytest.approx(col["height_m"])
    # a round face: coordinates on the cylinder and a radial normal
    rnd = next(s for s in surfaces.values() if s.round)
    o = next(o for o in t["objects"] if o["wall"] == rnd.id)
    u, v, d = surface_coords(rnd, np.array([o["position"]]))[0]
    assert (u, v, d) == pytest.approx((o["u"], o["v"], 0.0), abs=1e-4)
    assert np.allclose(surface_normal(rnd, np.array(o["position"])), o["normal"], atol=1e-5)
    # the shared type round-trips its contract-4 entry
    entry = t["surfaces"][0]
    assert Surface.from_dict(entry).to_dict(digits=6) == entry


def test_surfaces_refused_with_the_entry_named():
    doc = detections_of(truth())
    doc["surfaces"][0]["kind"] = "floor"
    with pytest.raises(InputError, match=r"surfaces\[0\]\.kind"):
        export_ifc(doc)
    doc = detections_of(truth())
    doc["surfaces"][-1]["radius_m"] = -1.0
    with pytest.raises(InputError, match="radius_m"):
        export_ifc(doc)


@pytest.mark.parametrize("schema", SCHEMAS)
def test_export_ceiling_and_column_objects(tmp_path, schema):
    t = truth()
    doc = detections_of(t)
    path = tmp_path / f"asis_{schema}.ifc"
    export_ifc(doc, schema=schema).write(str(path))
    assert validate(path) == []
    f = open_ifc(path)  # read after the validator (it switches ifcopenshell's log to JSON)
    coverings = {c.Tag: c for c in f.by_type("IfcCovering")}
    columns = {c.Tag: c for c in f.by_type("IfcColumn")}
    assert set(coverings) == {s["id"] for s in t["surfaces"] if s["kind"] == "ceiling"}
    assert set(columns) == {c["id"] for c in t["columns"]}
    assert all(ifcopenshell.util.element.get_predefined_type(c) == "CEILING" for c in coverings.values())
    profiles = {c.Tag: c.Representation.Representations[0].Items[0].SweptArea.is_a() for c in columns.values()}
    assert profiles == {c["id"]: "IfcRectangleProfileDef" if c["shape"] == "rect" else "IfcCircleProfileDef"
                        for c in t["columns"]}
    surfaces = {s["id"]: s for s in t["surfaces"]}
    objects = {el.Tag: el for el in f.by_type("IfcElement") if el.Tag and el.Tag.startswith("D")}
    assert len(objects) == len(doc["detections"])
    worst = 0.0
    for det, o in zip(doc["detections"], t["objects"], strict=True):
        el = objects[det["id"]]
        worst = max(worst, float(np.linalg.norm(world(el)[:3, 3] - det["position"])))
        kind = o.get("surface", "wall")
        if kind == "wall":
            continue
        s = surfaces[o["wall"]]
        host = coverings[s["id"]] if kind == "ceiling" else columns[s["column"]]
        assert el.ObjectPlacement.PlacementRelTo == host.ObjectPlacement  # placed relative to its host
        assert any(r.RelatingElement == host for r in el.ConnectedFrom)
        verts = body_vertices(el)
        if kind == "ceiling":  # hangs below the ceiling
            assert verts[:, 2].max() <= s["origin"][2] + 1e-6 and verts[:, 2].min() < s["origin"][2] - 1e-3
        else:  # stands out of the column, never into it
            out = (verts - o["position"]) @ np.asarray(o["normal"])
            assert out.min() >= -1e-6 and out.max() > 1e-3
    assert worst <= 0.001


def test_export_storeys(tmp_path):
    """Two storeys: one IfcBuildingStorey each; walls, ceilings, columns and objects in their own."""
    one = detections_of(truth())
    lift = 3.5
    doc = copy.deepcopy(one)
    doc["storeys"] = [{"id": "S1", "floor_z": 0.0, "ceiling_z": 3.0}, {"id": "S2", "floor_z": lift, "ceiling_z": lift + 3}]
    for w in doc["walls"]:
        w["storey"] = "S1"
    for w in one["walls"]:
        doc["walls"].append({**w, "id": "S2-" + w["id"], "storey": "S2", "origin": np.add(w["origin"], [0, 0, lift]).tolist()})
    for s in one["surfaces"]:
        doc["surfaces"].append({**s, "id": "S2-" + s["id"], "origin": np.add(s["origin"], [0, 0, lift]).tolist(),
                                **({"column": "S2-" + s["column"]} if s.get("column") else {})})
    doc["openings"] += [{**o, "wall": "S2-" + o["wall"]} for o in one["openings"]]
    doc["detections"] += [{**d, "id": "S2-" + d["id"], "wall": "S2-" + d["wall"],
                           "position": np.add(d["position"], [0, 0, lift]).tolist()} for d in one["detections"]]
    path = tmp_path / "storeys.ifc"
    export_ifc(doc, schema="IFC4").write(str(path))
    assert validate(path) == []
    f = open_ifc(path)
    storeys = {s.Name: s for s in f.by_type("IfcBuildingStorey")}
    assert sorted(storeys) == ["storey S1", "storey S2"]
    assert storeys["storey S2"].Elevation == pytest.approx(lift)
    for el in f.by_type("IfcElement"):
        if el.is_a("IfcFeatureElement") or el.is_a("IfcDoor") or el.is_a("IfcWindow"):
            continue
        container = ifcopenshell.util.element.get_container(el)
        want = "storey S2" if (el.Tag or el.Name).startswith("S2-") else "storey S1"
        assert container.Name == want, (el.Tag, el.Name)
    objects = {el.Tag: el for el in f.by_type("IfcElement") if el.Tag and "D" in el.Tag}
    worst = max(np.linalg.norm(world(objects[d["id"]])[:3, 3] - d["position"]) for d in doc["detections"])
    assert worst <= 0.001
