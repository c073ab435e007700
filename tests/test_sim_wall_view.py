"""Looking at a simulated wall straight on: every object shows where the truth says it is.

Uses the small one-room scene; the objects are the real ones of
``sbsc_core.simulate.objects`` when that module is present, else boxes of the catalogue
size (a stand-in while it is written).
"""

from __future__ import annotations

import hashlib
import json
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.paths import sample_projects_dir
from sbsc_core.simulate import mesh as M
from sbsc_core.simulate.building import build_building
from sbsc_core.simulate.catalogue import CATALOGUE
from sbsc_core.simulate.scanner import scan_mesh, wall_view
from sbsc_core.simulate.scenarios import simulate_scene
from sbsc_core.simulate.scene import load_scene

ONE_ROOM = sample_projects_dir() / "one_room.yaml"
PX = 0.005
DEPTH_STEP_M = 0.006  # a pixel standing out this far is not plain wall (range noise 2.5 mm)
COLOUR_STEP = 30.0  # RGB distance from the surrounding wall that is not plain wall


def _stand_in(class_id: str) -> M.ColouredMesh:
    s = CATALOGUE[class_id]
    return M.box((s.width_m, s.height_m, s.depth_m), (245, 245, 240), (0.0, 0.0, s.depth_m / 2))


def _builder():
    try:
        from sbsc_core.simulate.objects import build_object
    except ImportError:
        return _stand_in
    return build_object


@pytest.fixture(scope="module")
def room():
    scene = load_scene(ONE_ROOM)
    building = build_building(scene, _builder())
    scan = scan_mesh(building.mesh, building.stations, scene.scanner, seed=0)
    views = {wid: wall_view(scan.xyz, scan.rgb, w.frame, pixel_m=PX) for wid,
             w in building.layout.walls.items()}
    return building, views


def _rect(view, u0, u1, v0, v1):
    h, w = view.depth.shape
    c0, c1 = max(0, int(np.floor(u0 / PX))), min(w, int(np.ceil(u1 / PX)))
    r0, r1 = max(0, int(np.floor(h - v1 / PX))), min(h, int(np.ceil(h - v0 / PX)))
    return slice(r0, r1), slice(c0, c1)


def _blocked(building, wall_id, view, margin):
    """Pixels of other objects and openings (grown by ``margin``) on this wall."""
    mask = np.zeros(view.depth.shape, bool)
    for o in building.objects:
        if o.wall == wall_id:
            mask[_rect(view, o.u - o.width_m / 2 - margin, o.u + o.width_m / 2 + margin,
                       o.v - o.height_m / 2 - margin, o.v + o.height_m / 2 + margin)] = True
    fw = building.scene.door_frame_width_m
    for op in building.layout.openings_on(wall_id):
        mask[_rect(view, op.u_min - fw - margin, op.u_max + fw + margin, op.v_min - fw - margin,
                   op.v_max + fw + margin)] = True
    return mask


@pytest.mark.slow
def test_every_object_shows_in_colour_or_depth_where_the_truth_says(room) -> None:
    building, views = room
    walls = sorted({o.wall for o in building.objects})
    assert len(walls) == 4
    checked = 0
    for wall_id in walls:
        view = views[wall_id]
        has = view.count > 0
        blocked = _blocked(building, wall_id, view, 0.02)
        for o in (o for o in building.objects if o.wall == wall_id):
            # the object's own footprint (a pixel in from its edge) and a ring of wall around it
            inner = np.zeros_like(has)
            inner[_rect(view, o.u - o.width_m / 2 + PX, o.u + o.width_m / 2 - PX,
                        o.v - o.height_m / 2 + PX, o.v + o.height_m / 2 - PX)] = True
            outer = np.zeros_like(has)
            outer[_rect(view, o.u - o.width_m / 2 - 0.08, o.u + o.width_m / 2 + 0.08,
                        o.v - o.height_m / 2 - 0.08, o.v + o.height_m / 2 + 0.08)] = True
            ring = outer & ~blocked & has
            assert ring.sum() > 50, (wall_id, o.class_id)
            wall_rgb = np.median(view.colour[ring].astype(float), axis=0)
            wall_d = float(np.median(view.depth[ring]))
            assert abs(wall_d) < 0.002  # the truth frame's plane is where the wall was scanned
            dist = np.linalg.norm(view.colour.astype(float) - wall_rgb, axis=2)
            odd = has & ((view.depth - wall_d > DEPTH_STEP_M) | (dist > COLOUR_STEP))
            inside = inner & has
            assert inside.sum() > 0.5 * inner.sum(), (wall_id, o.class_id, "no data on the object")
            frac_in = odd[inside].mean()
            frac_ring = odd[ring].mean()
            assert frac_in > 0.3, (wall_id, o.class_id, frac_in)
            assert frac_ring < 0.1, (wall_id, o.class_id, frac_ring)
            # the odd pixels near the object are centred where the truth puts it
            win = np.zeros_like(has)
            win[_rect(view, o.u - o.width_m / 2 - 0.03, o.u + o.width_m / 2 + 0.03,
                      o.v - o.height_m / 2 - 0.03, o.v + o.height_m / 2 + 0.03)] = True
            rr, cc = np.nonzero(odd & win & ~(blocked & ~outer))
            u_c = (0.5 * (cc.min() + cc.max()) + 0.5) * PX
            v_c = (view.depth.shape[0] - 0.5 * (rr.min() + rr.max()) - 0.5) * PX
            assert abs(u_c - o.u) < max(0.015, 0.2 * o.width_m), (wall_id, o.class_id, u_c, o.u)
            assert abs(v_c - o.v) < max(0.015, 0.2 * o.height_m), (wall_id, o.class_id, v_c, o.v)
            checked += 1
    assert checked == len(building.objects)


@pytest.mark.slow
def test_plain_wall_is_sampled_densely_enough_for_5mm_pixels(room) -> None:
    building, views = room
    fractions = []
    for wall_id, view in views.items():
        plain = ~_blocked(building, wall_id, view, 0.10)
        plain[:10] = plain[-10:] = False  # corners with the floor / ceiling / next wall
        plain[:, :10] = plain[:, -10:] = False
        fractions.append((view.count[plain] > 0).mean())
    assert min(fractions) > 0.9, fractions


def _fake_library(monkeypatch) -> None:
    try:
        import sbsc_core.simulate.library  # noqa: F401
    except ImportError:
        fake = types.ModuleType("sbsc_core.simulate.library")

        def write_model_library(out, seed=0):
            Path(out).mkdir(parents=True)
            (Path(out) / "README").write_text(f"stand-in {seed}\n")

        fake.write_model_library = write_model_library
        monkeypatch.setitem(sys.modules, "sbsc_core.simulate.library", fake)


@pytest.mark.slow
def test_simulate_scene_writes_the_contracts_deterministically(tmp_path: Path, monkeypatch) -> None:
    _fake_library(monkeypatch)
    builder = _builder()
    a = simulate_scene(ONE_ROOM, tmp_path / "a", seed=5, angular_step_deg=0.3, object_builder=builder)
    b = simulate_scene(ONE_ROOM, tmp_path / "b", seed=5, angular_step_deg=0.3, object_builder=builder)
    simulate_scene(ONE_ROOM, tmp_path / "c", seed=6, angular_step_deg=0.3, object_builder=builder)
    assert a.points == b.points > 10_000

    def digest(p: Path) -> str:
        return hashlib.sha256(p.read_bytes()).hexdigest()

    assert digest(tmp_path / "a" / "scan.ply") == digest(tmp_path / "b" / "scan.ply")
    assert digest(tmp_path / "a" / "scan.ply") != digest(tmp_path / "c" / "scan.ply")
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == [
        "as_designed.ifc", "expected.json", "ground_truth.json", "models", "scan.ply"]
    head = (tmp_path / "a" / "scan.ply").read_bytes()[:400].decode("ascii", "replace")
    assert "property float x" in head and "property uchar red" in head
    assert f"element vertex {a.points}\n" in head
    truth = json.loads((tmp_path / "a" / "ground_truth.json").read_text())
    assert truth["schema"] == "sbsc.truth/1"
    scene = load_scene(ONE_ROOM)
    assert len(truth["objects"]) == len(scene.objects)
    walls = {w["id"]: w for w in truth["walls"]}
    for o, p in zip(truth["objects"], scene.objects, strict=True):
        assert o["class"] == p.class_id and o["wall"] == p.wall
        w = walls[o["wall"]]
        pos = np.add(np.add(w["origin"], np.multiply(o["u"], w["axis_u"])), np.multiply(o["v"], w["axis_v"]))
        assert np.allclose(pos, o["position"], atol=1e-4)
        assert np.allclose(o["normal"], w["normal"])
        assert o["width_m"] == pytest.approx(CATALOGUE[o["class"]].width_m)
    assert {op["kind"] for op in truth["openings"]} == {"door", "window"}
    expected = json.loads((tmp_path / "a" / "expected.json").read_text())
    assert expected["schema"] == "sbsc.expected/1"
    assert sum(expected["counts"].values()) == len(scene.objects)
    assert (tmp_path / "a" / "models").is_dir()
    # no temporary directories are left beside the outputs
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b", "c"]
