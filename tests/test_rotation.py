"""Any in-plane rotation: turned objects in the simulator's scenes, found and reported
with their turn (issue 13, item 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from sbsc_core import cli
from sbsc_core.evaluate import evaluate
from sbsc_core.io.documents import read_detections, read_truth
from sbsc_core.paths import sample_projects_dir
from sbsc_core.simulate import scenarios
from sbsc_core.simulate.scene import UNROTATABLE, load_scene


def _scene(tmp_path: Path, **extra) -> Path:
    data = yaml.safe_load((sample_projects_dir() / "one_room.yaml").read_text())
    data.update(extra)
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_object_rotation_turns_a_seeded_share_of_rotatable_objects(tmp_path: Path) -> None:
    a = load_scene(_scene(tmp_path, object_rotation={"fraction": 0.34, "seed": 5})).objects
    b = load_scene(_scene(tmp_path, object_rotation={"fraction": 0.34, "seed": 5})).objects
    c = load_scene(_scene(tmp_path, object_rotation={"fraction": 0.34, "seed": 6})).objects
    assert a == b and a != c
    turned = [o for o in a if o.rotation_deg]
    assert 1 <= len(turned) <= 4 and not any(o.class_id in UNROTATABLE for o in turned)
    assert all(abs(o.rotation_deg - 90 * round(o.rotation_deg / 90)) >= 5 for o in turned)
    everything = load_scene(_scene(tmp_path, object_rotation={"fraction": 1.0, "seed": 1})).objects
    # the exit light above the door cannot turn without touching the casing: it stays upright
    assert next(o for o in everything if o.class_id == "exit_light").rotation_deg == 0.0


def test_rotation_deg_per_object(tmp_path: Path) -> None:
    data = yaml.safe_load((sample_projects_dir() / "one_room.yaml").read_text())
    data["objects"][0]["rotation_deg"] = 30.0
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(data))
    assert load_scene(path).objects[0].rotation_deg == 30.0


@pytest.fixture(scope="module")
def turned_room(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("turned")
    scene = _scene(root, object_rotation={"fraction": 0.34, "seed": 1})
    scan = root / "scan"
    scenarios.simulate_scene(scene, scan, seed=1, angular_step_deg=0.12, design=False)
    out = root / "detect"
    assert cli.main(["-q", "detect", str(scan / "scan.ply"), "--models", str(scan / "models"),
                     "--out", str(out)]) == 0
    return scan, out


@pytest.mark.slow
def test_turned_objects_are_found_with_their_turn(turned_room) -> None:
    scan, out = turned_room
    doc = read_detections(out / "detections.json")
    dets = doc["detections"]
    result = evaluate(doc, read_truth(scan / "ground_truth.json"))
    objects = json.loads((scan / "ground_truth.json").read_text())["objects"]
    assert result.total.tp == len(objects) and result.total.fp == 0
    turned = [o for o in objects if o["rotation_deg"]]
    assert len(turned) == 3
    for o in turned:
        d = min((d for d in dets if d["class"] == o["class"]),
                key=lambda d: np.linalg.norm(np.subtract(d["position"], o["position"])))
        assert np.linalg.norm(np.subtract(d["position"], o["position"])) < 0.006
        err = (d["rotation_deg"] - o["rotation_deg"]) % 90.0  # square reliefs: modulo a quarter turn
        assert min(err, 90.0 - err) <= 3.0, (o["class"], o["rotation_deg"], d["rotation_deg"])
