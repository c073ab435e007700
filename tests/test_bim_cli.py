"""``sbsc export-ifc`` and ``sbsc compare``: success and one-line errors with nothing written."""

from __future__ import annotations

import json

import ifcopenshell
import pytest

from sbsc_core.bim import bundled_typings
from sbsc_core.bim.design_writer import write_as_designed_ifc
from sbsc_core.cli import main
from tests.bim_fixtures import detections_document, truth_document


@pytest.fixture
def detections(tmp_path):
    p = tmp_path / "detections.json"
    p.write_text(json.dumps(detections_document(statuses={1: "pending"})))
    return p


def _one_line_error(capsys, code: int, *names: str) -> str:
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err.startswith("sbsc: error: ") and "\n" not in err, err
    for name in names:
        assert name in err, err
    return err


def test_export_ifc_command(tmp_path, detections):
    out = tmp_path / "out" / "model.ifc"
    out.parent.mkdir()
    assert main(["-q", "export-ifc", str(detections), "--out", str(out), "--schema", "IFC4X3",
                 "--accepted-only"]) == 0
    f = ifcopenshell.open(str(out))
    assert f.schema_identifier.startswith("IFC4X3")
    tags = sorted(e.Tag for e in f.by_type("IfcElement") if (e.Tag or "").startswith("D"))
    assert "D0001" not in tags and len(tags) == 7  # the pending one left out
    assert [p.name for p in out.parent.iterdir()] == ["model.ifc"]  # no temporary left


@pytest.mark.parametrize("case", ["missing", "bad_json", "bad_doc", "bad_schema", "bad_models"])
def test_export_ifc_errors(tmp_path, detections, capsys, case):
    out = tmp_path / "model.ifc"
    args = ["export-ifc", str(detections), "--out", str(out)]
    names = [str(detections)]
    if case == "missing":
        args[1] = str(tmp_path / "nope.json")
        names = ["nope.json", "no such file"]
    elif case == "bad_json":
        detections.write_text('{"walls": [')
        names.append("invalid JSON")
    elif case == "bad_doc":
        doc = detections_document()
        doc["detections"][2]["review"] = {"status": "maybe"}
        detections.write_text(json.dumps(doc))
        names.append("detections[2].review.status")
    elif case == "bad_schema":
        args += ["--schema", "IFC5"]
        names = ["--schema", "IFC5"]
    else:
        args += ["--models", str(tmp_path / "no_models")]
        names = ["no_models", "no such directory"]
    _one_line_error(capsys, main(args), *names)
    assert not out.exists() and list(tmp_path.glob("*.ifc")) == []


def test_compare_command(tmp_path, detections):
    design = tmp_path / "design.ifc"
    write_as_designed_ifc(truth_document(), design, seed=2, n_moved=1, n_removed=1, n_added=1,
                          typings=bundled_typings())
    out = tmp_path / "cmp"
    assert main(["-q", "compare", "--as-designed", str(design), "--detections", str(detections),
                 "--out", str(out), "--tolerance", "0.05"]) == 0
    data = json.loads((out / "comparison.json").read_text())
    assert data["tolerance_m"] == 0.05
    assert data["summary"]["displaced"] == 1 and data["summary"]["missing"] == 1
    assert data["summary"]["unexpected"] == 1
    assert (out / "findings.bcf").stat().st_size > 0 and (out / "report.html").stat().st_size > 0


@pytest.mark.parametrize("case", ["text", "truncated", "no_storey", "ifc9", "tolerance"])
def test_compare_errors(tmp_path, detections, capsys, case):
    design = tmp_path / "design.ifc"
    write_as_designed_ifc(truth_document(), design, n_moved=0, n_removed=0, n_added=0,
                          typings=bundled_typings())
    text = design.read_text()
    extra = []
    reason = ""
    if case == "text":
        design.write_text("<html>not a model</html>")
        reason = "not an IFC file"
    elif case == "truncated":
        design.write_text(text[: len(text) * 2 // 3])
        reason = "malformed IFC file"
    elif case == "no_storey":
        f = ifcopenshell.open(str(design))
        for s in f.by_type("IfcBuildingStorey"):
            for rel in list(s.ContainsElements) + list(s.Decomposes):
                f.remove(rel)
            f.remove(s)
        f.write(str(design))
        reason = "no IfcBuildingStorey"
    elif case == "ifc9":
        design.write_text(text.replace("FILE_SCHEMA(('IFC4'))", "FILE_SCHEMA(('IFC9'))"))
        reason = "unsupported IFC schema"
    else:
        extra = ["--tolerance", "-1"]
        reason = "--tolerance"
    out = tmp_path / "cmp"
    try:
        code = main(["compare", "--as-designed", str(design), "--detections", str(detections), "--out", str(out),
                     *extra])
    except SystemExit as exc:  # a usage error (--tolerance -1) exits through argparse (issue 30)
        code = exc.code
    _one_line_error(capsys, code, reason, *([] if case == "tolerance" else [str(design)]))
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["design.ifc", "detections.json"]
