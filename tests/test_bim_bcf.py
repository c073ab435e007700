"""The BCF of ``sbsc compare`` against buildingSMART's BCF 2.1 XSDs (lxml), every kind of finding."""

from __future__ import annotations

import json
import zipfile

import pytest
from lxml import etree

from sbsc_core.bim import bundled_typings
from sbsc_core.bim.design_writer import write_as_designed_ifc
from sbsc_core.cli import main
from tests.bim_fixtures import SCHEMAS, bcf_errors, detections_document, truth_document
from tests.shared_data import shared_data

# the schema of each kind of file in a BCF 2.1 zip


@pytest.fixture(scope="module")
def xsd() -> dict[str, etree.XMLSchema]:
    folder = shared_data("bcf-xsd-2.1")
    return {name: etree.XMLSchema(etree.parse(str(folder / name))) for name in set(SCHEMAS.values())}






@pytest.mark.parametrize("with_images", [False, True])
def test_bcf_of_every_kind_of_finding_is_valid_bcf_2_1(tmp_path, xsd, with_images) -> None:
    det = tmp_path / "detect" / "detections.json"
    det.parent.mkdir()
    det.write_text(json.dumps(detections_document(noise_m=0.002, seed=3)))
    if with_images:
        import cv2
        import numpy as np

        (det.parent / "orthoimages").mkdir()
        for wall in json.loads(det.read_text())["walls"]:
            cv2.imwrite(str(det.parent / "orthoimages" / f"{wall['id']}_colour.png"),
                        np.full((300, 600, 3), 200, np.uint8))
    design = tmp_path / "design.ifc"
    write_as_designed_ifc(truth_document(), design, seed=2, n_moved=2, n_removed=2, n_added=2,
                          typings=bundled_typings())
    out = tmp_path / "cmp"
    assert main(["-q", "compare", "--as-designed", str(design), "--detections", str(det), "--out", str(out)]) == 0
    summary = json.loads((out / "comparison.json").read_text())["summary"]
    assert summary["displaced"] >= 1 and summary["missing"] >= 1 and summary["unexpected"] >= 1, summary
    errors, checked = bcf_errors(out / "findings.bcf", xsd)
    assert errors == []
    n_findings = summary["displaced"] + summary["missing"] + summary["unexpected"]
    assert checked["markup.xsd"] == n_findings and checked["visinfo.xsd"] == n_findings
    assert checked["version.xsd"] == 1 and checked.get("project.xsd", 0) <= 1


def test_the_check_finds_an_invalid_viewpoint(tmp_path, xsd) -> None:
    """The validator itself: an empty <Selection> (the old 'unexpected' viewpoint) is an error."""
    bad = tmp_path / "bad.bcf"
    with zipfile.ZipFile(bad, "w") as z:
        z.writestr("bcf.version", '<?xml version="1.0"?><Version VersionId="2.1"><DetailedVersion>2.1'
                                  "</DetailedVersion></Version>")
        z.writestr("t/viewpoint.bcfv", '<?xml version="1.0"?><VisualizationInfo Guid="'
                   '0b6e5c1e-1111-4222-8333-444455556666"><Components><Selection/>'
                   '<Visibility DefaultVisibility="true"/></Components></VisualizationInfo>')
    errors, _ = bcf_errors(bad, xsd)
    assert len(errors) == 1 and "Selection" in errors[0] and "Component" in errors[0]
