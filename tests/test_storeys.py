"""Storeys, per-room wall heights, recessed door leaves and stray points (issue 12, items 1-2)."""

from __future__ import annotations

import numpy as np
import pytest

from sbsc_core.errors import InputError, NoWallsError, SbscError
from sbsc_core.scene.segmentation import (
    assign_points_to_walls,
    find_storeys,
    segment_floor_ceiling_walls,
)
from sbsc_core.scene.stray_points import dense_box
from sbsc_core.settings import SegmentationSettings
from sbsc_core.types import PointCloud
from tests.synthetic_rooms import ORIGIN, Block, Hole, Room, _stack, _two_rooms, make_scene


@pytest.fixture(scope="module")
def two_storeys() -> PointCloud:
    """Storey 1: floor 0, rooms 2.90 and 2.65 high; a 0.25 m slab; storey 2: floor 3.15, 2.60 high."""
    return _stack(*_two_rooms(0.0, (2.90, 2.65), 0), *_two_rooms(3.15, (2.60, 2.60), 10))


def test_two_storeys_are_found_with_their_walls(two_storeys: PointCloud) -> None:
    seg = segment_floor_ceiling_walls(two_storeys)
    assert [(st.id, round(st.floor_z, 2), round(st.ceiling_z, 2)) for st in seg.storeys] == [
        ("S1", 0.0, 2.9), ("S2", 3.15, 5.75)]
    assert seg.floor_z == seg.storeys[0].floor_z and seg.ceiling_z == seg.storeys[1].ceiling_z
    for sid, floor in (("S1", 0.0), ("S2", 3.15)):
        walls = [w for w in seg.walls if w.storey == sid]
        assert len(walls) == 8, [w.id for w in walls]  # 4 room-facing walls per room, partition = 2
        assert all(w.id.startswith(f"{sid}-W") for w in walls)
        assert all(w.frame.origin[2] == pytest.approx(floor, abs=0.005) for w in walls)
    assert len({w.id for w in seg.walls}) == 16
    # no point is in two walls, and a wall's points stay in its storey
    z = two_storeys.world()[:, 2]
    for w in seg.walls:
        st = next(s for s in seg.storeys if s.id == w.storey)
        assert st.floor_z < z[w.point_index].min() and z[w.point_index].max() < st.ceiling_z


def test_storeys_joined_by_a_stairwell_are_still_two(two_storeys: PointCloud) -> None:
    # a 2 x 3.5 m stairwell beside the rooms, its walls going on through the slab
    shaft = Room([(8.15, 0), (9.65, 0), (9.65, 2.5), (8.15, 2.5)], {3: [Hole("door", 0.5, 1.4, 0, 2.1)]})
    well = make_scene([shaft], height=5.75, spacing=0.03, noise_m=0.002, see_through_m=0.0, origin=ORIGIN, seed=20)[0]
    cloud = _stack(two_storeys, well)
    seg = segment_floor_ceiling_walls(cloud)
    assert [(st.id, round(st.floor_z, 2), round(st.ceiling_z, 2)) for st in seg.storeys] == [
        ("S1", 0.0, 2.9), ("S2", 3.15, 5.75)]
    assert len([w for w in seg.walls if w.storey == "S1"]) >= 8


def test_one_higher_room_among_lower_ones_is_no_storey_of_its_own() -> None:
    # storey 1: a small room 3.0 m high beside two rooms 2.6 m high; then a slab and storey 2
    rooms = [Room([(0, 0), (2, 0), (2, 3), (0, 3)]), Room([(2.15, 0), (7, 0), (7, 3), (2.15, 3)]),
             Room([(7.15, 0), (12, 0), (12, 3), (7.15, 3)])]
    parts = [make_scene([r], height=h, spacing=0.03, see_through_m=0.0, origin=ORIGIN, seed=30 + i)[0]
             for i, (r, h) in enumerate(zip(rooms, (3.0, 2.6, 2.6), strict=True))]
    parts += [make_scene(rooms, height=2.7, floor_z=3.3, spacing=0.03, see_through_m=0.0, origin=ORIGIN, seed=40)[0]]
    seg = segment_floor_ceiling_walls(_stack(*parts))
    assert [(st.id, round(st.floor_z, 2), round(st.ceiling_z, 2)) for st in seg.storeys] == [
        ("S1", 0.0, 3.0), ("S2", 3.3, 6.0)]
    heights = sorted(round(w.frame.height_m, 2) for w in seg.walls if w.storey == "S1")
    assert heights == [2.6] * 8 + [3.0] * 4


def test_each_wall_takes_the_height_of_its_own_room(two_storeys: PointCloud) -> None:
    seg = segment_floor_ceiling_walls(two_storeys)
    s1 = [w for w in seg.walls if w.storey == "S1"]
    centre_x = [float(w.frame.to_world(w.frame.width_m / 2, 0)[0]) for w in s1]
    for w, x in zip(s1, centre_x, strict=True):
        expected = 2.90 if x < 4.07 else 2.65  # room A (west) or room B (east)
        assert w.frame.height_m == pytest.approx(expected, abs=0.01), (w.id, x, w.frame.height_m)
    # the lower room's ceiling points are no wall points
    z = two_storeys.world()[:, 2]
    for w, x in zip(s1, centre_x, strict=True):
        if x > 4.07:
            assert z[w.point_index].max() < 2.65


def test_one_storey_keeps_plain_ids() -> None:
    cloud = _two_rooms(0.0, (2.7, 2.7), 3)[0]
    seg = segment_floor_ceiling_walls(cloud)
    assert len(seg.storeys) == 1 and [w.id for w in seg.walls] == ["W01", "W02", "W03", "W04"]
    assert {w.storey for w in seg.walls} == {"S1"}


def test_storeys_from_a_subsample_are_the_same(two_storeys: PointCloud) -> None:
    s = SegmentationSettings()
    full = find_storeys(two_storeys.xyz[:, 2], s, two_storeys.xyz[:, :2])
    sub = find_storeys(two_storeys.xyz[::7, 2], s, two_storeys.xyz[::7, :2])
    assert len(full) == len(sub) == 2
    np.testing.assert_allclose(np.asarray(full), np.asarray(sub), atol=0.01)


@pytest.mark.parametrize("depth", [0.05, 0.10])
def test_a_recessed_door_leaf_is_no_wall(depth: float) -> None:
    leaf = Block(1.0, 1.9, 0.0, 2.1, -depth, (150, 110, 80))  # a door leaf set back in its opening
    room = Room([(0, 0), (5, 0), (5, 4), (0, 4)], {0: [leaf]})
    cloud, truth = make_scene([room], height=2.8, spacing=0.025, noise_m=0.002, see_through_m=0.0, origin=ORIGIN)
    rng = np.random.default_rng(0)  # the floor goes on into the door's reveal, up to the leaf
    sill = np.column_stack([rng.uniform(3.1, 4.0, 3000), rng.uniform(-depth, 0, 3000), rng.normal(0, 0.002, 3000)])
    cloud = _with(cloud, sill - np.asarray(ORIGIN))
    seg = segment_floor_ceiling_walls(cloud)
    assert len(seg.walls) == 4  # (a 10 cm recess gave a fifth 0.9 m wall before)
    assert sorted(round(w.frame.width_m, 1) for w in seg.walls) == [4.0, 4.0, 5.0, 5.0]
    # the leaf's points belong to the wall in front of it (the door shows in its depth)
    south = next(w for w in seg.walls if w.frame.normal[1] > 0.99)
    uvd = south.frame.to_uvd(cloud.world()[south.point_index])
    assert (np.abs(uvd[:, 2] + depth) < 0.01).sum() > 1000 or depth > 0.05


def test_assign_points_to_walls_chunk_by_chunk(two_storeys: PointCloud) -> None:
    seg = segment_floor_ceiling_walls(two_storeys)
    whole = assign_points_to_walls(two_storeys.xyz, two_storeys.origin, seg.walls)
    cut = len(two_storeys) // 3
    parts = [assign_points_to_walls(two_storeys.xyz[a:b], two_storeys.origin, seg.walls)
             for a, b in ((0, cut), (cut, len(two_storeys)))]
    for w, idx in enumerate(whole):
        np.testing.assert_array_equal(idx, np.concatenate([parts[0][w], parts[1][w] + cut]))
        # nearly the same points as the segmentation's own assignment
        mine = seg.walls[w].point_index
        assert len(np.intersect1d(idx, mine)) > 0.97 * len(mine)


# --------------------------------------------------------------------------- stray points


@pytest.fixture(scope="module")
def room() -> PointCloud:
    r = Room([(0, 0), (5, 0), (5, 4), (0, 4)], {0: [Hole("door", 1.0, 1.9, 0.0, 2.1)]})
    return make_scene([r], spacing=0.03, noise_m=0.002, see_through_m=0.0, origin=ORIGIN)[0]


def _with(cloud: PointCloud, xyz_rel: np.ndarray) -> PointCloud:
    return PointCloud(np.concatenate([cloud.xyz, np.asarray(xyz_rel, np.float32)]),
                      np.concatenate([cloud.rgb, np.full((len(xyz_rel), 3), 128, np.uint8)]), cloud.origin)


@pytest.mark.parametrize("x", [1e7, 1e38, -3e38])
def test_one_far_point_is_ignored_and_counted(room: PointCloud, x: float) -> None:
    ref = segment_floor_ceiling_walls(room)
    seg = segment_floor_ceiling_walls(_with(room, [[x, 1.0, 1.0]]))
    assert seg.stray_points == 1 and ref.stray_points == 0
    assert [w.id for w in seg.walls] == [w.id for w in ref.walls]
    for a, b in zip(ref.walls, seg.walls, strict=True):
        np.testing.assert_array_equal(a.point_index, b.point_index)


def test_scattered_points_up_to_10_km_change_nothing(room: PointCloud) -> None:
    rng = np.random.default_rng(5)
    k = len(room) // 1000  # 0.1 %
    far = rng.uniform(-10_000, 10_000, (k, 3))
    seg = segment_floor_ceiling_walls(_with(room, far))
    ref = segment_floor_ceiling_walls(room)
    assert seg.stray_points == k
    for a, b in zip(ref.walls, seg.walls, strict=True):
        np.testing.assert_array_equal(a.point_index, b.point_index)
        np.testing.assert_allclose(a.frame.origin, b.frame.origin)


def test_a_dense_part_kilometres_wide_is_refused_in_one_line() -> None:
    # like laspy's sample LAS: 1,065 points over 3.4 x 4.6 km
    rng = np.random.default_rng(0)
    xyz = rng.uniform([0, 0, 0], [3400, 4600, 30], (1065, 3)).astype(np.float32)
    cloud = PointCloud(xyz, np.zeros((1065, 3), np.uint8), sources=("simple.las",))
    with pytest.raises(InputError, match=r"^simple\.las: no dense part"):
        segment_floor_ceiling_walls(cloud)
    # dense but 3 km long: a town, not a building
    x = np.repeat(np.arange(0, 3000, 0.5), 40)
    big = np.column_stack([x, rng.uniform(0, 1, len(x)), rng.uniform(0, 3, len(x))]).astype(np.float32)
    with pytest.raises(InputError, match=r"spans 3\.0 x .* km, more than the 2 km") as exc:
        dense_box(big, where="town.ply")
    assert "\n" not in str(exc.value)


def test_far_points_in_files_read_and_segment(tmp_path, room: PointCloud) -> None:
    from sbsc_core.io.ply import write_ply
    from sbsc_core.io.scans import read_scans

    world = room.world()
    world[0] = [1e7, 1e7, 1e7]  # the first point of the file is the stray one
    write_ply(tmp_path / "scan.ply", world, room.rgb)
    cloud = read_scans([tmp_path / "scan.ply"])
    assert np.abs(cloud.origin).max() < 10  # the origin is not pulled away by the stray point
    seg = segment_floor_ceiling_walls(cloud)
    assert seg.stray_points == 1 and len(seg.walls) == 4


def test_no_storey_is_no_walls() -> None:
    rng = np.random.default_rng(1)
    xyz = rng.normal(0, 0.002, (20_000, 3)).astype(np.float32) + np.float32([0, 0, 0])
    xyz[:, :2] = rng.uniform(0, 5, (20_000, 2))
    with pytest.raises(SbscError):
        segment_floor_ceiling_walls(PointCloud(xyz, np.zeros((len(xyz), 3), np.uint8)))
    with pytest.raises(NoWallsError):
        find_storeys(np.zeros(1000, np.float32))


# --------------------------------------------------------------------------- end to end


@pytest.fixture(scope="module")
def small_scan(tmp_path_factory):
    from sbsc_core.paths import sample_projects_dir
    from sbsc_core.simulate.scenarios import simulate_scene

    out = tmp_path_factory.mktemp("stray") / "scan"
    simulate_scene(sample_projects_dir() / "one_room.yaml", out, seed=2, angular_step_deg=0.2, design=False)
    return out


@pytest.mark.slow
def test_detections_with_01_percent_of_points_scattered_10_km_away_are_the_same(small_scan) -> None:
    from sbsc_core.io.models import load_model_library
    from sbsc_core.io.scans import read_scans
    from sbsc_core.pipeline.detect import detect
    from sbsc_core.settings import DetectionSettings

    cloud = read_scans([small_scan / "scan.ply"])
    library = load_model_library(small_scan / "models")
    s = DetectionSettings(workers=1)
    ref = detect(cloud, library, settings=s)
    rng = np.random.default_rng(7)
    k = len(cloud) // 1000
    far = _with(cloud, rng.uniform(-10_000, 10_000, (k, 3)))
    got = detect(far, library, settings=s)
    assert got.segmentation.stray_points == k and ref.segmentation.stray_points == 0
    assert len(ref.detections) >= 10
    assert [(d.class_id, d.wall_id) for d in got.detections] == [(d.class_id, d.wall_id) for d in ref.detections]
    for a, b in zip(ref.detections, got.detections, strict=True):
        np.testing.assert_allclose(a.position, b.position, atol=1e-4)


@pytest.mark.slow
def test_a_sparse_las_spanning_kilometres_is_refused_in_one_line(tmp_path, capsys) -> None:
    import laspy

    from sbsc_core.cli import main
    from sbsc_core.paths import bundled_models_dir

    rng = np.random.default_rng(3)  # like laspy's simple.las: 1,065 points over 3.4 x 4.6 km
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = [0.01, 0.01, 0.01]
    header.offsets = [635_000.0, 848_000.0, 400.0]
    las = laspy.LasData(header)
    las.x = 635_000 + rng.uniform(0, 3400, 1065)
    las.y = 848_000 + rng.uniform(0, 4600, 1065)
    las.z = 400 + rng.uniform(0, 80, 1065)
    las.red = las.green = las.blue = rng.integers(0, 65535, 1065)
    las.write(tmp_path / "simple.las")
    rc = main(["-q", "detect", str(tmp_path / "simple.las"), "--models", str(bundled_models_dir()),
               "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "simple.las: no dense part" in err, err
    assert not (tmp_path / "out" / "detections.json").exists()


def test_each_storey_keeps_its_own_expected_counts() -> None:
    """With per-storey counts (contract 3's ``storeys``) a storey whose candidates are weaker is
    not starved by another storey's: each storey takes its own count, as when scanned alone."""
    from sbsc_core.io.documents import ExpectedCounts
    from sbsc_core.pipeline.detect import consensus_by_storey, storey_counts
    from sbsc_core.recognition.consensus import consensus_all
    from sbsc_core.recognition.matching import box_at
    from sbsc_core.settings import DetectionSettings
    from sbsc_core.types import Candidate, Segmentation, Storey, Wall, WallFrame

    def cand(source: str, wall: str, col: float, score: float) -> Candidate:
        return Candidate("switch", wall, source, box_at((50.0, col), 16, 16), (50.0, col), score)

    # S1: one switch found in depth only (alpha 0.5); S2: two found in both (alpha 1), one of them not in the design
    depth = [cand("depth", "S1-W01", 40, 0.85), cand("depth", "S2-W01", 40, 0.95), cand("depth", "S2-W01", 140, 0.95)]
    colour = [cand("colour", "S2-W01", 40, 0.05), cand("colour", "S2-W01", 140, 0.05)]
    frame = WallFrame(origin=np.zeros(3), axis_u=np.array([1.0, 0, 0]), axis_v=np.array([0, 0, 1.0]),
                      normal=np.array([0, 1.0, 0]), width_m=4.0, height_m=2.8)
    seg = Segmentation(0.0, 5.9, [Wall(f"{sid}-W01", frame, np.zeros(0, np.int64), sid) for sid in ("S1", "S2")],
                       [Storey("S1", 0.0, 2.8), Storey("S2", 3.1, 5.9)])
    s = DetectionSettings()
    per_storey = ExpectedCounts({"switch": 2}, {"S1": {"switch": 1}, "S2": {"switch": 1}})
    counts = storey_counts(seg, per_storey)
    assert counts == {"S1": {"switch": 1}, "S2": {"switch": 1}}
    def run(d: list, c: list, n: dict) -> list:
        return consensus_all(d, c, n, s.consensus, ["switch"])["switch"]

    hits = consensus_by_storey(depth, colour, {"S1-W01": "S1", "S2-W01": "S2"}, counts=counts,
                               classes=["switch"], run=run)
    assert sorted(h.wall_id for h in hits) == ["S1-W01", "S2-W01"]
    # the building's counts alone: both places go to S2's stronger candidates
    assert [h.wall_id for h in consensus_all(depth, colour, {"switch": 2}, s.consensus, ["switch"])["switch"]] == [
        "S2-W01", "S2-W01"]
    # storeys that do not match the scan's: the building's counts, and a warning naming both
    said: list[str] = []
    assert storey_counts(seg, ExpectedCounts({"switch": 2}, {"S1": {"switch": 2}}), said.append) is None
    assert said and "S1" in said[0] and "S1, S2" in said[0]
    assert storey_counts(Segmentation(0.0, 2.8, seg.walls[:1], seg.storeys[:1]), per_storey) is None


def test_a_floor_level_spread_over_two_bins_still_separates_the_storeys() -> None:
    """Range noise and registration error spread a storey's floor over two bins of the Z histogram,
    neither of which holds ``slab_level_factor`` x the median; the two together do."""
    s = SegmentationSettings()
    b = s.storey_bin_m
    per_bin = 1000

    def walls(z0: float, z1: float) -> np.ndarray:  # a uniform band: per_bin points per bin
        n = int(round((z1 - z0) / b))
        return np.repeat(z0 + (np.arange(n) + 0.5) * b, per_bin)

    ceiling_1, floor_2 = 2.80, 3.04  # a 0.24 m slab between them
    level = int(s.slab_level_factor * per_bin)
    z = np.concatenate([
        np.zeros(2 * level),  # storey 1's floor, in one bin
        walls(0.0, ceiling_1), np.full(2 * level, ceiling_1 - 0.005),  # its walls and ceiling
        np.full(level * 7 // 10, floor_2 - 0.005), np.full(level * 7 // 10, floor_2 + 0.005),  # split floor
        walls(floor_2, 5.74), np.full(2 * level, 5.735),
    ])
    storeys = find_storeys(z, s)
    assert len(storeys) == 2
    np.testing.assert_allclose(storeys, [(0.0, ceiling_1), (floor_2, 5.74)], atol=0.011)
