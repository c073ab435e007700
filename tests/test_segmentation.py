"""Floor, ceiling and wall segmentation (paper, section 3.1) on synthetic rooms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sbsc_core.errors import NoWallsError
from sbsc_core.scene.segmentation import (
    find_floor_ceiling,
    fit_line_2d,
    segment_floor_ceiling_walls,
)
from sbsc_core.settings import SegmentationSettings
from sbsc_core.types import PointCloud
from tests.synthetic_rooms import Block, Hole, Room, make_scene, rotated

SLANTED = [(0.0, 0.0), (5.0, 0.0), (5.0, 3.0), (0.0, 3.0 + 5.0 * math.tan(math.radians(30)))]
ORIGIN = (1000.0, -2000.0, 50.0)


def _angle_deg(a, b) -> float:
    return math.degrees(math.acos(float(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def _match(frame, truth_walls):
    """The truth wall of the same facing whose origin is nearest."""
    same = [t for t in truth_walls if np.dot(t["normal"], frame.normal) > 0.9]
    return min(same, key=lambda t: np.linalg.norm(np.asarray(t["origin"]) - frame.origin))


def _check_frames(seg, truth, tol_m=0.02, tol_deg=0.5):
    matched = []
    for w in seg.walls:
        f = w.frame
        t = _match(f, truth["walls"])
        matched.append((t["room"], t["edge"]))
        assert np.linalg.norm(np.asarray(t["origin"]) - f.origin) < tol_m, (w.id, f.origin, t["origin"])
        assert _angle_deg(t["normal"], f.normal) < tol_deg
        assert _angle_deg(t["axis_u"], f.axis_u) < tol_deg
        assert abs(f.width_m - t["width_m"]) < tol_m, (w.id, f.width_m, t["width_m"])
        assert abs(f.height_m - t["height_m"]) < 0.01
        np.testing.assert_allclose(f.axis_v, [0, 0, 1])
        np.testing.assert_allclose(np.cross([0, 0, 1], f.normal), f.axis_u, atol=1e-9)
    assert len(set(matched)) == len(truth["walls"]) == len(seg.walls)


def test_floor_and_ceiling_are_the_two_z_maxima() -> None:
    rng = np.random.default_rng(0)
    z = np.concatenate([
        rng.normal(0.10, 0.002, 50_000),  # floor
        rng.normal(2.95, 0.002, 40_000),  # ceiling
        rng.uniform(0.1, 2.95, 60_000),  # walls
        rng.normal(0.75, 0.002, 3_000),  # a table top: a smaller maximum
    ]).astype(np.float32)
    floor, ceiling = find_floor_ceiling(z)
    assert floor == pytest.approx(0.10, abs=0.003)
    assert ceiling == pytest.approx(2.95, abs=0.003)


def test_one_level_only_is_no_walls() -> None:
    z = np.random.default_rng(1).normal(0.0, 0.002, 10_000)
    with pytest.raises(NoWallsError, match="no walls found"):
        find_floor_ceiling(z)


def test_fit_line_2d_ignores_objects_on_the_wall() -> None:
    rng = np.random.default_rng(2)
    t = rng.uniform(0, 5, 2000)
    a = math.radians(30)
    d = rng.normal(0, 0.002, 2000)
    d[:300] += 0.1  # a radiator standing out
    xy = np.column_stack([t * math.cos(a) - d * math.sin(a), t * math.sin(a) + d * math.cos(a)]) + [3, 4]
    n, s = fit_line_2d(xy, (0.03, 0.015))
    assert _angle_deg(np.abs(n), [math.sin(a), math.cos(a)]) < 0.2
    assert abs(abs(s) - abs(np.dot(n, [3, 4]))) < 0.002


@pytest.fixture(scope="module")
def slanted_room():
    room = Room(SLANTED, features={
        0: [Hole("door", 1.0, 1.9, 0.0, 2.1), Block(3.0, 3.8, 0.15, 0.75, 0.10, (245, 245, 245))],
        2: [Hole("window", 1.0, 2.2, 0.9, 2.1), Block(4.0, 4.2, 0.9, 1.5, 0.18, (220, 30, 30))],
    })
    return make_scene([room], spacing=0.02, origin=ORIGIN, noise_m=0.0025)


def test_room_with_a_wall_at_30_degrees(slanted_room) -> None:
    cloud, truth = slanted_room
    seg = segment_floor_ceiling_walls(cloud, SegmentationSettings())
    assert seg.floor_z == pytest.approx(0.0, abs=0.005)  # world z (the cloud is stored around z=50)
    assert seg.ceiling_z == pytest.approx(2.7, abs=0.005)
    assert [w.id for w in seg.walls] == ["W01", "W02", "W03", "W04"]
    _check_frames(seg, truth)
    # normals point into the room: towards the room's centre
    centre = np.array([*np.mean(SLANTED, axis=0), 1.0])
    for w in seg.walls:
        assert np.dot(centre - w.frame.origin, w.frame.normal) > 0.5
    # deterministic
    again = segment_floor_ceiling_walls(cloud, SegmentationSettings())
    assert [w.id for w in again.walls] == [w.id for w in seg.walls]
    for a, b in zip(seg.walls, again.walls, strict=True):
        np.testing.assert_array_equal(a.point_index, b.point_index)


def test_wall_points_include_objects_exclude_floor_ceiling_and_other_walls(slanted_room) -> None:
    cloud, truth = slanted_room
    s = SegmentationSettings()
    seg = segment_floor_ceiling_walls(cloud, s)
    world = cloud.world()
    all_idx = np.concatenate([w.point_index for w in seg.walls])
    assert len(np.unique(all_idx)) == len(all_idx)  # no point in two walls
    for w in seg.walls:
        p = world[w.point_index]
        assert w.point_index.dtype == np.int64
        assert np.all(np.diff(w.point_index) > 0)
        assert p[:, 2].min() > seg.floor_z + s.slab_tolerance_m - 1e-4
        assert p[:, 2].max() < seg.ceiling_z - s.slab_tolerance_m + 1e-4
        uvd = w.frame.to_uvd(p)
        assert uvd[:, 2].min() >= -s.behind_depth_m - 1e-3
        assert uvd[:, 2].max() <= s.object_depth_m + 1e-3
    # the radiator front (10 cm out) and the extinguisher (18 cm) belong to their walls
    south = next(w for w in seg.walls if np.dot(w.frame.normal, [0, 1, 0]) > 0.99)
    uvd = south.frame.to_uvd(world[south.point_index])
    front = (np.abs(uvd[:, 2] - 0.10) < 0.01) & (uvd[:, 1] > 0.2) & (uvd[:, 1] < 0.7)
    assert front.sum() > 500
    assert uvd[front, 0].min() == pytest.approx(3.0, abs=0.02)
    assert uvd[front, 0].max() == pytest.approx(3.8, abs=0.02)
    slanted = next(w for w in seg.walls if abs(w.frame.normal[0]) > 0.3 and abs(w.frame.normal[1]) > 0.3)
    uvd = slanted.frame.to_uvd(world[slanted.point_index])
    assert (np.abs(uvd[:, 2] - 0.18) < 0.01).sum() > 100
    # every wall point of the truth is given to a wall
    on_wall = np.zeros(len(cloud), bool)
    for t in truth["walls"]:
        o, n = np.asarray(t["origin"]), np.asarray(t["normal"])
        a = np.asarray(t["axis_u"])
        d, u = (world - o) @ n, (world - o) @ a
        z = world[:, 2]
        on_wall |= (np.abs(d) < 0.01) & (u > 0.05) & (u < t["width_m"] - 0.05) & (z > 0.05) & (z < 2.65)
    got = np.zeros(len(cloud), bool)
    got[all_idx] = True
    assert got[on_wall].mean() > 0.999


def test_rotated_rooms_partition_and_corridor() -> None:
    """Two rooms and a corridor, rotated by 30 degrees: 12 room-facing walls."""
    turn = lambda o: rotated(o, 30.0, (3.0, -2.0))  # noqa: E731
    a = Room(turn([(0, 0), (5, 0), (5, 4), (0, 4)]), {1: [Hole("door", 2.1, 3.0, 0, 2.1)],
                                                      2: [Hole("door", 2.0, 2.9, 0, 2.1)]})
    b = Room(turn([(5.12, 0), (9, 0), (9, 4), (5.12, 4)]), {3: [Hole("door", 1.0, 1.9, 0, 2.1)],
                                                          2: [Hole("door", 1.88, 2.78, 0, 2.1)]})
    c = Room(turn([(0, 4.15), (9, 4.15), (9, 6), (0, 6)]), {0: [Hole("door", 6.1, 7.0, 0, 2.1),
                                                              Hole("door", 1.1, 2.0, 0, 2.1)]})
    cloud, truth = make_scene([a, b, c], spacing=0.03, noise_m=0.003, see_through_m=0.0, origin=ORIGIN)
    seg = segment_floor_ceiling_walls(cloud)
    assert len(seg.walls) == 12
    _check_frames(seg, truth, tol_m=0.03)  # 3 cm point spacing: a wall's end is known to half of it
    # the 12 cm partition gives two walls with opposite normals (A's east face, B's west face)
    part = [w for w in seg.walls if _match(w.frame, truth["walls"]) in (truth["walls"][1], truth["walls"][7])]
    assert len(part) == 2 and np.dot(part[0].frame.normal, part[1].frame.normal) < -0.99
    # the corridor's wall towards the rooms is one 9 m wall despite two doors
    corridor = [w for w in seg.walls if _match(w.frame, truth["walls"]) is truth["walls"][8]]
    assert len(corridor) == 1 and corridor[0].frame.width_m == pytest.approx(9.0, abs=0.02)


def test_no_walls() -> None:
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 5, (20_000, 2))
    xyz = np.vstack([np.column_stack([xy, np.zeros(len(xy))]), np.column_stack([xy, np.full(len(xy), 2.7)])])
    cloud = PointCloud(xyz.astype(np.float32), np.zeros((len(xyz), 3), np.uint8))
    with pytest.raises(NoWallsError, match="no walls found"):
        segment_floor_ceiling_walls(cloud)
    with pytest.raises(NoWallsError, match="no walls found"):
        segment_floor_ceiling_walls(PointCloud(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8)))


def test_l_shaped_room_with_an_outside_corner() -> None:
    """Six walls, one pair meeting at an outside (convex) corner, turned by 30 degrees."""
    outline = rotated([(0, 0), (6, 0), (6, 3), (3, 3), (3, 5), (0, 5)], 30.0, (-4.0, 7.0))
    room = Room(outline, {0: [Hole("door", 2.0, 2.9, 0.0, 2.1)], 3: [Hole("window", 0.8, 2.0, 0.9, 2.1)]})
    cloud, truth = make_scene([room], spacing=0.025, noise_m=0.0025, see_through_m=0.0, origin=ORIGIN)
    seg = segment_floor_ceiling_walls(cloud)
    assert len(seg.walls) == 6
    _check_frames(seg, truth, tol_m=0.025)


def test_nearest_planes_blockwise_equals_all_at_once(monkeypatch):
    """The voxel-to-plane assignment is computed in blocks of voxels (bounded memory for a
    building with many walls); the block size does not change it."""
    from sbsc_core.scene import segmentation as seg

    rng = np.random.default_rng(3)
    xy = rng.uniform(-20, 20, (5000, 2))
    ang = rng.uniform(0, np.pi, 5000)
    nxy = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    pa = rng.uniform(0, np.pi, 40)
    ns = np.stack([np.cos(pa), np.sin(pa)], axis=1)
    ss = rng.uniform(-20, 20, 40)
    best, ok = seg._nearest_planes(xy, nxy, ns, ss, min_cos=0.95, tolerance=0.5)
    dist = np.abs(xy @ ns.T - ss)
    dist[np.abs(nxy @ ns.T) < 0.95] = np.inf
    assert ok.any() and not ok.all()
    assert np.array_equal(ok, dist.min(axis=1) <= 0.5)
    assert np.array_equal(best[ok], np.argmin(dist, axis=1)[ok])
    monkeypatch.setattr(seg, "_PLANE_BLOCK", 77)
    best2, ok2 = seg._nearest_planes(xy, nxy, ns, ss, min_cos=0.95, tolerance=0.5)
    assert np.array_equal(best, best2) and np.array_equal(ok, ok2)


def test_boards_in_front_of_a_wall_do_not_find_it_twice() -> None:
    """Boards a few cm in front of two walls (notice boards, the backs of shelves) make a second
    maximum of the offset histogram beside each wall's own; refitted, it lands on the wall. Each
    wall is found once and keeps all its points (they were shared with a copy of it)."""
    outline = rotated([(0, 0), (9, 0), (9, 5), (0, 5)], 23.5, (2.0, 1.0))
    boards = {0: [Block(u, u + 1.0, 0.9, 2.1, 0.05, (200, 190, 170)) for u in (0.5, 2.2, 3.9, 5.6, 7.3)],
              1: [Block(u, u + 1.0, 0.9, 2.1, 0.06, (90, 90, 90)) for u in (0.5, 2.5)]}
    plain, _ = make_scene([Room(outline)], spacing=0.025, noise_m=0.003, see_through_m=0.0, origin=ORIGIN)
    cloud, truth = make_scene([Room(outline, boards)], spacing=0.025, noise_m=0.003, see_through_m=0.0,
                              origin=ORIGIN)
    seg = segment_floor_ceiling_walls(cloud)
    assert len(seg.walls) == 4
    _check_frames(seg, truth, tol_m=0.025)
    bare = {_match(w.frame, truth["walls"])["edge"]: len(w.point_index) for w in segment_floor_ceiling_walls(plain).walls}
    for w in seg.walls:  # a wall with boards has at least the points of the same wall without them
        assert len(w.point_index) >= 0.98 * bare[_match(w.frame, truth["walls"])["edge"]]


def test_tall_cabinet_fronts_and_door_casings_are_no_walls() -> None:
    """Planes standing in front of a wall and lower than it - the fronts of tall cabinets
    (0.45 m out, 1.9 m high) and a door casing 1.5 cm proud - are furniture or trim, not walls:
    each wall is found once, at its own plane, and keeps the points around them."""
    outline = rotated([(0, 0), (8, 0), (8, 5), (0, 5)], 23.5, (2.0, 1.0))
    cabinets = {0: [Block(1.0, 2.0, 0.0, 1.9, 0.45, (120, 122, 126)), Block(5.0, 5.9, 0.0, 1.95, 0.5, (200, 180, 140))],
                2: [Block(2.0, 2.07, 0.0, 2.17, 0.015, (96, 70, 50)), Block(2.97, 3.04, 0.0, 2.17, 0.015, (96, 70, 50)),
                    Block(2.0, 3.04, 2.1, 2.17, 0.015, (96, 70, 50)), Block(2.3, 2.38, 1.06, 1.14, 0.012, (250, 250, 250)),
                    Block(2.5, 2.86, 2.19, 2.33, 0.05, (30, 160, 60))]}
    cloud, truth = make_scene([Room(outline, cabinets)], spacing=0.02, noise_m=0.003, see_through_m=0.0, origin=ORIGIN)
    seg = segment_floor_ceiling_walls(cloud)
    assert len(seg.walls) == 4
    _check_frames(seg, truth, tol_m=0.02)
    casing_wall = next(w for w in seg.walls if _match(w.frame, truth["walls"])["edge"] == 2)
    fr = casing_wall.frame
    d = (cloud.xyz[casing_wall.point_index] + cloud.origin - fr.origin) @ fr.normal
    assert ((d > 0.035) & (d < 0.065)).sum() > 100  # the exit light above the casing is this wall's
