"""Scene descriptions of the virtual building: schema, validation, layout and the scenarios."""

from __future__ import annotations

import copy
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml

from sbsc_core.errors import InputError
from sbsc_core.paths import sample_projects_dir
from sbsc_core.simulate import scenarios
from sbsc_core.simulate.catalogue import CATALOGUE, CLASS_ORDER, TABLE1_COUNTS
from sbsc_core.simulate.scene import build_layout, load_scene, parse_scene, validate_scene

ONE_ROOM = sample_projects_dir() / "one_room.yaml"


def _one_room_data() -> dict:
    return yaml.safe_load(ONE_ROOM.read_text())


def _write(tmp_path: Path, data: dict, name: str = "scene.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _error(tmp_path: Path, data: dict, name: str = "scene.yaml") -> str:
    with pytest.raises(InputError) as err:
        load_scene(_write(tmp_path, data, name))
    msg = str(err.value)
    assert "\n" not in msg
    return msg


# --------------------------------------------------------------------------- one room


def test_one_room_loads_with_contract4_frames() -> None:
    scene = load_scene(ONE_ROOM)
    layout = build_layout(scene)
    assert sorted(layout.walls) == ["R1-E", "R1-N", "R1-S", "R1-W"]
    centre = np.array([2.0, 1.5, 1.4])
    for wall in layout.walls.values():
        fr = wall.frame
        assert np.allclose(fr.axis_v, [0, 0, 1])
        assert np.allclose(np.cross(fr.axis_u, fr.axis_v), fr.normal)  # right-handed u, v, n
        assert fr.to_uvd(centre[None])[0, 2] > 1.0  # the normal points into the room
        # origin is the lower-left corner seen from the room: the wall runs to +u from it
        mid = fr.to_uvd(fr.to_world(fr.width_m / 2, 1.0)[None])[0]
        assert 0 < mid[0] < fr.width_m
    assert layout.walls["R1-N"].frame.width_m == pytest.approx(4.0)
    assert layout.walls["R1-E"].frame.width_m == pytest.approx(3.0)
    # the north wall seen from inside runs west -> east
    assert np.allclose(layout.walls["R1-N"].frame.origin, [0, 3, 0])
    assert np.allclose(layout.walls["R1-N"].frame.axis_u, [1, 0, 0])
    assert len(scene.objects) >= 8 and len({o.class_id for o in scene.objects}) >= 8


def test_partition_door_is_cut_through_both_faces(tmp_path: Path) -> None:
    data = {
        "rooms": [{"id": "A", "rect": [0, 0, 4, 3]}, {"id": "B", "rect": [4.15, 0, 8, 3]}],
        "openings": [{"wall": "A-E", "kind": "door", "u": 1.0, "width_m": 0.9, "height_m": 2.1}],
        "objects": [{"class": "switch", "wall": "B-W", "u": 1.0, "v": 1.1}],
    }
    path = _write(tmp_path, data)
    layout = validate_scene(load_scene(path))
    holes = {o.wall: o for o in layout.openings}
    assert set(holes) == {"A-E", "B-W"}
    assert holes["A-E"].depth_m == pytest.approx(0.15)
    # the same world interval on both faces
    wa, wb = layout.walls["A-E"].frame, layout.walls["B-W"].frame
    ya = sorted(wa.to_world(np.array([holes["A-E"].u_min, holes["A-E"].u_max]), 0)[:, 1])
    yb = sorted(wb.to_world(np.array([holes["B-W"].u_min, holes["B-W"].u_max]), 0)[:, 1])
    assert np.allclose(ya, yb)
    # an object on B-W over the hole cut by A-E's door does not fit
    data["objects"][0]["u"] = 2.0
    m = _error(tmp_path, data)
    assert "objects[0] (switch on wall B-W): does not fit on its wall" in m and "door" in m


# --------------------------------------------------------------------------- bad input


def test_missing_file_names_the_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="nothere.yaml: scene description not found"):
        load_scene(tmp_path / "nothere.yaml")


def test_malformed_yaml(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("rooms: [ {id: R1, rect: [0, 0, 4\n objects: ]\n")
    with pytest.raises(InputError, match=r"^broken\.yaml: malformed YAML: "):
        load_scene(path)


def test_malformed_json(tmp_path: Path) -> None:
    path = tmp_path / "broken.json"
    path.write_text('{"rooms": [')
    with pytest.raises(InputError, match=r"^broken\.json: malformed JSON: "):
        load_scene(path)


def test_json_description_is_accepted(tmp_path: Path) -> None:
    import json

    path = tmp_path / "room.json"
    path.write_text(json.dumps(_one_room_data()))
    assert len(load_scene(path).objects) == len(load_scene(ONE_ROOM).objects)


def test_unknown_class(tmp_path: Path) -> None:
    data = _one_room_data()
    data["objects"][3]["class"] = "sokket"
    m = _error(tmp_path, data, "one.yaml")
    assert m.startswith("one.yaml: objects[3].class: unknown class 'sokket'")


def test_object_outside_wall(tmp_path: Path) -> None:
    data = _one_room_data()
    data["objects"].append({"class": "socket_x1", "wall": "R1-W", "u": 2.98, "v": 0.3})
    m = _error(tmp_path, data, "one.yaml")
    k = len(data["objects"]) - 1
    assert m.startswith(f"one.yaml: objects[{k}] (socket_x1 on wall R1-W): does not fit on its wall: ")
    assert "outside the wall" in m


def test_object_over_door(tmp_path: Path) -> None:
    data = _one_room_data()
    data["objects"].append({"class": "switch", "wall": "R1-S", "u": 1.0, "v": 1.1})
    m = _error(tmp_path, data)
    assert "(switch on wall R1-S): does not fit on its wall: overlaps door openings[0]" in m


def test_object_on_door_frame_and_over_window(tmp_path: Path) -> None:
    data = _one_room_data()
    data["objects"].append({"class": "switch", "wall": "R1-S", "u": 1.48, "v": 1.1})  # on the casing
    assert "overlaps door" in _error(tmp_path, data)
    data = _one_room_data()
    data["objects"].append({"class": "fire_alarm_switch_sign", "wall": "R1-N", "u": 2.0, "v": 1.5})
    assert "overlaps window" in _error(tmp_path, data)


def test_overlapping_objects(tmp_path: Path) -> None:
    data = _one_room_data()
    data["objects"].append({"class": "socket_x1", "wall": "R1-W", "u": 1.6, "v": 0.32})
    m = _error(tmp_path, data)
    assert "does not fit on its wall: overlaps objects[8] (socket_x4)" in m


def test_objects_colliding_in_a_corner(tmp_path: Path) -> None:
    data = _one_room_data()
    # two extinguishers (0.18 m deep) in the north-east corner, one on each wall
    data["objects"].append({"class": "fire_extinguisher", "wall": "R1-N", "u": 3.88, "v": 1.2})
    data["objects"].append({"class": "fire_extinguisher", "wall": "R1-E", "u": 0.11, "v": 1.2})
    assert "collides with objects" in _error(tmp_path, data)


def test_unknown_wall_and_fields(tmp_path: Path) -> None:
    data = _one_room_data()
    data["objects"][0]["wall"] = "R9-N"
    assert "objects[0] (switch on wall R9-N): unknown wall 'R9-N'" in _error(tmp_path, data)
    data = _one_room_data()
    data["objects"][0]["colour"] = "red"
    assert "objects[0].colour: unknown field" in _error(tmp_path, data)
    data = _one_room_data()
    data["objects"][0]["u"] = "left"
    assert "objects[0].u: expected a number" in _error(tmp_path, data)
    data = _one_room_data()
    del data["rooms"]
    assert _error(tmp_path, data).endswith("rooms: missing")
    data = _one_room_data()
    data["scanner"] = {"angular_step_deg": 0.0}
    assert "scanner" in _error(tmp_path, data)


def test_bad_room_outlines(tmp_path: Path) -> None:
    data = _one_room_data()
    data["rooms"][0] = {"id": "R1", "outline": [[0, 0], [4, 0], [3, 3], [0, 3]]}
    assert "outline: edges must be axis-aligned" in _error(tmp_path, data)
    data = {"rooms": [{"id": "A", "rect": [0, 0, 4, 3]}, {"id": "B", "rect": [3, 0, 8, 3]}]}
    assert "rooms A and B overlap" in _error(tmp_path, data)


def test_opening_that_does_not_fit(tmp_path: Path) -> None:
    data = _one_room_data()
    data["openings"][1]["u"] = 3.7  # window past the end of R1-N
    m = _error(tmp_path, data)
    assert "openings[1] (window on wall R1-N): does not fit on its wall" in m


# --------------------------------------------------------------------------- scenarios


def _scenario_counts(scene) -> dict[str, int]:
    return dict(Counter(o.class_id for o in scene.objects))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["I", "II"])
def test_shipped_scenario_matches_table1(name: str) -> None:
    scene = load_scene(sample_projects_dir() / f"scenario_{name}.yaml")
    layout = validate_scene(scene)
    assert len(scene.objects) == 116
    assert _scenario_counts(scene) == TABLE1_COUNTS
    assert [TABLE1_COUNTS[c] for c in CLASS_ORDER] == [4, 20, 6, 11, 6, 16, 9, 6, 8, 10, 3, 9, 8]
    assert len({o.wall for o in scene.objects}) == 24
    assert len(layout.walls) == 28
    assert len(scene.rooms) == 5  # four rooms and a corridor
    # footprint of the floor plate, exterior walls included
    pts = np.concatenate([np.asarray(r.outline) for r in scene.rooms])
    extent = pts.max(axis=0) - pts.min(axis=0) + 2 * scene.exterior_wall_thickness_m
    assert np.allclose(extent, [22.9, 19.4])
    assert scene.ceiling_height_m == pytest.approx(3.0)
    assert sum(o.kind == "door" for o in scene.openings) >= 5
    assert sum(o.kind == "window" for o in scene.openings) >= 6
    # realistic heights: sockets low, switches at ~1.1 m, smoke detectors high, signs above
    for o in scene.objects:
        if o.class_id.startswith("socket") or o.class_id == "builtin_socket":
            assert o.v < 0.5
        if o.class_id == "switch":
            assert 0.9 < o.v < 1.3
        if o.class_id == "smoke_detector":
            assert o.v > 2.2
    for sign, base in (("extinguisher_sign", "fire_extinguisher"), ("fire_alarm_switch_sign", "fire_alarm_switch")):
        bases = [(o.wall, o.u, o.v) for o in scene.objects if o.class_id == base]
        for s in (o for o in scene.objects if o.class_id == sign):
            assert any(w == s.wall and abs(u - s.u) < 1e-9 and v < s.v for w, u, v in bases)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["I", "II"])
def test_shipped_file_is_what_the_generator_writes(name: str) -> None:
    if name == "II":
        pytest.importorskip("sbsc_core.simulate.objects")  # Scenario II's paints follow the objects
    text = (sample_projects_dir() / f"scenario_{name}.yaml").read_text()
    assert text == scenarios.scenario_yaml(name)


@pytest.mark.slow
def test_scenarios_differ_only_in_paint() -> None:
    a = yaml.safe_load((sample_projects_dir() / "scenario_I.yaml").read_text())
    b = yaml.safe_load((sample_projects_dir() / "scenario_II.yaml").read_text())
    for key in ("openings", "objects", "stations"):
        assert a[key] == b[key]
    ra, rb = copy.deepcopy(a["rooms"]), copy.deepcopy(b["rooms"])
    assert [r["outline"] for r in ra] == [r["outline"] for r in rb]
    assert [r["paint"] for r in ra] != [r["paint"] for r in rb]


@pytest.mark.slow
def test_scenario_ii_paints_are_close_to_object_colours() -> None:
    objects = pytest.importorskip("sbsc_core.simulate.objects")
    scene = load_scene(sample_projects_dir() / "scenario_II.yaml")
    contrast = scenarios.colour_contrast(scene, objects.build_object)
    smallest = contrast[0][0]
    assert smallest == pytest.approx(4 / 255, abs=1e-3)  # the paper: 1.56 %, for the electrical panel
    assert "electrical_panel" in {cls for d, cls, _ in contrast if d <= smallest + 1e-9}
    # every white-ish object (sockets, switches, panels, detectors) is within 3.5 %
    assert all(d < 0.035 for d, cls, _ in contrast
               if cls in ("electrical_panel", "socket_x1", "socket_x2", "socket_x4", "switch", "smoke_detector"))
    scene_i = load_scene(sample_projects_dir() / "scenario_I.yaml")
    contrast_i = scenarios.colour_contrast(scene_i, objects.build_object)
    assert contrast_i[0][0] > 0.04  # Scenario I: moderate contrast everywhere
    assert np.median([c for c, _, _ in contrast]) < 0.5 * np.median([c for c, _, _ in contrast_i])


def test_cli_refuses_a_bad_scenario_and_writes_nothing(tmp_path: Path) -> None:
    projects = tmp_path / "projects"
    projects.mkdir()
    data = yaml.safe_load((sample_projects_dir() / "scenario_I.yaml").read_text())
    data["objects"][17]["u"] = 500.0
    (projects / "scenario_I.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "out"
    env = {"SBSC_SAMPLE_PROJECTS": str(projects), "PATH": "/usr/bin:/bin"}
    res = subprocess.run([sys.executable, "-m", "sbsc_core", "simulate", "--scenario", "I", "--out", str(out)],
                         capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1
    o = data["objects"][17]
    assert lines[0].startswith(f"sbsc: error: scenario_I.yaml: objects[17] ({o['class']} on wall {o['wall']}): "
                               "does not fit on its wall: ")
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [projects]


def test_catalogue_sizes_drive_footprints() -> None:
    scene = parse_scene(_one_room_data(), "x")
    from sbsc_core.simulate.scene import footprint

    for o in scene.objects:
        u0, u1, v0, v1 = footprint(o)
        assert u1 - u0 == pytest.approx(CATALOGUE[o.class_id].width_m)
        assert v1 - v0 == pytest.approx(CATALOGUE[o.class_id].height_m)
