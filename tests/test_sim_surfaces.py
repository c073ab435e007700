"""The simulator's objects beyond walls (issue 11): ceilings and free-standing columns."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest
import yaml

from sbsc_core.errors import InputError
from sbsc_core.paths import sample_projects_dir
from sbsc_core.simulate.building import build_building
from sbsc_core.simulate.scanner import ScannerSettings, scan_mesh
from sbsc_core.simulate.scenarios import simulate_scene
from sbsc_core.simulate.scene import load_scene, parse_scene, point_in_outline

ONE_ROOM = sample_projects_dir() / "one_room.yaml"


def _hall(**options) -> dict:
    """An 8 m x 7 m hall with a door: big enough for a column."""
    return {"schema": "sbsc.scene/1", "name": "hall", "ceiling_height_m": 2.8,
            "rooms": [{"id": "H", "rect": [0, 0, 8, 7]}],
            "openings": [{"wall": "H-S", "kind": "door", "u": 2.0, "width_m": 0.9, "height_m": 2.1}],
            "objects": [{"class": "switch", "wall": "H-S", "u": 3.0, "v": 1.1}], **options}


def test_options_off_change_nothing():
    scene = load_scene(ONE_ROOM)
    truth = build_building(scene).truth_document()
    assert "surfaces" not in truth and "columns" not in truth
    assert all("surface" not in o for o in truth["objects"])


def test_ceiling_objects_and_columns_in_the_truth():
    b = build_building(parse_scene(_hall(ceiling_objects=True, columns=True), "hall.yaml"))
    truth = b.truth_document()
    kinds = Counter(o["surface"] for o in truth["objects"])
    assert kinds["wall"] == 1 and kinds["ceiling"] >= 2 and kinds["column"] == 6
    by_class = Counter((o["surface"], o["class"]) for o in truth["objects"])
    assert by_class["ceiling", "smoke_detector"] >= 1 and by_class["ceiling", "exit_light"] == 1
    surfaces = {s["id"]: s for s in truth["surfaces"]}
    ceiling = surfaces["H-C"]
    assert ceiling["kind"] == "ceiling" and ceiling["normal"] == [0.0, 0.0, -1.0]
    assert ceiling["axis_v"][2] == 0.0 and np.isclose(np.cross(ceiling["axis_u"], ceiling["axis_v"]) @ ceiling["normal"], 1)
    (col,) = truth["columns"]
    assert col["shape"] == "rect" and col["faces"] == ["H-COL1-N", "H-COL1-E", "H-COL1-S", "H-COL1-W"]
    stations = np.asarray(truth["stations"])[:, :2]
    assert np.min(np.linalg.norm(stations - col["centre"], axis=1)) >= 1.0
    for o in truth["objects"]:
        s = surfaces.get(o["wall"])
        if o["surface"] == "ceiling":
            assert o["position"][2] == 2.8 and o["normal"] == [0.0, 0.0, -1.0]
            assert point_in_outline(np.array([o["position"][:2]]), ((0, 0), (8, 0), (8, 7), (0, 7)))[0]
            # u, v are the ceiling frame's coordinates of the position
            p = np.add(s["origin"], np.multiply(o["u"], s["axis_u"]) + np.multiply(o["v"], s["axis_v"]))
            assert np.allclose(p, o["position"], atol=1e-4)
        elif o["surface"] == "column":
            assert s["column"] == col["id"] and o["normal"] == s["normal"]
            # on the face: half the column's side from its centre, along the face normal
            off = np.subtract(o["position"][:2], col["centre"]) @ np.asarray(s["normal"][:2])
            assert off == pytest.approx(col["size_m"][0] / 2, abs=1e-4)
    # the objects are in the mesh with their own labels: a ray up through a ceiling object meets it
    from sbsc_core.simulate.raycast import MeshRaycaster

    rc = MeshRaycaster(b.mesh)
    for o in b.objects:
        if o.surface == "ceiling":
            hit = rc.cast(np.array([o.position - [0, 0, 1.0]]), np.array([[0.0, 0.0, 1.0]]))
            assert hit.label[0] == o.index and hit.t[0] < 1.0


def test_round_column_objects_touch_the_column():
    data = _hall(columns=True)
    data["rooms"].append({"id": "K", "rect": [8.15, 0, 16, 7]})
    b = build_building(parse_scene(data, "hall.yaml"))
    truth = b.truth_document()
    shapes = {c["id"]: c for c in truth["columns"]}
    assert [c["shape"] for c in shapes.values()] == ["rect", "round"]
    rnd = shapes["K-COL2"]
    surf = next(s for s in truth["surfaces"] if s["id"] == "K-COL2")
    assert surf["radius_m"] == pytest.approx(rnd["diameter_m"] / 2)
    on = [o for o in truth["objects"] if o["wall"] == "K-COL2"]
    assert [o["class"] for o in on] == ["fire_extinguisher", "fire_alarm_switch", "socket_x1"]
    for o in on:
        radial = np.subtract(o["position"][:2], rnd["centre"])
        assert np.linalg.norm(radial) == pytest.approx(surf["radius_m"], abs=1e-4)
        assert np.allclose(radial / np.linalg.norm(radial), o["normal"][:2], atol=1e-4)
        # u is the arc length counter-clockwise from +x
        assert o["u"] == pytest.approx(np.arctan2(radial[1], radial[0]) % (2 * np.pi) * surf["radius_m"], abs=1e-4)


def test_the_scanner_sees_ceiling_and_column_objects():
    b = build_building(parse_scene(_hall(ceiling_objects=True, columns=True), "hall.yaml"))
    scan = scan_mesh(b.mesh, b.stations, ScannerSettings(angular_step_deg=0.4), keep_labels=True)
    seen = Counter(int(x) for x in scan.label if x >= 0)
    for o in b.objects:
        assert seen[o.index] >= 3, (o.class_id, o.wall)


def test_description_keys_and_errors(tmp_path):
    scene = parse_scene(_hall(ceiling_objects=True), "hall.yaml")
    assert scene.ceiling_objects and not scene.columns
    with pytest.raises(InputError, match=r"^hall.yaml: columns: expected true or false"):
        parse_scene(_hall(columns="yes"), "hall.yaml")


@pytest.mark.slow
def test_simulate_scene_writes_the_surfaces(tmp_path):
    path = tmp_path / "hall.yaml"
    path.write_text(yaml.safe_dump(_hall(scanner={"angular_step_deg": 0.5})))
    simulate_scene(path, tmp_path / "out", ceiling_objects=True, columns=True, design=False)
    truth = json.loads((tmp_path / "out" / "ground_truth.json").read_text())
    assert {o["surface"] for o in truth["objects"]} == {"wall", "ceiling", "column"}
    assert truth["columns"] and any(s["kind"] == "ceiling" for s in truth["surfaces"])
    expected = json.loads((tmp_path / "out" / "expected.json").read_text())["counts"]
    assert expected["fire_extinguisher"] == 1 and expected["smoke_detector"] >= 1
    model = json.loads((tmp_path / "out" / "models" / "smoke_detector" / "model.json").read_text())
    assert model["mount"] == ["wall", "ceiling"]


@pytest.mark.slow
def test_building_storeys_put_ceiling_objects_under_their_own_ceilings():
    from sbsc_core.simulate.building_scenario import build_storey, plan_building

    plans = plan_building(2, ceiling_objects=True, columns=True)
    assert all(p.scene.ceiling_objects and p.scene.columns for p in plans)
    b = build_storey(plans[1])  # storey S2: lifted, and room R3 has a lower ceiling
    top = plans[1].floor_z + plans[1].height_m
    low = plans[1].floor_z + plans[1].room_ceilings["R3"]
    on_ceiling = [o for o in b.objects if o.surface == "ceiling"]
    assert on_ceiling and sorted({round(o.position[2], 6) for o in on_ceiling}) == pytest.approx([low, top])
    for o in on_ceiling:
        assert o.frame.origin[2] == pytest.approx(o.position[2])
        assert np.allclose(o.frame.to_world(o.u, o.v), o.position)
    assert sorted({round(s.frame.origin[2], 6) for s in b.surfaces if s.kind == "ceiling"}) == pytest.approx([low, top])
    assert b.columns and all(o.position[2] > plans[1].floor_z for o in b.objects)
    plain = build_storey(plan_building(2)[1])
    assert not plain.surfaces and all(o.surface == "wall" for o in plain.objects)


def test_survey_frame_moves_columns_surfaces_and_storeys():
    from sbsc_core.simulate.survey import SurveyFrame

    desc = _hall(ceiling_objects=True, columns=True)
    desc["rooms"].append({"id": "K", "rect": [8.15, 0, 16.15, 7]})  # a second column: round
    truth = build_building(parse_scene(desc, "hall.yaml")).truth_document()
    truth["storeys"] = [{"id": "S1", "floor_z": 0.0, "ceiling_z": 2.8, "room_ceilings": {"H": 2.5}}]
    frame = SurveyFrame((412000.0, 5612000.0, 100.0), 30.0)
    moved = frame.truth(json.loads(json.dumps(truth)))
    for before, after in zip(truth["columns"], moved["columns"], strict=True):
        want = frame.points(np.array([[*before["centre"], 0.0]]))[0][:2]
        assert np.allclose(after["centre"], want, atol=1e-4)
    rounds = [(a, m) for a, m in zip(truth["surfaces"], moved["surfaces"], strict=True) if "radius_m" in a]
    assert rounds and truth["columns"]
    for before, after in rounds:
        assert len(after["centre"]) == 2
        assert np.allclose(after["centre"], frame.points(np.array([[*before["centre"], 0.0]]))[0][:2], atol=1e-4)
    assert moved["storeys"][0]["floor_z"] == 100.0 and moved["storeys"][0]["ceiling_z"] == 102.8
    assert moved["storeys"][0]["room_ceilings"] == {"H": 102.5}
    # the objects on a round column stay on its cylinder in the survey frame
    for (sf, msf) in rounds:
        on = [o for o in moved["objects"] if o["wall"] == sf["id"]]
        assert on
        for o in on:
            r = np.hypot(o["position"][0] - msf["centre"][0], o["position"][1] - msf["centre"][1])
            assert abs(r - msf["radius_m"]) < 0.05
