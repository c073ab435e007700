"""As-designed import (a foreign-style IFC in millimetres) and the simulated design writer."""

from __future__ import annotations

import ifcopenshell
import ifcopenshell.api.aggregate
import ifcopenshell.api.context
import ifcopenshell.api.geometry
import ifcopenshell.api.project
import ifcopenshell.api.root
import ifcopenshell.api.spatial
import ifcopenshell.api.type
import ifcopenshell.api.unit
import numpy as np
import pytest

from sbsc_core.bim import bundled_typings
from sbsc_core.bim.design import read_as_designed
from sbsc_core.bim.design_writer import write_as_designed_ifc
from sbsc_core.errors import InputError
from sbsc_core.types import WallFrame
from tests.bim_fixtures import truth_document

TYPINGS = bundled_typings()


def _foreign_design(path, *, storey: bool = True) -> dict[str, list[float]]:
    """An IFC4 file as a design tool might write it: millimetres, no sbsc property sets,
    untagged types, nothing connected to the wall. Returns expected positions by name."""
    f = ifcopenshell.api.project.create_file(version="IFC4")
    project = ifcopenshell.api.root.create_entity(f, ifc_class="IfcProject", name="design")
    ifcopenshell.api.unit.assign_unit(f)  # millimetres
    model = ifcopenshell.api.context.add_context(f, context_type="Model")
    body = ifcopenshell.api.context.add_context(f, context_type="Model", context_identifier="Body",
                                                target_view="MODEL_VIEW", parent=model)
    site = ifcopenshell.api.root.create_entity(f, ifc_class="IfcSite")
    building = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuilding")
    ifcopenshell.api.aggregate.assign_object(f, products=[site], relating_object=project)
    ifcopenshell.api.aggregate.assign_object(f, products=[building], relating_object=site)
    container = building
    if storey:
        container = ifcopenshell.api.root.create_entity(f, ifc_class="IfcBuildingStorey", name="Level 0")
        ifcopenshell.api.aggregate.assign_object(f, products=[container], relating_object=building)

    def place(el, x, y, z):
        m = np.eye(4)
        m[:3, 3] = [x, y, z]
        ifcopenshell.api.spatial.assign_container(f, products=[el], relating_structure=container)
        ifcopenshell.api.geometry.edit_object_placement(f, product=el, matrix=m, is_si=True)

    def box(el, w, h, d):
        """w along X, d out of the wall towards -Y, h up (from the placement point)."""
        rep = ifcopenshell.api.geometry.add_wall_representation(f, context=body, length=w, height=h,
                                                                thickness=d, offset=-d)
        ifcopenshell.api.geometry.assign_representation(f, product=el, representation=rep)

    wall = ifcopenshell.api.root.create_entity(f, ifc_class="IfcWall", name="Basic wall 200")
    place(wall, 0.0, 0.0, 0.0)
    box(wall, 6.0, 3.0, -0.2)  # y 0..0.2: the room face is y = 0, facing -Y
    outlet_type = ifcopenshell.api.root.create_entity(f, ifc_class="IfcOutletType", name="Outlet",
                                                      predefined_type="POWEROUTLET")
    expected = {}

    def obj(ifc_class, name, x0, z0, w, h, d, predefined=None, object_type=None, typ=None, y=0.0):
        el = ifcopenshell.api.root.create_entity(f, ifc_class=ifc_class, name=name, predefined_type=predefined)
        if object_type:
            el.ObjectType = object_type
        place(el, x0, y, z0)
        box(el, w, h, d)
        if typ is not None:
            ifcopenshell.api.type.assign_type(f, related_objects=[el], relating_type=typ)
        expected[name] = [x0 + w / 2, y, z0 + h / 2]

    obj("IfcOutlet", "A-1", 1.0, 0.26, 0.08, 0.08, 0.012, typ=outlet_type)
    obj("IfcOutlet", "A-2", 2.0, 0.26, 0.29, 0.08, 0.012, typ=outlet_type)
    obj("IfcBuildingElementProxy", "Sign", 3.0, 1.8, 0.21, 0.30, 0.003, "USERDEFINED", "EXTINGUISHERSIGN")
    obj("IfcFireSuppressionTerminal", "FE", 3.0, 0.9, 0.20, 0.60, 0.18, "USERDEFINED", "FIREEXTINGUISHER")
    obj("IfcSwitchingDevice", "S-1", 4.0, 1.06, 0.08, 0.08, 0.012, "TOGGLESWITCH", y=-1.5)  # off the wall
    obj("IfcFurniture", "Desk", 4.5, 0.0, 1.2, 0.75, 0.6)
    f.write(str(path))
    return expected


def test_reads_a_foreign_design(tmp_path):
    path = tmp_path / "design.ifc"
    expected = _foreign_design(path)
    design = read_as_designed(path, typings=TYPINGS)
    assert len(design.walls) == 1 and design.walls[0].thickness_m == pytest.approx(0.2)
    got = {o.name: o for o in design.objects}
    assert {n: o.class_id for n, o in got.items()} == {
        "A-1": "socket_x1", "A-2": "socket_x4", "Sign": "extinguisher_sign", "FE": "fire_extinguisher",
        "S-1": "switch"}
    assert got["A-1"].matched_by == "size" and got["A-2"].matched_by == "size"
    assert got["Sign"].matched_by == "typing"
    for name in ("A-1", "A-2", "Sign", "FE"):
        o = got[name]
        assert np.abs(o.position - expected[name]).max() < 1e-3, name
        assert o.wall_name == "Basic wall 200" and o.normal == pytest.approx([0.0, -1.0, 0.0])
    assert got["A-2"].width_m == pytest.approx(0.29) and got["FE"].height_m == pytest.approx(0.60)
    # the switch stands 1.5 m off the wall: no host, the body's centre
    assert got["S-1"].wall_guid is None
    assert np.abs(got["S-1"].position - [4.04, -1.506, 1.10]).max() < 1e-3
    assert design.unmapped == [{"ifc_class": "IfcFurniture", "predefined_type": None, "object_type": None, "count": 1}]
    assert design.expected_counts() == {"extinguisher_sign": 1, "fire_extinguisher": 1, "socket_x1": 1,
                                        "socket_x4": 1, "switch": 1}
    assert design.expected_document()["schema"] == "sbsc.expected/1"
    # a scanned wall on the room face (right-handed frame seen from y < 0), one elsewhere
    scan = {"S1": WallFrame(np.array([0.3, -0.01, 0.0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]),
                            np.array([0, -1.0, 0]), 5.5, 2.9),
            "S2": WallFrame(np.array([0.0, 5.0, 0.0]), np.array([-1.0, 0, 0]), np.array([0, 0, 1.0]),
                            np.array([0, 1.0, 0]), 6.0, 2.9)}
    assert design.expected_by_wall(scan) == {"S1": {"extinguisher_sign": 1, "fire_extinguisher": 1,
                                                    "socket_x1": 1, "socket_x4": 1}}
    assert design.wall_matches(scan) == {design.walls[0].guid: ["S1"]}


def test_refuses_bad_files(tmp_path):
    cases = {}
    p = tmp_path / "notes.ifc"
    p.write_text("just some text\n")
    cases[p] = "not an IFC file"
    good = tmp_path / "good.ifc"
    _foreign_design(good)
    text = good.read_text()
    p = tmp_path / "truncated.ifc"
    p.write_text(text[: len(text) // 2])
    cases[p] = "malformed IFC file"
    p = tmp_path / "garbage.ifc"
    p.write_text(text.replace("IFCWALL(", "IFCWALLX(", 1))
    cases[p] = "malformed IFC file"
    p = tmp_path / "ifc9.ifc"
    p.write_text(text.replace("FILE_SCHEMA(('IFC4'))", "FILE_SCHEMA(('IFC9'))"))
    cases[p] = "unsupported IFC schema"
    p = tmp_path / "nostorey.ifc"
    _foreign_design(p, storey=False)
    cases[p] = "no IfcBuildingStorey"
    cases[tmp_path / "absent.ifc"] = "no such file"
    for path, reason in cases.items():
        with pytest.raises(InputError) as exc:
            read_as_designed(path, typings=TYPINGS)
        msg = str(exc.value)
        assert msg.startswith(str(path)) and reason in msg and "\n" not in msg, msg


def test_writes_a_design_with_known_differences(tmp_path):
    truth = truth_document()
    out = tmp_path / "as_designed.ifc"
    res = write_as_designed_ifc(truth, out, seed=3, n_moved=2, n_removed=2, n_added=2, typings=TYPINGS)
    again = write_as_designed_ifc(truth, tmp_path / "again.ifc", seed=3, n_moved=2, n_removed=2, n_added=2,
                                  typings=TYPINGS)
    assert res["as_designed"] == "as_designed.ifc"
    diffs = res["design_differences"]
    assert diffs == again["design_differences"]  # deterministic for a seed
    kinds = [d["kind"] for d in diffs]
    assert kinds.count("moved") == 2 and kinds.count("removed") == 2 and kinds.count("added") == 2
    design = read_as_designed(out, typings=TYPINGS)
    designed = sorted((o.class_id, *np.round(o.position, 3)) for o in design.objects)
    built = [(o["class"], *np.round(o["position"], 3)) for o in truth["objects"]]
    for d in diffs:
        if d["kind"] in ("removed", "moved"):
            built.remove((d["class"], *np.round(d["built_position"], 3)))
        if d["kind"] in ("moved", "added"):
            built.append((d["class"], *np.round(d["designed_position"], 3)))
        if d["kind"] == "moved":
            assert 0.4 <= d["shift_m"] <= 0.8
            assert d["designed_position"][2] == pytest.approx(d["built_position"][2])
    assert designed == sorted(built)
    assert all(o.matched_by in ("name", "typing") for o in design.objects)  # no sbsc pset in a design
    # every designed object stays on its wall face (moved/added ones clear of openings)
    for o in design.objects:
        assert o.wall_name in {"W1", "W2", "W3"}
        assert 0 < o.u < 5.0 and 0 < o.v < 2.7


def test_design_writer_refuses_a_bad_truth(tmp_path):
    truth = truth_document()
    del truth["objects"][2]["position"]
    with pytest.raises(InputError, match=r"ground truth: objects\[2\]"):
        write_as_designed_ifc(truth, tmp_path / "x.ifc", typings=TYPINGS)
    assert not (tmp_path / "x.ifc").exists()
