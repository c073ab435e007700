"""As-is IFC export: schema validity (with EXPRESS rules), round trip, typing, sign-off."""

from __future__ import annotations

import ifcopenshell
import ifcopenshell.util.element
import ifcopenshell.validate
import numpy as np
import pytest

from sbsc_core.bim import PSET_RECOGNITION, bundled_typings
from sbsc_core.bim.design import read_as_designed
from sbsc_core.bim.export import export_ifc, wall_thicknesses
from sbsc_core.errors import InputError
from tests.bim_fixtures import OBJECTS, detections_document, frames

SIGNOFF = {"by": "maria", "at": "2024-05-03T17:30:00", "comment": "checked on site",
           "counts": {"accepted": 6, "rejected": 1}}
# detection 2 pending, 6 rejected, 7 without a review key (pending)
STATUSES = {2: "pending", 6: "rejected", 7: "none"}


def _export(tmp_path, schema: str, **kw):
    doc = detections_document(statuses=STATUSES)
    model = export_ifc(doc, schema=schema, typings=bundled_typings(), **kw)
    path = tmp_path / f"asis_{schema}.ifc"
    model.write(str(path))
    return doc, path


def _validate(model_or_path) -> list:
    logger = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(model_or_path, logger, express_rules=True)
    return logger.statements


@pytest.mark.slow
@pytest.mark.parametrize("schema", ["IFC4", "IFC4X3"])
def test_export_passes_validation_and_reads_back(tmp_path, schema):
    doc, path = _export(tmp_path, schema, signoff=SIGNOFF)
    assert _validate(str(path)) == []

    f = ifcopenshell.open(str(path))
    assert f.schema_identifier.startswith(schema)
    assert len(f.by_type("IfcProject")) == len(f.by_type("IfcSite")) == len(f.by_type("IfcBuilding")) == 1
    storey = f.by_type("IfcBuildingStorey")[0]
    walls = {w.Name: w for w in f.by_type("IfcWall")}
    assert sorted(walls) == ["W1", "W2", "W3"]
    # openings void their walls; the door seen from both sides of the partition is one door
    assert len(f.by_type("IfcOpeningElement")) == 3
    assert len(f.by_type("IfcDoor")) == 1 and len(f.by_type("IfcWindow")) == 1
    assert all(o.VoidsElements and o.VoidsElements[0].RelatingBuildingElement.is_a("IfcWall")
               for o in f.by_type("IfcOpeningElement"))
    assert f.by_type("IfcWindow")[0].FillsVoids[0].RelatingOpeningElement.VoidsElements[0] \
        .RelatingBuildingElement.Name == "W2"

    # re-read: every written object with class, position (1 mm) and properties
    design = read_as_designed(path, typings=bundled_typings())
    written = [d for i, d in enumerate(doc["detections"]) if STATUSES.get(i) != "rejected"]
    assert len(design.objects) == len(written) == 7
    by_id = {f.by_guid(o.guid).Tag: o for o in design.objects}
    for det in written:
        o = by_id[det["id"]]
        assert o.class_id == det["class"] and o.matched_by == "pset"
        assert np.abs(o.position - det["position"]).max() < 1e-3
        assert o.wall_name == det["wall"]
        el = f.by_guid(o.guid)
        props = ifcopenshell.util.element.get_psets(el)[PSET_RECOGNITION]
        assert props["Class"] == det["class"] and props["DetectionId"] == det["id"]
        assert props["Alpha"] == pytest.approx(det["alpha"])
        assert props["RhoDepth"] == pytest.approx(det["rho_depth"])
        assert props.get("RhoColour") == (None if det["rho_colour"] is None else pytest.approx(det["rho_colour"]))
        assert props["Source"] == det["source"]
        review = det.get("review", {"status": "pending"})
        assert props["ReviewStatus"] == review["status"]
        assert props.get("ReviewedBy") == review.get("by") and props.get("ReviewedAt") == review.get("at")
        # placed relative to its wall, connected to it, in the storey
        assert el.ObjectPlacement.PlacementRelTo == walls[det["wall"]].ObjectPlacement
        connected = [r.RelatingElement for r in el.ConnectedFrom]
        assert connected == [walls[det["wall"]]]
        assert el.ContainedInStructure[0].RelatingStructure == storey
        assert el.Representation.Representations[0].RepresentationType == "SweptSolid"

    # IFC typing from the library: class, predefined type, ObjectType
    outlet = f.by_type("IfcOutlet")
    assert {ifcopenshell.util.element.get_predefined_type(e) for e in outlet} == {"POWEROUTLET"}
    assert ifcopenshell.util.element.get_predefined_type(f.by_type("IfcSwitchingDevice")[0]) == "TOGGLESWITCH"
    assert not f.by_type("IfcSpaceHeater")  # the radiator's detection was rejected
    assert f.by_type("IfcSensor")[0].IsTypedBy[0].RelatingType.PredefinedType == "SMOKESENSOR"
    ext = f.by_type("IfcFireSuppressionTerminal")[0]
    assert ext.ObjectType == "FIREEXTINGUISHER"
    assert ext.IsTypedBy[0].RelatingType.PredefinedType == "USERDEFINED"
    if schema == "IFC4X3":
        sign = f.by_type("IfcSign")[0]
        assert sign.IsTypedBy[0].RelatingType.PredefinedType == "PICTORAL"
    else:
        sign = [e for e in f.by_type("IfcBuildingElementProxy")][0]
        assert sign.ObjectType == "EXTINGUISHERSIGN"
        assert sign.IsTypedBy[0].RelatingType.ElementType == "EXTINGUISHERSIGN"

    # one type object per class, shared by its occurrences (two socket_x1 written)
    types = [t for t in f.by_type("IfcTypeObject")]
    assert len(types) == len({t.Tag for t in types}) == len({d["class"] for d in written})
    socket_type = [t for t in types if t.Tag == "socket_x1"][0]
    assert len(socket_type.Types[0].RelatedObjects) == 2

    # the sign-off as an approval
    approval = f.by_type("IfcApproval")[0]
    assert approval.Status == "APPROVED" and approval.Description == "checked on site"
    assert approval.TimeOfApproval == "2024-05-03T17:30:00"
    assert approval.GivingApproval.Identification == "maria"
    assert "accepted=6" in approval.Qualifier
    related = approval.ApprovedObjects[0].RelatedObjects
    assert f.by_type("IfcProject")[0] in related and len(related) == 1 + 7


@pytest.mark.slow
def test_validator_catches_a_broken_rule(tmp_path):
    """Negative control: the EXPRESS rules really run (USERDEFINED type without ElementType)."""
    _, path = _export(tmp_path, "IFC4")
    f = ifcopenshell.open(str(path))
    f.by_type("IfcBuildingElementProxyType")[0].ElementType = None
    assert _validate(f) != []


def test_accepted_only_and_rejected_never_written():
    doc = detections_document(statuses=STATUSES)
    all_model = export_ifc(doc, typings=bundled_typings())
    acc_model = export_ifc(doc, accepted_only=True, typings=bundled_typings())
    tags = lambda m: sorted(e.Tag for e in m.by_type("IfcElement") if e.Tag and e.Tag.startswith("D"))  # noqa: E731
    assert tags(all_model) == ["D0000", "D0001", "D0002", "D0003", "D0004", "D0005", "D0007"]
    assert tags(acc_model) == ["D0000", "D0001", "D0003", "D0004", "D0005"]
    assert not all_model.by_type("IfcApproval")


def test_geometry_of_walls_and_object_bodies():
    f = export_ifc(detections_document(), typings=bundled_typings())
    import ifcopenshell.geom
    import ifcopenshell.util.shape

    s = ifcopenshell.geom.settings()
    s.set("use-world-coords", True)
    s.set("disable-opening-subtractions", True)
    fr = frames()
    # partition W1/W3 is 0.15 m: each face gets half of it; W2 (no partner) the default
    th = wall_thicknesses(fr)
    assert th["W1"] == pytest.approx(0.075) and th["W3"] == pytest.approx(0.075) and th["W2"] == pytest.approx(0.20)
    w1 = [w for w in f.by_type("IfcWall") if w.Name == "W1"][0]
    v = np.asarray(ifcopenshell.util.shape.get_vertices(ifcopenshell.geom.create_shape(s, w1).geometry)).reshape(-1, 3)
    assert v.min(0) == pytest.approx([0.0, -0.075, 0.0]) and v.max(0) == pytest.approx([5.0, 0.0, 2.7])
    # the radiator's box: footprint 0.8 x 0.6 centred on its position, standing 0.10 m into the room
    rad = f.by_type("IfcSpaceHeater")[0]
    v = np.asarray(ifcopenshell.util.shape.get_vertices(ifcopenshell.geom.create_shape(s, rad).geometry)).reshape(-1, 3)
    c, w, u, vv, _, _ = [o for o in OBJECTS if o[0] == "radiator"][0]
    centre = fr[w].to_world(u, vv)
    assert v.min(0) == pytest.approx(centre + [-0.10, -0.40, -0.30])
    assert v.max(0) == pytest.approx(centre + [0.0, 0.40, 0.30])


def test_unknown_class_becomes_a_proxy_and_bad_documents_are_refused():
    doc = detections_document()
    doc["detections"][0]["class"] = "fire_hose"
    f = export_ifc(doc, typings=bundled_typings())
    proxy = [e for e in f.by_type("IfcBuildingElementProxy") if e.Tag == "D0000"][0]
    assert proxy.ObjectType == "FIRE_HOSE"
    with pytest.raises(InputError, match=r"detections: walls\[0\]: missing key 'normal'"):
        bad = detections_document()
        del bad["walls"][0]["normal"]
        export_ifc(bad)
    with pytest.raises(InputError, match="unknown IFC schema 'IFC2'"):
        export_ifc(detections_document(), schema="IFC2")


def test_typings_come_from_the_model_library(tmp_path):
    import json

    import cv2

    from sbsc_core.bim import DEFAULT_DEPTH_M, class_typings
    from sbsc_core.types import ModelLibrary, ObjectModel

    relief = np.full((12, 12), np.nan, np.float32)
    relief[3:9, 3:9] = 0.035
    lib = ModelLibrary({"exit_sign": ObjectModel("exit_sign", "Exit sign", "IfcSign", "PICTORAL", 0.3, 0.15,
                                                 [], relief, {"object_type": "EXITSIGN"})})
    t = class_typings(lib)["exit_sign"]
    assert (t.ifc_class, t.predefined_type, t.object_type) == ("IfcSign", "PICTORAL", "EXITSIGN")
    assert t.depth_m == pytest.approx(0.035) and (t.width_m, t.height_m) == (0.3, 0.15)

    d = tmp_path / "models" / "data_socket"
    d.mkdir(parents=True)
    (d / "model.json").write_text(json.dumps({"name": "Data socket", "ifc_class": "IfcOutlet",
                                              "predefined_type": "DATAOUTLET", "width_m": 0.08, "height_m": 0.08}))
    cv2.imwrite(str(d / "colour.png"), np.full((16, 16, 3), 250, np.uint8))
    typings = class_typings(models=tmp_path / "models")
    assert typings["data_socket"].depth_m == DEFAULT_DEPTH_M
    doc = detections_document(objects=[("data_socket", "W1", 1.0, 0.3, 0.08, 0.08)])
    f = export_ifc(doc, typings=typings)
    (outlet,) = f.by_type("IfcOutlet")
    assert outlet.IsTypedBy[0].RelatingType.PredefinedType == "DATAOUTLET"
    assert outlet.IsTypedBy[0].RelatingType.Tag == "data_socket"
