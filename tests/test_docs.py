"""The documentation: the README for users, the MkDocs site, the JSON Schemas of the formats."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import pytest

from sbsc_core.io.schemas import json_schemas, schema_text

from .app_support import ROOT, _fake_output, served_fake_sample


def test_readme_is_short_and_refers_only_to_files_of_the_repository() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    assert "bash scripts/demo.sh" in text and "bash scripts/test.sh" in text  # the two commands
    assert "/work/" not in text and "CONTRACTS.md" not in text
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not target.startswith(("http://", "https://")):
            assert (ROOT / target).exists(), f"README links to {target}, which is not in the repository"
    assert re.search(r"!\[[^]]*\]\(docs/images/[^)]+\.png\)", text)  # a screenshot


def test_mkdocs_builds_strict(tmp_path) -> None:
    pytest.importorskip("mkdocs", reason="mkdocs is in the test extras: pip install -e '.[test]'")
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert (tmp_path / "site" / "formats" / "index.html").is_file()
    api = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")  # mkdocstrings' numpydoc
    assert "detect_to_dir" in api and "register_reader" in api and api.count("Parameters") >= 15
    shutil.rmtree(tmp_path / "site")


def test_committed_schemas_are_what_the_code_generates() -> None:
    for name, schema in json_schemas().items():
        path = ROOT / "docs" / "schemas" / f"{name}.schema.json"
        assert path.read_text(encoding="utf-8") == schema_text(schema), \
            f"{path} is stale: python -m sbsc_core.io.schemas docs/schemas"


def _validator(name: str):  # noqa: ANN202
    jsonschema = pytest.importorskip("jsonschema", reason="jsonschema is in the test extras")
    schema = json.loads((ROOT / "docs" / "schemas" / f"{name}.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_the_review_apps_documents_follow_the_schema(tmp_path) -> None:
    v = _validator("detections")
    served = served_fake_sample(tmp_path, 200)  # GET /api/projects/{pid}/detections, as the app makes it
    assert served["detections"] and list(v.iter_errors(served)) == []
    _fake_output(tmp_path / "raw", 3, lambda s, f: None, 0.0)
    raw = json.loads((tmp_path / "raw" / "detections.json").read_text())
    assert list(v.iter_errors(raw)) == []
    broken = {**served, "walls": [{"id": "W1"}]}  # the schema does catch a wall without its frame
    assert {e.validator for e in v.iter_errors(broken)} == {"required"}
    bad = {**served, "detections": [{**served["detections"][0], "alpha": "high"}]}
    assert any(e.validator == "anyOf" for e in v.iter_errors(bad))


@pytest.mark.slow
def test_sbsc_detect_output_follows_the_schema(tmp_path) -> None:
    """The real pipeline on the bundled one-room scene."""
    from sbsc_core.pipeline.detect import detect_to_dir

    from .app_support import simulate_one_room

    sim = simulate_one_room(tmp_path / "sim", step_deg=0.5)
    detect_to_dir([sim / "scan.ply"], sim / "models", expected=sim / "expected.json", out=tmp_path / "out")
    doc = json.loads((tmp_path / "out" / "detections.json").read_text())
    assert doc["detections"] and list(_validator("detections").iter_errors(doc)) == []
