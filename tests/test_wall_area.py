"""Visible wall area and openings (paper, section 3.3) on synthetic orthoimages."""

from __future__ import annotations

import numpy as np
import pytest

from sbsc_core.imaging.colour_prep import prepare_colour
from sbsc_core.imaging.wall_area import find_wall_area
from sbsc_core.settings import WallAreaSettings
from tests.synthetic_rooms import Block, Hole, Patch, make_ortho

PX = 0.005
H = 2.7
WALL = (205, 200, 190)
BROWN = (96, 70, 50)
DOOR = Hole("door", 0.5, 1.4, 0.0, 2.1)
WINDOW = Hole("window", 3.4, 4.6, 0.9, 2.1)
CASING = [Block(0.43, 0.5, 0.0, 2.17, 0.015, BROWN), Block(1.4, 1.47, 0.0, 2.17, 0.015, BROWN),
          Block(0.43, 1.47, 2.1, 2.17, 0.015, BROWN)]
WINDOW_FRAME = [Block(3.4, 3.46, 0.9, 2.1, -0.12, (70, 74, 80)), Block(4.54, 4.6, 0.9, 2.1, -0.12, (70, 74, 80)),
                Block(3.97, 4.03, 0.9, 2.1, -0.12, (70, 74, 80))]  # mullions deep in the reveal
OBJECTS = {
    "socket": Block(1.8, 1.88, 0.26, 0.34, 0.012, (245, 245, 242)),
    "sign": Patch(2.2, 2.41, 1.8, 2.1, (0, 140, 80)),
    "radiator": Block(3.6, 4.4, 0.15, 0.75, 0.10, (240, 240, 240)),
    "panel": Block(2.6, 3.0, 1.35, 1.85, 0.10, (150, 152, 155)),
    "extinguisher": Block(1.9, 2.1, 0.9, 1.5, 0.18, (210, 30, 30)),
    "poster": Patch(5.0, 5.45, 1.2, 1.8, (60, 90, 160)),  # flat, window sized: not an opening
}


def _px(u: float, v: float) -> tuple[int, int]:
    return int((H - v) / PX), int(u / PX)


def _region(o, u0, u1, v0, v1, inset=0.02):
    (r0, c0), (r1, c1) = _px(u0 + inset, v1 - inset), _px(u1 - inset, v0 + inset)
    return (slice(r0, r1), slice(c0, c1))


@pytest.fixture(scope="module")
def wall():
    o = make_ortho(6.0, H, features=[DOOR, WINDOW, *CASING, *WINDOW_FRAME, *OBJECTS.values()],
                   gains=[(2.5, 6.0, 0.0, H, 0.85)], specular=[(2.3, 0.6, 0.12, 70.0)],
                   nodata=[(5.2, 5.7, 0.1, 0.5), (0.0, 6.0, 0.0, 0.015)], seed=5)
    # an unscanned shadow that is not rectangular (blind spot under a station)
    h, w = o.shape
    rr, cc = np.mgrid[0:h, 0:w]
    blind = ((cc - 500) / 90.0) ** 2 + ((rr - h) / 50.0) ** 2 < 1.0
    o.mask[blind] = False
    o.depth[blind] = np.nan
    o.colour[blind] = 0
    return o, find_wall_area(prepare_colour(o), WallAreaSettings())


def test_door_and_window_are_found(wall) -> None:
    o, area = wall
    kinds = sorted(op.kind for op in area.openings)
    assert kinds == ["door", "window"], area.openings
    door = next(op for op in area.openings if op.kind == "door")
    win = next(op for op in area.openings if op.kind == "window")
    assert door.wall_id == "W01"
    for got, want in ((door, DOOR), (win, WINDOW)):
        assert got.u_min == pytest.approx(want.u0, abs=0.03)
        assert got.u_max == pytest.approx(want.u1, abs=0.03)
        assert got.v_min == pytest.approx(want.v0, abs=0.03)
        assert got.v_max == pytest.approx(want.v1, abs=0.03)
    assert area.opening_mask[_region(o, DOOR.u0, DOOR.u1, DOOR.v0, DOOR.v1)].all()
    assert area.opening_mask.sum() * PX * PX == pytest.approx(0.9 * 2.1 + 1.2 * 1.2, rel=0.05)


def test_small_objects_are_neither_openings_nor_wall(wall) -> None:
    o, area = wall
    for name, f in OBJECTS.items():
        reg = _region(o, f.u0, f.u1, f.v0, f.v1, inset=0.01)
        assert not area.opening_mask[reg].any(), name
        assert area.visible[reg].mean() < 0.05, name


def test_unscanned_parts_are_neither_visible_nor_openings(wall) -> None:
    o, area = wall
    nodata = ~o.mask
    assert not area.visible[nodata].any()
    reg = _region(o, 5.2, 5.7, 0.1, 0.5, inset=0.0)
    assert not area.opening_mask[reg].any()
    assert not area.opening_mask[-40:, 300:700].any()  # the blind spot at the bottom


def test_visible_area_is_the_plain_wall_and_its_colour(wall) -> None:
    o, area = wall
    things = [DOOR, WINDOW, *CASING, *WINDOW_FRAME, *OBJECTS.values()]
    plain, exact = np.ones(o.shape, bool), np.ones(o.shape, bool)
    for f in things:
        plain[_region(o, f.u0, f.u1, f.v0, f.v1, inset=-0.02)] = False  # 2 cm away from anything
        exact[_region(o, f.u0, f.u1, f.v0, f.v1, inset=0.0)] = False
    plain &= o.mask
    exact &= o.mask
    assert area.visible[plain].mean() > 0.97  # including the darker station and the highlight
    assert (area.visible & ~exact).sum() < 0.01 * exact.sum()
    prepared = prepare_colour(o).colour
    np.testing.assert_allclose(area.wall_colour, np.median(prepared[plain], axis=0), atol=3.0)


def test_closed_door_of_another_colour_and_a_wall_without_openings() -> None:
    leaf = Block(1.0, 1.9, 0.0, 2.05, -0.01, (150, 110, 70))
    o = make_ortho(4.0, H, features=[leaf, OBJECTS["radiator"], OBJECTS["panel"]], seed=6)
    area = find_wall_area(prepare_colour(o))
    assert [op.kind for op in area.openings] == ["door"]
    op = area.openings[0]
    assert (op.u_min, op.u_max, op.v_max) == pytest.approx((1.0, 1.9, 2.05), abs=0.03)
    plain = make_ortho(6.0, H, features=[OBJECTS["radiator"], OBJECTS["panel"], OBJECTS["poster"]], seed=7)
    area = find_wall_area(prepare_colour(plain))
    assert area.openings == [] and not area.opening_mask.any()


@pytest.mark.slow
def test_one_room_simulated_scan() -> None:
    """The simulator's one-room scene scanned coarsely: 4 walls and the door and window.

    Uses the steps of ``simulate_scene`` (scene, building, scanner, truth) without writing
    the PLY and the model library, which this test does not need.
    """
    pytest.importorskip("sbsc_core.simulate.objects", reason="the simulator's objects are not there yet")
    from sbsc_core.imaging.orthoimage import build_orthoimage
    from sbsc_core.paths import sample_projects_dir
    from sbsc_core.scene.segmentation import segment_floor_ceiling_walls
    from sbsc_core.simulate.building import build_building
    from sbsc_core.simulate.scanner import scan_mesh
    from sbsc_core.simulate.scene import load_scene
    from sbsc_core.types import PointCloud

    scene = load_scene(sample_projects_dir() / "one_room.yaml")
    scene.scanner = scene.scanner.replace(angular_step_deg=0.2)
    building = build_building(scene)
    scan = scan_mesh(building.mesh, building.stations, scene.scanner, seed=0)
    origin = np.round(scan.xyz.astype(np.float64).mean(axis=0))
    cloud = PointCloud((scan.xyz - origin).astype(np.float32), scan.rgb, origin)
    truth = building.truth_document()
    seg = segment_floor_ceiling_walls(cloud)
    assert len(seg.walls) == len(truth["walls"]) == 4
    found, ids = [], set()
    for w in seg.walls:
        f = w.frame
        t = min(truth["walls"], key=lambda t: np.linalg.norm(np.asarray(t["origin"]) - f.origin)
                + 5 * np.linalg.norm(np.asarray(t["normal"]) - f.normal))
        ids.add(t["id"])
        assert np.linalg.norm(np.asarray(t["origin"]) - f.origin) < 0.02
        assert np.dot(t["normal"], f.normal) > np.cos(np.radians(0.5))
        assert abs(f.width_m - t["width_m"]) < 0.02 and abs(f.height_m - t["height_m"]) < 0.01
        area = find_wall_area(prepare_colour(build_orthoimage(cloud, w)))
        found += [(t["id"], op) for op in area.openings]
    assert len(ids) == 4
    assert len(found) == len(truth["openings"]) == 2
    for wall_id, op in found:
        t = next(t for t in truth["openings"] if t["wall"] == wall_id)
        assert op.kind == t["kind"]
        for k in ("u_min", "u_max", "v_min", "v_max"):
            assert getattr(op, k) == pytest.approx(t[k], abs=0.03), (wall_id, k)
