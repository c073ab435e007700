"""IFC export, as-designed IFC, Scan-vs-BIM and BCF for objects on ceilings and columns (issue 11)."""

from __future__ import annotations

import copy
import math
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
from sbsc_core.bim.surfaces import (
    column_bodies,
    drawing_frame,
    read_surfaces,
    surface_coords,
    surface_normal,
)
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
    drawn = drawing_frame(rnd)  # drawn like a wall, unrolled around the column
    assert drawn.to_uvd(np.array([o["position"]]))[0] == pytest.approx((o["u"], o["v"], 0.0), abs=1e-4)
    assert np.allclose(drawn.to_world(o["u"], o["v"]), o["position"], atol=1e-4)
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
    doc = detections_of(truth())
    doc["surfaces"][0]["axis_u"] = [0.0, 0.0, 1.0]
    with pytest.raises(InputError, match=r"surfaces\[0\]\.axis_u: .* must be horizontal"):
        export_ifc(doc)


@pytest.mark.slow
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


@pytest.mark.slow
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


# --------------------------------------------------------------------------- as-designed, compare, BCF


def _design(tmp_path: Path, schema: str = "IFC4", seed: int = 0) -> tuple[Path, dict]:
    from sbsc_core.bim.design_writer import write_as_designed_ifc

    path = tmp_path / f"design_{schema}.ifc"
    res = write_as_designed_ifc(truth(), path, seed=seed, schema=schema)
    return path, res


@pytest.mark.slow
@pytest.mark.parametrize("schema", SCHEMAS)
def test_as_designed_holds_ceilings_and_columns_with_their_objects(tmp_path, schema):
    from sbsc_core.bim.design import read_as_designed

    t = truth()
    path, res = _design(tmp_path, schema)
    if schema == "IFC4":  # the same builder as the export, validated there in every schema
        assert validate(path) == []
    diffs = res["design_differences"]
    for kind in ("ceiling", "column"):  # one of each difference on each kind of surface
        assert sorted(d["kind"] for d in diffs if d["surface"] == kind) == ["added", "moved", "removed"], kind
    design = read_as_designed(path)
    assert sorted(h.kind for h in design.hosts) == ["ceiling", "ceiling", "column", "column"]
    removed = {tuple(d["built_position"]) for d in diffs if d["kind"] == "removed"}
    moved = {tuple(d["built_position"]): d["designed_position"] for d in diffs if d["kind"] == "moved"}
    want = [(o["class"], o.get("surface", "wall"), moved.get(tuple(o["position"]), o["position"]))
            for o in t["objects"] if tuple(o["position"]) not in removed]
    want += [(d["class"], d["surface"], d["designed_position"]) for d in diffs if d["kind"] == "added"]
    assert len(design.objects) == len(want)
    for cls, kind, pos in want:  # every designed object back, on its surface, within 1 mm
        o = min(design.objects, key=lambda o: np.linalg.norm(o.position - pos))
        assert (o.class_id, o.surface) == (cls, kind) and np.linalg.norm(o.position - pos) <= 0.001
        if kind == "ceiling":
            assert np.allclose(o.normal, [0, 0, -1])
    on_round = [o for o in design.objects if o.surface == "column" and o.width_m is not None]
    assert on_round and all(abs(float(np.linalg.norm(o.normal)) - 1) < 1e-9 for o in on_round)


def test_compare_finds_the_differences_per_kind_of_surface_and_bcf_validates(tmp_path):
    from lxml import etree

    from sbsc_core.bim.bcf import write_bcf
    from sbsc_core.bim.compare import compare
    from sbsc_core.bim.design import read_as_designed
    from tests.bim_fixtures import SCHEMAS as BCF_SCHEMAS
    from tests.bim_fixtures import bcf_errors
    from tests.shared_data import shared_data

    t = truth()
    path, res = _design(tmp_path, seed=3)
    cmp = compare(read_as_designed(path), detections_of(t), 0.10)
    by_kind = cmp.summary_by_surface()
    diffs = res["design_differences"]
    status = {"removed": "unexpected", "moved": "displaced", "added": "missing"}
    for kind in ("wall", "ceiling", "column"):
        want = {s: sum(d["surface"] == kind and status[d["kind"]] == s for d in diffs) for s in status.values()}
        assert {s: by_kind[kind][s] for s in want} == want, (kind, by_kind[kind])
        assert by_kind[kind]["found"] >= 1 and by_kind[kind]["not_scanned"] == 0
    assert cmp.to_dict()["summary_by_surface"] == by_kind
    for it in cmp.findings:  # each finding where the difference is
        d = next(d for d in diffs if status[d["kind"]] == it.status and d["class"] == it.class_id
                 and d["surface"] == it.surface)
        if it.designed is not None:
            assert np.linalg.norm(it.designed_position - d["designed_position"]) <= 0.001
        if it.detection is not None:
            assert np.linalg.norm(it.detected_position - d["built_position"]) <= 0.001
    bcf = tmp_path / "findings.bcf"
    write_bcf(cmp, bcf)
    folder = shared_data("bcf-xsd-2.1")
    xsd = {name: etree.XMLSchema(etree.parse(str(folder / name))) for name in set(BCF_SCHEMAS.values())}
    errors, checked = bcf_errors(bcf, xsd)
    assert errors == [] and checked["visinfo.xsd"] == len(cmp.findings)


def test_bcf_viewpoints_from_below_a_ceiling_and_beside_a_column(tmp_path):
    from sbsc_core.bim.bcf import _viewpoint
    from sbsc_core.bim.compare import compare
    from sbsc_core.bim.design import read_as_designed

    path, _ = _design(tmp_path, seed=3)
    cmp = compare(read_as_designed(path), detections_of(truth()), 0.10)
    seen = set()
    for it in cmp.findings:
        cam = _viewpoint(cmp, it).perspective_camera
        eye = np.array([cam.camera_view_point.x, cam.camera_view_point.y, cam.camera_view_point.z])
        look = np.array([cam.camera_direction.x, cam.camera_direction.y, cam.camera_direction.z])
        up = np.array([cam.camera_up_vector.x, cam.camera_up_vector.y, cam.camera_up_vector.z])
        p = it.designed_position if it.designed is not None else it.detected_position
        assert abs(float(look @ up)) < 1e-9
        if it.surface == "ceiling":  # below, looking straight up
            assert eye[2] < p[2] - 1.0 and look[2] == pytest.approx(1.0)
        elif it.surface == "column":  # in front of the face, level with the object, looking at it
            sf = cmp.surfaces[it.wall]
            n = surface_normal(sf, p)
            assert (eye - p) @ n > 1.0 and abs(look[2]) < 1e-9 and look @ n == pytest.approx(-1.0)
        seen.add(it.surface)
    assert seen == {"wall", "ceiling", "column"}


@pytest.mark.slow
def test_commands_with_ceilings_and_columns(tmp_path, capsys):
    """``sbsc export-ifc`` counts ceilings and columns; ``sbsc compare`` writes the report and
    the BCF and gives the verdicts per kind of surface."""
    import json

    from sbsc_core.cli import main

    det = tmp_path / "detections.json"
    det.write_text(json.dumps(detections_of(truth())))
    assert main(["-q", "export-ifc", str(det), "--out", str(tmp_path / "asis.ifc"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["ceilings"] == 2 and summary["columns"] == 2
    design, _ = _design(tmp_path, seed=1)
    out = tmp_path / "cmp"
    assert main(["-q", "compare", "--as-designed", str(design), "--detections", str(det), "--out", str(out),
                 "--json"]) == 0
    by_surface = json.loads(capsys.readouterr().out)["summary_by_surface"]
    assert set(by_surface) == {"wall", "ceiling", "column"}
    data = json.loads((out / "comparison.json").read_text())
    assert data["summary_by_surface"] == by_surface
    assert {it["surface"] for it in data["items"]} == {"wall", "ceiling", "column"}
    html = (out / "report.html").read_text()
    assert "Ceiling H-C<" in html and "Column face H-COL1-N<" in html and "Column face K-COL2<" in html


def test_turned_survey_frame_puts_surface_objects_back(tmp_path):
    """At UTM coordinates, turned in plan: ceilings and columns go to the local frame with the
    walls, and every object comes back within 1 mm through the map conversion."""
    import math

    from tests.bim_fixtures import UTM, _turned, world_positions

    doc = detections_of(truth())
    turned = _turned(doc, 23.5, UTM)
    a = math.radians(23.5)
    r = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    for s in doc["surfaces"]:
        s = {**s, "origin": list(r @ np.asarray(s["origin"]) + UTM),
             **{k: list(r @ np.asarray(s[k])) for k in ("axis_u", "axis_v", "normal")}}
        if "centre" in s:
            s["centre"] = list((r @ np.array([*s["centre"], 0.0]) + UTM)[:2])
        turned["surfaces"] = [*[x for x in turned["surfaces"] if x["id"] != s["id"]], s]
    model = export_ifc(turned, schema="IFC4", crs="EPSG:25832")
    world_pos, largest = world_positions(model)
    assert largest < 1000.0
    expected = {d["id"]: np.asarray(d["position"]) for d in turned["detections"]}
    assert set(world_pos) == set(expected)
    assert max(float(np.linalg.norm(world_pos[k] - expected[k])) for k in expected) < 1e-3
    for c in model.by_type("IfcColumn"):  # the columns stand in the local frame, not at UTM coordinates
        assert np.abs(world(c)[:2, 3]).max() < 1000.0


def _two_storey_truth(lift: float = 3.5) -> dict:
    """The two halls stacked: a truth with ``storeys``, ids prefixed by the storey."""
    one = truth()
    t = {"schema": "sbsc.truth/1", "storeys": [{"id": "S1", "floor_z": 0.0, "ceiling_z": 3.0},
                                               {"id": "S2", "floor_z": lift, "ceiling_z": lift + 3.0}],
         "walls": [], "openings": [], "objects": [], "surfaces": [], "columns": []}
    up = np.array([0.0, 0.0, 1.0])
    for sid, dz in (("S1", 0.0), ("S2", lift)):
        t["walls"] += [{**w, "id": f"{sid}-{w['id']}", "storey": sid, "origin": list(np.add(w["origin"], dz * up))}
                       for w in one["walls"]]
        t["openings"] += [{**o, "wall": f"{sid}-{o['wall']}"} for o in one["openings"]]
        t["objects"] += [{**o, "wall": f"{sid}-{o['wall']}", "storey": sid,
                          "position": list(np.add(o["position"], dz * up))} for o in one["objects"]]
        t["surfaces"] += [{**s, "id": f"{sid}-{s['id']}", "storey": sid, "origin": list(np.add(s["origin"], dz * up)),
                           **({"column": f"{sid}-{s['column']}"} if s.get("column") else {})} for s in one["surfaces"]]
    return t


def test_design_and_compare_of_two_storeys(tmp_path):
    from sbsc_core.bim.compare import compare
    from sbsc_core.bim.design import read_as_designed
    from sbsc_core.bim.design_writer import write_as_designed_ifc

    t = _two_storey_truth()
    path = tmp_path / "design.ifc"
    res = write_as_designed_ifc(t, path, seed=5)
    f = open_ifc(path)
    assert sorted(s.Name for s in f.by_type("IfcBuildingStorey")) == ["storey S1", "storey S2"]
    for el in [*f.by_type("IfcCovering"), *f.by_type("IfcColumn")]:
        want = "storey S2" if el.Tag.startswith("S2-") else "storey S1"
        assert ifcopenshell.util.element.get_container(el).Name == want
    diffs = res["design_differences"]
    cmp = compare(read_as_designed(path), detections_of(t), 0.10)
    by_kind = cmp.summary_by_surface()
    status = {"removed": "unexpected", "moved": "displaced", "added": "missing"}
    for kind in ("wall", "ceiling", "column"):
        want = {s: sum(d["surface"] == kind and status[d["kind"]] == s for d in diffs) for s in status.values()}
        assert {s: by_kind[kind][s] for s in want} == want, (kind, by_kind[kind])
        assert by_kind[kind]["not_scanned"] == 0


def test_design_objects_without_connections_find_their_ceiling_or_column(tmp_path):
    """A design that does not connect its objects to their hosts: each is on the ceiling
    above it or the column it stands beside, not on the nearest wall."""
    from sbsc_core.bim.design import read_as_designed

    path, _ = _design(tmp_path, seed=2)
    connected = read_as_designed(path)
    f = ifcopenshell.open(str(path))
    for rel in f.by_type("IfcRelConnectsElements"):
        f.remove(rel)
    loose = tmp_path / "loose.ifc"
    f.write(str(loose))
    got = read_as_designed(loose)
    assert len(got.objects) == len(connected.objects)
    for a, b in zip(connected.objects, got.objects, strict=True):
        assert (a.guid, a.surface) == (b.guid, b.surface)
        assert np.linalg.norm(a.position - b.position) <= 0.001


@pytest.mark.parametrize("turn", [30.0, -60.0])
def test_turned_objects_on_a_ceiling_and_a_column(turn):
    """``rotation_deg`` turns the body about the surface's normal, counter-clockwise seen from
    the room (as the simulator places it): the footprint's width runs along u turned towards v."""
    t = truth()
    doc = detections_of(t)
    surfaces = {s["id"]: s for s in t["surfaces"]}
    picks = {}
    for d in doc["detections"]:
        kind = d.get("surface")
        if kind and kind not in picks and not surfaces[d["wall"]].get("radius_m") and d["class"] == (
                "exit_light" if kind == "ceiling" else "fire_extinguisher"):
            d["rotation_deg"] = turn
            picks[kind] = d
    assert set(picks) == {"ceiling", "column"}
    model = export_ifc(doc, schema="IFC4")
    a = math.radians(turn)
    for d in picks.values():
        el = next(e for e in model.by_type("IfcElement") if e.Tag == d["id"])
        s = surfaces[d["wall"]]
        u, v, n = (np.asarray(s[k], float) for k in ("axis_u", "axis_v", "normal"))
        along = math.cos(a) * u + math.sin(a) * v  # where the footprint's width now runs
        across = -math.sin(a) * u + math.cos(a) * v
        verts = body_vertices(el) - d["position"]
        w_ext, h_ext = np.ptp(verts @ along), np.ptp(verts @ across)
        assert w_ext == pytest.approx(d["width_m"], abs=1e-6) and h_ext == pytest.approx(d["height_m"], abs=1e-6)
        assert (verts @ n).min() >= -1e-6  # still out of the surface, into the room
