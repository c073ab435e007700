"""Wall clutter, furniture, visible fractions and the survey frame of the simulator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.evaluate import evaluate
from sbsc_core.io.documents import read_truth
from sbsc_core.io.scans import read_scan
from sbsc_core.paths import sample_projects_dir
from sbsc_core.simulate.building import build_building
from sbsc_core.simulate.clutter import WALL_KINDS, Distractor
from sbsc_core.simulate.raycast import MeshRaycaster
from sbsc_core.simulate.scenarios import apply_realism, simulate_scene
from sbsc_core.simulate.scene import footprint, load_scene
from sbsc_core.simulate.survey import SurveyFrame
from sbsc_core.simulate.visibility import visible_fractions

ONE_ROOM = sample_projects_dir() / "one_room.yaml"


def _scene(**options):
    return apply_realism(load_scene(ONE_ROOM), **options)


def test_clutter_is_in_the_truth_clear_of_objects_and_openings() -> None:
    scene = _scene(clutter=True)
    scene.clutter_per_metre = 1.5
    b = build_building(scene, seed=3)
    truth = b.truth_document()
    kinds = {d["kind"] for d in truth["distractors"]}
    assert len(truth["distractors"]) >= 8 and kinds <= set(WALL_KINDS)
    for d in b.distractors:
        box = d.box()
        for p in scene.objects:
            if p.wall == d.wall:
                f = footprint(p)
                assert min(box[1], f[1]) <= max(box[0], f[0]) or min(box[3], f[3]) <= max(box[2], f[2])
    # the mesh holds them: a ray onto each distractor's centre hits a distractor (label -2)
    rc = MeshRaycaster(b.mesh)
    for d in truth["distractors"]:
        n = np.array(d["normal"])
        start = np.array(d["position"]) + 0.5 * n
        hit = rc.cast(start, -n[None, :].astype(np.float32))
        if d["kind"] not in ("coat_hooks",):
            assert hit.label[0] == -2, d["kind"]
    # none of it without the option, and the same layout for the same seed
    assert "distractors" not in build_building(_scene(), seed=3).truth_document()
    again = build_building(scene, seed=3).truth_document()["distractors"]
    assert again == truth["distractors"]


def test_look_alike_clutter_exists() -> None:
    # a thermostat and a room controller are switch-sized white boxes
    for kind in ("thermostat", "room_controller"):
        _, wr, hr, depth, _ = WALL_KINDS[kind]
        assert 0.07 <= wr[0] <= 0.1 and 0.07 <= hr[0] <= 0.13 and depth < 0.03


def test_furniture_hides_part_of_an_object() -> None:
    scene = _scene()
    b = build_building(scene)
    clear = visible_fractions(b, scene.scanner)
    assert min(clear) > 0.75
    # a desk in front of the socket_x1 on R1-N (u 0.6, v 0.3): its modesty panel hides the socket
    # from the stations, which look down at it from behind the desk
    sock = next(o for o in b.objects if o.class_id == "socket_x1")
    desk = Distractor("desk", "R1-N", 0.9, 0.37, 1.2, 0.74, 0.7, 0.02, 1)
    b2 = build_building(scene)
    from sbsc_core.simulate import mesh as M
    from sbsc_core.simulate.clutter import distractor_mesh

    b2.mesh = M.merge([b2.mesh, distractor_mesh(desk, b2.layout)])
    b2.distractors = [desk]
    hidden = visible_fractions(b2, scene.scanner)
    k = b.objects.index(sock)
    assert hidden[k] < 0.9 * clear[k]
    others = [i for i in range(len(clear)) if i != k]
    assert np.allclose(np.array(hidden)[others], np.array(clear)[others], atol=0.05)


def test_furniture_layout_keeps_doors_and_stations_free() -> None:
    scene = _scene(furniture=True)
    scene.furniture_per_metre = 1.0
    b = build_building(scene, seed=5)
    furniture = [d for d in b.distractors if d.furniture]
    assert furniture
    for d in furniture:
        for o in b.layout.openings_on(d.wall):
            if o.kind == "door":
                assert d.u + d.width_m / 2 <= o.u_min or d.u - d.width_m / 2 >= o.u_max
        fr = b.layout.walls[d.wall].frame
        centre = fr.to_world(d.u, 0.0, d.gap_m + d.depth_m / 2)[:2]
        assert np.min(np.linalg.norm(b.stations[:, :2] - centre, axis=1)) > 0.5


@pytest.mark.slow
def test_survey_frame_moves_scan_and_truth_alike(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    simulate_scene(ONE_ROOM, out, seed=2, angular_step_deg=0.8, design=False, survey_frame=True, clutter=True)
    truth = json.loads((out / "ground_truth.json").read_text())
    assert truth["survey_frame"]["offset"] == [412000.0, 5612000.0, 100.0]
    cloud = read_scan(out / "scan.ply")
    xyz = np.asarray(cloud.xyz, np.float64) + np.asarray(cloud.origin, np.float64)
    assert xyz[:, 0].min() > 411_990 and xyz[:, 1].min() > 5_611_990
    # every wall of the truth has scan points on its plane, inside its extent
    for w in truth["walls"]:
        o, n, au = (np.array(w[k]) for k in ("origin", "normal", "axis_u"))
        d = (xyz - o) @ n
        u = (xyz - o) @ au
        on = (np.abs(d) < 0.01) & (u > 0.2) & (u < w["width_m"] - 0.2)
        assert on.sum() > 50, w["id"]
    # objects and distractors turned like the walls: normals are the walls' normals
    walls = {w["id"]: w for w in truth["walls"]}
    for item in truth["objects"] + truth["distractors"]:
        assert np.allclose(item["normal"], walls[item["wall"]]["normal"], atol=1e-5)
    frame = SurveyFrame()
    local = load_scene(ONE_ROOM)
    first = build_building(local).objects[0]
    assert np.allclose(truth["objects"][0]["position"], frame.points(first.position[None])[0], atol=1e-4)
    assert "visible_fraction" in truth["objects"][0] and "registration_errors" not in truth


def test_evaluator_counts_false_positives_on_distractors(tmp_path: Path) -> None:
    truth_doc = {"schema": "sbsc.truth/1",
                 "objects": [{"class": "switch", "position": [0.0, 0.0, 1.1], "normal": [0, -1, 0],
                              "width_m": 0.08, "height_m": 0.08}],
                 "distractors": [
                     {"kind": "thermostat", "furniture": False, "centre": [1.0, 0.0125, 1.5],
                      "axis_u": [1, 0, 0], "axis_v": [0, 0, 1], "normal": [0, 1, 0], "size_m": [0.08, 0.1, 0.025]},
                     {"kind": "clock", "furniture": False, "centre": [3.0, 0.02, 2.0],
                      "axis_u": [1, 0, 0], "axis_v": [0, 0, 1], "normal": [0, 1, 0], "size_m": [0.3, 0.3, 0.04]},
                     {"kind": "desk", "furniture": True, "centre": [5.0, 0.4, 0.37],
                      "axis_u": [1, 0, 0], "axis_v": [0, 0, 1], "normal": [0, 1, 0], "size_m": [1.2, 0.74, 0.7]}]}
    dets = {"detections": [
        {"id": "d1", "class": "switch", "position": [0.0, 0.0, 1.1], "alpha": 1.0},
        {"id": "d2", "class": "switch", "position": [1.01, 0.0, 1.49], "alpha": 0.8},  # on the thermostat
        {"id": "d3", "class": "socket_x1", "position": [5.2, 0.74, 0.5], "alpha": 0.7},  # on the desk front
        {"id": "d4", "class": "socket_x1", "position": [8.0, 0.0, 0.3], "alpha": 0.7}]}  # on bare wall
    def truth(doc: dict):
        (tmp_path / "t.json").write_text(json.dumps(doc))
        return read_truth(tmp_path / "t.json")

    table = evaluate(dets, truth(truth_doc))
    f = table.distractors
    assert table.total.tp == 1 and table.total.fp == 3
    assert f.fp_on_distractors == 2 and f.clutter == 2 and f.clutter_with_fp == 1 and f.furniture_with_fp == 1
    assert f.clutter_with_fp_pct == pytest.approx(50.0)
    assert table.to_dict()["distractors"]["fp_by_kind"] == {"thermostat": 1, "desk": 1}
    plain = dict(truth_doc)
    del plain["distractors"]
    assert evaluate(dets, truth(plain)).distractors is None


def test_cli_realism_options(monkeypatch, tmp_path: Path) -> None:
    from sbsc_core import cli
    from sbsc_core.simulate import scenarios

    calls = []
    monkeypatch.setattr(scenarios, "simulate_scenario", lambda *a, **kw: calls.append(kw))
    assert cli.main(["-q", "simulate", "--scenario", "I", "--out", str(tmp_path / "a")]) == 0
    assert cli.main(["-q", "simulate", "--scenario", "I", "--out", str(tmp_path / "b"), "--clutter",
                     "--survey-frame", "--designs", "third"]) == 0
    assert cli.main(["-q", "simulate", "--scenario", "I", "--out", str(tmp_path / "c"), "--all-realism"]) == 0
    keys = ("realistic", "clutter", "furniture", "survey_frame")
    assert [calls[0][k] for k in keys] == [False] * 4
    assert [calls[1][k] for k in keys] == [False, True, False, True]
    assert [calls[2][k] for k in keys] == [True] * 4


def test_description_keys_and_their_errors(tmp_path: Path) -> None:
    from sbsc_core.errors import InputError

    text = ONE_ROOM.read_text()
    good = tmp_path / "g.yaml"
    good.write_text(text + "realism: {range_noise_10m_m: 0.002}\nclutter: {per_metre: 0.8}\n"
                    "survey_frame: {offset: [500000, 4400000, 650], rotation_deg: -12}\n")
    scene = load_scene(good)
    assert scene.effects.range_noise_10m_m == 0.002 and scene.effects.beam_divergence_rad == 0.0003
    assert scene.clutter_per_metre == 0.8 and scene.furniture_per_metre == 0.0
    assert scene.survey_frame.rotation_deg == -12
    assert not load_scene(ONE_ROOM).realistic
    bad = tmp_path / "b.yaml"
    for extra, field in (("realism: {laser_colour: 1}\n", "realism.laser_colour"),
                         ("clutter: {per_metre: -1}\n", "clutter.per_metre"),
                         ("survey_frame: {offset: [1, 2]}\n", "survey_frame.offset")):
        bad.write_text(text + extra)
        with pytest.raises(InputError, match=field.replace(".", r"\.")):
            load_scene(bad)
