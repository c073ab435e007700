"""Each storey segmented as if scanned alone, in memory and out of core (issue 12)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sbsc_core.imaging.partition import plan_parts
from sbsc_core.io.ply import write_ply
from sbsc_core.io.scans import read_scans
from sbsc_core.scene.segmentation import (
    find_scan_storeys,
    segment_floor_ceiling_walls,
    segment_storeys,
    storey_bounds,
)
from sbsc_core.scene.storey_samples import storey_cloud, storey_part, storey_steps
from sbsc_core.settings import SegmentationSettings
from sbsc_core.types import PointCloud
from tests.synthetic_rooms import _stack, _two_rooms


def _frames(seg, sid: str | None = None) -> list[tuple]:
    return [(w.id.split("-")[-1], tuple(w.frame.origin), tuple(w.frame.normal), w.frame.width_m, w.frame.height_m)
            for w in seg.walls if sid is None or w.storey == sid]


@pytest.fixture(scope="module")
def storeys() -> tuple[PointCloud, PointCloud]:
    return _stack(*_two_rooms(0.0, (2.90, 2.65), 0)), _stack(*_two_rooms(3.15, (2.60, 2.60), 10))


@pytest.fixture(scope="module")
def storey_files(tmp_path_factory, storeys) -> list[list]:
    """Each storey's points in two PLY files (as two stations): [[S1 files], [S2 files]]."""
    root = tmp_path_factory.mktemp("storeys")
    files = []
    for k, c in enumerate(storeys):
        half = len(c) // 2
        files.append([])
        for j, (a, b) in enumerate(((0, half), (half, len(c)))):
            files[-1].append(root / f"S{k + 1}_{j}.ply")
            write_ply(files[-1][-1], c.world()[a:b], c.rgb[a:b])
    return files


def test_storey_bounds_are_the_middles_of_the_slabs() -> None:
    assert storey_bounds([(0.0, 2.9), (3.15, 5.75), (6.0, 9.0)]) == [
        (-math.inf, 3.025), (3.025, 5.875), (5.875, math.inf)]


def test_a_storey_of_a_building_is_segmented_as_alone(storey_files) -> None:
    """Its walls are those of the storey's own files read alone, bit for bit (each storey in
    its own frame, as a scan of it alone), even where the building's sample would be thinned
    more than the storey's (``fit_max_points`` below the building's points)."""
    building = read_scans(storey_files[0] + storey_files[1])
    s1, s2 = read_scans(storey_files[0]), read_scans(storey_files[1])
    assert not np.array_equal(s1.origin, s2.origin)
    s = SegmentationSettings(fit_max_points=len(s1) // 3)
    assert math.ceil(len(building) / (2 * s.fit_max_points)) > math.ceil(len(s1) / (2 * s.fit_max_points))
    seg = segment_floor_ceiling_walls(building, s)
    assert [st.id for st in seg.storeys] == ["S1", "S2"]
    for sid, alone in (("S1", s1), ("S2", s2)):
        one = segment_floor_ceiling_walls(alone, s)
        assert _frames(seg, sid) == _frames(one)
        st = next(x for x in seg.storeys if x.id == sid)
        assert (st.floor_z, st.ceiling_z) == (one.storeys[0].floor_z, one.storeys[0].ceiling_z)
        # the point indices are into the building's cloud
        off = 0 if sid == "S1" else len(s1)
        for w, a in zip([w for w in seg.walls if w.storey == sid], one.walls, strict=True):
            np.testing.assert_array_equal(w.point_index, a.point_index + off)


def test_storeys_read_again_from_files_are_segmented_as_alone(tmp_path, storey_files) -> None:
    """Out of core: a thinned sample of the building finds the storeys, each storey's points
    are read again from the files at its own density (the same points as the storey's files
    when it would not be thinned alone) and give the walls of the storey alone."""
    files = storey_files[0] + storey_files[1]
    building = read_scans(files)
    origin = building.origin
    parts, total = plan_parts(files, part_points=len(building) // 11)  # several parts per file
    assert total == len(building) and len(parts) > len(files)
    s = SegmentationSettings(fit_max_points=len(building) // 3)  # a storey alone: every point
    sample = PointCloud(building.xyz[::3].copy(), building.rgb[::3].copy(), origin, building.sources)
    limit = 2 * s.fit_max_points
    steps_seen = []

    def again(bounds, shares):
        steps = storey_steps(shares, total, limit)
        steps_seen.append(steps)
        for part in parts:
            storey_part(part, origin, bounds, steps, str(tmp_path), points=0, spilled=False)
        for k in range(len(bounds)):
            yield storey_cloud(tmp_path, parts, k, origin, sources=sample.sources, limit=limit)

    found = find_scan_storeys(sample, s)
    assert found.sample is None and sum(found.shares) == pytest.approx(1.0)
    seg = segment_storeys(found, again, s)
    assert steps_seen == [[1, 1]]
    assert not list(tmp_path.glob("storey*"))  # read back and deleted
    for sid, own in (("S1", storey_files[0]), ("S2", storey_files[1])):
        assert _frames(seg, sid) == _frames(segment_floor_ceiling_walls(read_scans(own), s))
    thin = segment_floor_ceiling_walls(sample, s)  # the building's sample alone gives other walls
    assert _frames(thin, "S1") != _frames(seg, "S1")


def test_storey_part_keeps_every_step_th_point_over_all_files(tmp_path, storeys) -> None:
    s1, s2 = storeys
    both = _stack(s1, s2)
    write_ply(tmp_path / "a.ply", both.world(), both.rgb)
    cloud = read_scans([tmp_path / "a.ply"])
    parts, total = plan_parts([tmp_path / "a.ply"], part_points=len(both) // 7)
    bounds = [(-math.inf, 3.0 - cloud.origin[2]), (3.0 - cloud.origin[2], math.inf)]
    got = [0, 0]
    for part in parts:
        got = [a + b for a, b in zip(got, storey_part(part, cloud.origin, bounds, [1, 3], str(tmp_path), points=0, spilled=False),
                                     strict=True)]
    z = cloud.xyz[:, 2]
    low = np.flatnonzero(z < bounds[0][1])
    high = np.flatnonzero(z >= bounds[1][0])
    high = high[high % 3 == 0]
    assert got == [len(low), len(high)]
    a = storey_cloud(tmp_path, parts, 0, cloud.origin, sources=(),
                     limit=(len(low) + 1) // 2)  # thinned: every 2nd
    np.testing.assert_array_equal(a.xyz, cloud.xyz[low[::2]])
    b = storey_cloud(tmp_path, parts, 1, cloud.origin, sources=(), limit=10**9)
    np.testing.assert_array_equal(b.xyz, cloud.xyz[high])
    np.testing.assert_array_equal(b.rgb, cloud.rgb[high])


def test_detect_scans_reads_each_storey_again_as_alone(tmp_path, storey_files) -> None:
    """The pipeline's storey pass (``pipeline._storey_points``: the parts read again by an
    executor's tasks) gives each storey's walls as the storey's own files do."""
    from concurrent.futures import ThreadPoolExecutor

    from sbsc_core.pipeline.detect import _storey_points
    from sbsc_core.settings import DetectionSettings

    files = storey_files[0] + storey_files[1]
    building = read_scans(files)
    parts, total = plan_parts(files, part_points=len(building) // 7)
    s = DetectionSettings(segmentation=SegmentationSettings(fit_max_points=len(building) // 3))
    sample = PointCloud(building.xyz[::4].copy(), building.rgb[::4].copy(), building.origin, building.sources)
    said: list[str] = []
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    with ThreadPoolExecutor(2) as ex:
        again = _storey_points(ex, parts, [(0, False)] * len(parts), sample.origin,
                               sources=sample.sources, points=total, s=s,
                               scratch=scratch, in_flight=4, log=said.append)
        seg = segment_storeys(find_scan_storeys(sample, s.segmentation), again, s.segmentation)
    assert said and "S1" in said[0] and "(every 1)" in said[0]
    assert not list(scratch.iterdir())
    for sid, own in (("S1", storey_files[0]), ("S2", storey_files[1])):
        alone = read_scans(own)
        assert _frames(seg, sid) == _frames(segment_floor_ceiling_walls(alone, s.segmentation))


def test_a_storey_whose_points_show_two_storeys_keeps_the_levels_given(storeys) -> None:
    """A storey's cloud that holds two storeys (Z ranges not cut at the slab) is segmented on
    the levels and the dense part given, not split again."""
    from sbsc_core.scene.segmentation import segment_storey

    s1, s2 = storeys
    building = _stack(s1, s2)
    z0 = float(building.origin[2])
    whole = segment_floor_ceiling_walls(building)
    st = whole.storeys[0]
    one = segment_storey(building, "S1", (st.floor_z - z0, st.ceiling_z - z0))
    assert [x.id for x in one.storeys] == ["S1"]
    assert (one.storeys[0].floor_z, one.storeys[0].ceiling_z) == pytest.approx((st.floor_z, st.ceiling_z), abs=1e-9)
    assert len(one.walls) == 8 and all(w.id.startswith("S1-W") for w in one.walls)
    assert all(w.frame.origin[2] == pytest.approx(st.floor_z, abs=1e-6) for w in one.walls)
