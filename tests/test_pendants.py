"""Objects hanging from the ceiling (issue 27): finding the panels, their surfaces, their documents."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

from sbsc_core.bim.surfaces import read_surfaces
from sbsc_core.scene.ceilings import ceiling_levels
from sbsc_core.scene.pendants import find_pendants
from sbsc_core.settings import CeilingSettings, PendantSettings
from sbsc_core.types import PointCloud, Segmentation, Storey
from tests.synthetic_rooms import plan_wall

_wall = partial(plan_wall, height=2.7)
SIGN = (0.34, 0.14)  # an exit sign's width and height (m)
SIZES = [SIGN, (0.11, 0.11)]  # the classes that may be on a ceiling: an exit sign and a smoke detector


def _grid(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    gu, gv = np.meshgrid(u, v)
    return gu.ravel(), gv.ravel()


def _box(x: tuple[float, float], y: tuple[float, float], z: tuple[float, float], step: float = 0.005,
         faces: str = "xXyYzZ") -> np.ndarray:
    """Points on the faces of an axis-aligned box (x-, x+, y-, y+, z-, z+ as the letters say)."""
    xs, ys, zs = (np.arange(a, b + 1e-9, step) for a, b in (x, y, z))
    out = []
    if "x" in faces or "X" in faces:
        a, b = _grid(ys, zs)
        out += [np.column_stack([np.full(a.size, xv), a, b]) for f, xv in (("x", x[0]), ("X", x[1])) if f in faces]
    if "y" in faces or "Y" in faces:
        a, b = _grid(xs, zs)
        out += [np.column_stack([a, np.full(a.size, yv), b]) for f, yv in (("y", y[0]), ("Y", y[1])) if f in faces]
    if "z" in faces or "Z" in faces:
        a, b = _grid(xs, ys)
        out += [np.column_stack([a, b, np.full(a.size, zv)]) for f, zv in (("z", z[0]), ("Z", z[1])) if f in faces]
    return np.vstack(out)


def _room(rng, *, lower_ceiling: bool = False) -> tuple[PointCloud, Segmentation]:
    """A 6 x 4 m room, 2.7 m high, with:

    - an exit sign (0.34 x 0.14 m, 5 cm thick) hanging 4 cm under the ceiling at x = 3, facing
      -x, seen mostly on its front (x = 2.95) and a little on its bottom;
    - a board as thin as a sign (5 cm, 0.4 m wide), standing on the floor up to 2.4 m (it does
      not hang);
    - a smoke detector on the ceiling (flat: not upright);
    - with ``lower_ceiling``, the half x > 4 has a ceiling at 2.3 m (a lower level), and a
      second sign hangs under it at x = 5 (so 0.4 m lower than the first).
    """
    top = 2.7
    parts = [
        _box((0.0, 6.0), (0.0, 4.0), (0.0, top), step=0.02, faces="xXyYzZ"),  # walls, floor, ceiling
        _box((2.95, 3.0), (1.83, 2.17), (2.52, 2.66), faces="xz"),  # the sign: front and bottom
        _box((1.0, 1.05), (0.5, 0.9), (0.0, 2.4), step=0.01, faces="xXZ"),  # the shelf
        _box((4.0, 4.11), (3.0, 3.11), (2.66, 2.7), faces="z"),  # the smoke detector's face
    ]
    if lower_ceiling:
        parts = [p[~((p[:, 0] > 4.0) & (p[:, 2] > 2.69))] for p in parts]  # the high ceiling over x > 4 is hidden
        parts.append(_box((4.0, 6.0), (0.0, 4.0), (2.3, 2.3), step=0.02, faces="z"))
        parts.append(_box((4.95, 5.0), (2.83, 3.17), (2.12, 2.26), faces="xz"))
    xyz = np.vstack(parts)
    xyz = xyz + rng.normal(0, 0.002, xyz.shape)
    cloud = PointCloud(xyz.astype(np.float32), np.full((len(xyz), 3), 200, np.uint8))
    walls = [_wall("W1", (0, 0), (6, 0)), _wall("W2", (6, 0), (6, 4)), _wall("W3", (6, 4), (0, 4)),
             _wall("W4", (0, 4), (0, 0))]
    return cloud, Segmentation(0.0, top, walls, [Storey("S1", 0.0, top)])


def test_a_hanging_sign_is_found_and_nothing_else():
    cloud, seg = _room(np.random.default_rng(3))
    faces = find_pendants(cloud, seg, PendantSettings(), sizes=SIZES)
    assert [f.id for f in faces] == ["P1"]
    f = faces[0].frame
    assert f.normal == pytest.approx([-1.0, 0.0, 0.0], abs=0.02)  # towards the side that was seen
    assert float(np.dot(f.origin, f.normal)) == pytest.approx(-3.0, abs=0.01)  # its plane: the sign's back
    centre = f.to_world(f.width_m / 2, f.height_m / 2)
    assert centre[1] == pytest.approx(2.0, abs=0.01)
    assert f.width_m == pytest.approx(SIGN[0] + 0.2, abs=0.03)  # the sign and a margin on each side
    assert f.origin[2] == pytest.approx(2.52 - 0.1, abs=0.02)
    assert f.origin[2] + f.height_m <= 2.7 - PendantSettings().gap_m + 1e-6  # the ceiling stays out of the image
    doc = faces[0].surface()
    assert doc["kind"] == "pendant" and doc["hangs_from"] == "S1"
    assert list(read_surfaces({"surfaces": [doc]})) == ["P1"]  # the documents' reader takes it


def test_what_stands_on_the_floor_does_not_hang():
    cloud, seg = _room(np.random.default_rng(6))
    big = [*SIZES, (1.0, 0.6)]  # a radiator too may be on a ceiling: the board is of a size to look at
    assert [f.id for f in find_pendants(cloud, seg, PendantSettings(), sizes=big)] == ["P1"]
    lax = PendantSettings(max_under_share=1e9)  # were standing things let through, the board would be one
    assert len(find_pendants(cloud, seg, lax, sizes=big)) == 2


def test_the_library_says_how_big_a_panel_may_be():
    cloud, seg = _room(np.random.default_rng(4))
    assert find_pendants(cloud, seg, PendantSettings(), sizes=[(0.08, 0.08)]) == []  # only switch-sized classes
    assert find_pendants(cloud, seg, PendantSettings(), sizes=[]) == []  # nothing may be on a ceiling


def test_a_sign_under_a_lower_ceiling_is_found_under_it():
    cloud, seg = _room(np.random.default_rng(5), lower_ceiling=True)
    levels = ceiling_levels(cloud, seg, CeilingSettings())
    assert levels and levels[0].z[0] == pytest.approx(2.3, abs=0.01)
    faces = find_pendants(cloud, seg, PendantSettings(), sizes=SIZES, levels=levels)
    centres = sorted(round(float(f.frame.to_world(f.frame.width_m / 2, 0)[0]), 1) for f in faces)
    assert centres == [3.0, 5.0]
    low = next(f for f in faces if f.frame.origin[0] > 4)
    assert low.frame.origin[2] + low.frame.height_m <= 2.3 - PendantSettings().gap_m + 1e-6


def _hall(**options) -> dict:
    """A 6 m x 5 m room, 2.8 m high, with a door and no exit light on the walls: the door's
    exit light is on the ceiling (hanging, with ``pendants``)."""
    return {"schema": "sbsc.scene/1", "name": "hall", "ceiling_height_m": 2.8,
            "rooms": [{"id": "H", "rect": [0, 0, 6, 5]}],
            "openings": [{"wall": "H-S", "kind": "door", "u": 2.0, "width_m": 0.9, "height_m": 2.1}],
            "objects": [{"class": "switch", "wall": "H-S", "u": 3.2, "v": 1.1},
                        {"class": "socket_x1", "wall": "H-W", "u": 2.0, "v": 0.3}], **options}


def test_the_simulator_hangs_the_ceilings_exit_lights():
    from sbsc_core.errors import InputError
    from sbsc_core.simulate.building import build_building
    from sbsc_core.simulate.scene import parse_scene

    truth = build_building(parse_scene(_hall(ceiling_objects=True, pendants=True), "hall.yaml")).truth_document()
    exit_light = next(o for o in truth["objects"] if o["class"] == "exit_light")
    pendant = next(s for s in truth["surfaces"] if s["id"] == exit_light["wall"])
    assert exit_light["surface"] == "ceiling" and pendant["kind"] == "pendant" and pendant["hangs_from"] == "H-C"
    assert pendant["normal"] == pytest.approx([0.0, 1.0, 0.0])  # facing the room, as the door's wall
    assert exit_light["position"][2] + 0.07 == pytest.approx(2.8 - 0.08, abs=1e-6)  # its top 8 cm under the ceiling
    with pytest.raises(InputError, match=r"^hall.yaml: pendants: needs ceiling_objects"):
        parse_scene(_hall(pendants=True), "hall.yaml")


@pytest.mark.slow
def test_a_hanging_exit_light_is_found_end_to_end(tmp_path):
    import json

    import yaml

    from sbsc_core.cli import main
    from sbsc_core.simulate.scenarios import simulate_scene

    path = tmp_path / "hall.yaml"
    path.write_text(yaml.safe_dump(_hall(ceiling_objects=True, pendants=True, scanner={"angular_step_deg": 0.25})))
    simulate_scene(path, tmp_path / "sim", seed=2, design=False)
    sim = tmp_path / "sim"
    assert main(["-q", "detect", str(sim / "scan.ply"), "--models", str(sim / "models"),
                 "--expected", str(sim / "expected.json"), "--out", str(tmp_path / "det")]) == 0
    doc = json.loads((tmp_path / "det" / "detections.json").read_text())
    pendants = [s for s in doc["surfaces"] if s["kind"] == "pendant"]
    assert len(pendants) == 1
    hung = [d for d in doc["detections"] if d["wall"] == pendants[0]["id"]]
    assert [(d["class"], d["surface"]) for d in hung] == [("exit_light", "ceiling")]
    truth = json.loads((sim / "ground_truth.json").read_text())
    t = next(o for o in truth["objects"] if o["class"] == "exit_light")
    assert np.linalg.norm(np.subtract(hung[0]["position"], t["position"])) < 0.03
    assert main(["-q", "export-ifc", str(tmp_path / "det" / "detections.json"), "--out", str(tmp_path / "a.ifc")]) == 0
