"""Georeferenced IFC: local coordinates near the origin, IfcMapConversion + IfcProjectedCRS
from the scan's CRS (LAS WKT / GeoTIFF keys, E57 coordinateMetadata) or ``--crs``; IFC2X3."""

from __future__ import annotations

import json
import math
import uuid
from pathlib import Path

import ifcopenshell
import ifcopenshell.util.element
import ifcopenshell.util.placement
import ifcopenshell.validate
import numpy as np
import pytest

from sbsc_core.bim.export import export_ifc
from sbsc_core.cli import main
from sbsc_core.errors import InputError
from sbsc_core.io.crs import CRS, e57_crs, las_crs, parse_crs, scan_crs
from tests.bim_fixtures import UTM, _turned, detections_document, map_conversion, world_positions

WKT_25832 = ('PROJCS["ETRS89 / UTM zone 32N",GEOGCS["ETRS89",DATUM["European_Terrestrial_Reference_System_1989",'
             'SPHEROID["GRS 1980",6378137,298.257222101,AUTHORITY["EPSG","7019"]],AUTHORITY["EPSG","6258"]],'
             'PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433],AUTHORITY["EPSG","4258"]],'
             'PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_origin",0],'
             'PARAMETER["central_meridian",9],PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],'
             'PARAMETER["false_northing",0],UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["Easting",EAST],'
             'AXIS["Northing",NORTH],AUTHORITY["EPSG","25832"]]')








@pytest.mark.parametrize("schema", ["IFC4", "IFC4X3", "IFC2X3"])
def test_turned_scan_at_utm_comes_back_within_a_millimetre(schema) -> None:
    doc = _turned(detections_document(), 31.7, UTM)
    model = export_ifc(doc, schema=schema, crs="EPSG:25832")
    assert model.schema == ("IFC4X3" if schema == "IFC4X3" else schema) or model.schema.startswith(schema)
    name, enh, _, _ = map_conversion(model)
    assert name == "EPSG:25832"
    world, largest = world_positions(model)
    assert largest < 1000.0 and np.abs(enh[:2] - UTM[:2]).max() < 100  # near the building
    expected = {d["id"]: np.asarray(d["position"]) for d in doc["detections"]}
    assert set(world) == set(expected)
    err = max(float(np.linalg.norm(world[k] - expected[k])) for k in expected)
    assert err < 1e-3, err
    # the local frame follows the building: the walls are axis-aligned in the model
    for w in model.by_type("IfcWall"):
        x_axis = ifcopenshell.util.placement.get_local_placement(w.ObjectPlacement)[:3, 0]
        assert min(abs(x_axis[0]), abs(x_axis[1])) < 1e-9
    log = ifcopenshell.validate.json_logger()
    ifcopenshell.validate.validate(model, log)
    assert log.statements == []


def test_ifcopenshell_reads_the_same_map_positions() -> None:
    import ifcopenshell.util.geolocation as geo

    doc = _turned(detections_document(), -12.0, UTM)
    model = export_ifc(doc, crs="EPSG:25832")
    for e in model.by_type("IfcElement"):
        if (e.Tag or "").startswith("D"):
            p = ifcopenshell.util.placement.get_local_placement(e.ObjectPlacement)[:3, 3]
            want = next(d["position"] for d in doc["detections"] if d["id"] == e.Tag)
            assert np.allclose(geo.auto_xyz2enh(model, *p), want, atol=1e-3)


def test_local_model_without_crs_is_not_georeferenced_and_unchanged() -> None:
    doc = detections_document()
    model = export_ifc(doc)
    assert not model.by_type("IfcMapConversion") and not model.by_type("IfcProjectedCRS")
    p = ifcopenshell.util.placement.get_local_placement(
        next(e for e in model.by_type("IfcElement") if e.Tag == doc["detections"][0]["id"]).ObjectPlacement)
    assert np.allclose(p[:3, 3], doc["detections"][0]["position"])


def test_far_coordinates_without_crs_are_still_moved_near_the_origin() -> None:
    doc = _turned(detections_document(), 10.0, UTM)
    model = export_ifc(doc)
    name, _, _, _ = map_conversion(model)
    assert name == "unknown"
    world, largest = world_positions(model)
    assert largest < 1000.0
    assert all(np.linalg.norm(world[d["id"]] - d["position"]) < 1e-3 for d in doc["detections"])


def test_crs_of_the_document_is_used_and_the_option_overrides_it(tmp_path, capsys) -> None:
    doc = _turned(detections_document(), 5.0, UTM)
    doc["crs"] = {"name": "EPSG:25832", "epsg": 25832}
    det = tmp_path / "detections.json"
    det.write_text(json.dumps(doc))
    assert main(["-q", "export-ifc", str(det), "--out", str(tmp_path / "a.ifc")]) == 0
    assert map_conversion(ifcopenshell.open(str(tmp_path / "a.ifc")))[0] == "EPSG:25832"
    assert main(["-q", "export-ifc", str(det), "--out", str(tmp_path / "b.ifc"), "--crs", "EPSG:3044",
                 "--schema", "IFC2X3"]) == 0
    model = ifcopenshell.open(str(tmp_path / "b.ifc"))
    assert model.schema == "IFC2X3" and map_conversion(model)[0] == "EPSG:3044"
    assert main(["export-ifc", str(det), "--out", str(tmp_path / "c.ifc"), "--crs", "UTM32"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--crs" in err and not (tmp_path / "c.ifc").exists()


# --------------------------------------------------------------------------- reading the CRS


def test_parse_crs_forms() -> None:
    assert parse_crs("EPSG:25832") == CRS("EPSG:25832", 25832)
    assert parse_crs("urn:ogc:def:crs:EPSG::3044").epsg == 3044
    wkt = parse_crs(WKT_25832)
    assert wkt.name == "EPSG:25832" and wkt.epsg == 25832 and wkt.projected and wkt.wkt == WKT_25832
    geog = parse_crs('GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],'
                     'AUTHORITY["EPSG","4326"]]')
    assert geog.epsg == 4326 and not geog.projected
    with pytest.raises(InputError, match="--crs"):
        parse_crs("zone 32")


def _write_las(path: Path, xyz: np.ndarray, rgb: np.ndarray, vlr) -> None:
    import laspy

    header = laspy.LasHeader(point_format=7, version="1.4")
    header.offsets = xyz.min(axis=0)
    header.scales = [0.0005, 0.0005, 0.0005]
    header.vlrs.append(vlr)
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.red, las.green, las.blue = (rgb.astype(np.uint16) * 257).T
    las.write(path)


def test_las_wkt_and_geotiff_keys(tmp_path) -> None:
    from laspy.vlrs.known import GeoKeyDirectoryVlr, GeoKeyEntryStruct, WktCoordinateSystemVlr

    xyz = np.random.default_rng(0).uniform(0, 5, (100, 3)) + UTM
    rgb = np.full((100, 3), 128, np.uint8)
    _write_las(tmp_path / "wkt.las", xyz, rgb, WktCoordinateSystemVlr(WKT_25832))
    assert las_crs(tmp_path / "wkt.las").name == "EPSG:25832"
    keys = GeoKeyDirectoryVlr()
    keys.geo_keys_header.key_directory_version, keys.geo_keys_header.number_of_keys = 1, 2
    projected, vertical = GeoKeyEntryStruct(), GeoKeyEntryStruct()
    projected.id, projected.tiff_tag_location, projected.count, projected.value_offset = 3072, 0, 1, 25833
    vertical.id, vertical.tiff_tag_location, vertical.count, vertical.value_offset = 4096, 0, 1, 7837
    keys.geo_keys = [projected, vertical]
    _write_las(tmp_path / "keys.las", xyz, rgb, keys)
    crs = las_crs(tmp_path / "keys.las")
    assert crs.name == "EPSG:25833" and crs.vertical_epsg == 7837
    with pytest.raises(InputError, match="differs"):
        scan_crs([tmp_path / "wkt.las", tmp_path / "keys.las"])


def _write_e57(path: Path, xyz: np.ndarray, rgb: np.ndarray, metadata: str) -> None:
    import pye57
    from pye57 import libe57

    class E57WithCRS(pye57.E57):
        def write_default_header(self) -> None:
            imf = self.image_file
            imf.extensionsAdd("", libe57.E57_V1_0_URI)
            self.root.set("formatName", libe57.StringNode(imf, "ASTM E57 3D Imaging Data File"))
            self.root.set("guid", libe57.StringNode(imf, f"{{{uuid.uuid4()}}}"))
            self.root.set("versionMajor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MAJOR))
            self.root.set("versionMinor", libe57.IntegerNode(imf, libe57.E57_FORMAT_MINOR))
            self.root.set("coordinateMetadata", libe57.StringNode(imf, metadata))
            self.root.set("data3D", libe57.VectorNode(imf, True))
            self.root.set("images2D", libe57.VectorNode(imf, True))

    with E57WithCRS(str(path), mode="w") as e:
        e.write_scan_raw({"cartesianX": xyz[:, 0], "cartesianY": xyz[:, 1], "cartesianZ": xyz[:, 2],
                          "colorRed": rgb[:, 0], "colorGreen": rgb[:, 1], "colorBlue": rgb[:, 2]})


def test_e57_coordinate_metadata(tmp_path) -> None:
    xyz = np.random.default_rng(1).uniform(0, 5, (50, 3)) + UTM
    rgb = np.full((50, 3), 90, np.uint8)
    _write_e57(tmp_path / "crs.e57", xyz, rgb, WKT_25832)
    assert e57_crs(tmp_path / "crs.e57").name == "EPSG:25832"
    _write_e57(tmp_path / "none.e57", xyz, rgb, "")
    assert e57_crs(tmp_path / "none.e57") is None and scan_crs([tmp_path / "none.e57"]) is None


@pytest.mark.slow
def test_detect_records_the_scan_crs_and_export_puts_every_object_back(tmp_path) -> None:
    """A simulated room turned in plan, at UTM coordinates, as LAS with a WKT: detect writes
    ``crs`` and ``origin``; the IFC's map conversion brings every object back within 1 mm."""
    from sbsc_core.io.scans import read_scan

    sim = tmp_path / "sim"
    assert main(["-q", "simulate", "--scene", "one_room", "--out", str(sim), "--step", "0.3", "--seed", "3"]) == 0
    cloud = read_scan(sim / "scan.ply")
    a = math.radians(23.0)
    r = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    from laspy.vlrs.known import WktCoordinateSystemVlr

    _write_las(tmp_path / "scan.las", cloud.world() @ r.T + UTM, cloud.rgb, WktCoordinateSystemVlr(WKT_25832))
    det = tmp_path / "det"
    assert main(["-q", "detect", str(tmp_path / "scan.las"), "--models", str(sim / "models"),
                 "--expected", str(sim / "expected.json"), "--out", str(det)]) == 0
    doc = json.loads((det / "detections.json").read_text())
    assert doc["crs"]["name"] == "EPSG:25832" and doc["crs"]["wkt"] == WKT_25832
    assert np.linalg.norm(np.asarray(doc["origin"][:2]) - UTM[:2]) < 20
    assert len(doc["detections"]) >= 5  # recognition is tested elsewhere; here: where they go
    assert main(["-q", "export-ifc", str(det / "detections.json"), "--out", str(tmp_path / "as_is.ifc")]) == 0
    model = ifcopenshell.open(str(tmp_path / "as_is.ifc"))
    assert map_conversion(model)[0] == "EPSG:25832"
    world, largest = world_positions(model)
    assert largest < 1000.0
    err = max(float(np.linalg.norm(world[d["id"]] - np.asarray(d["position"]))) for d in doc["detections"])
    assert err < 1e-3, err
