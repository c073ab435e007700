"""Fast checks of scan differences another simulator / a real scanner produce (see
benchmarks/bench_robustness.py for the full one_room benchmark).

The two floor / ceiling cases were failures of ``find_floor_ceiling`` when it took the two
largest Z-histogram maxima (a table top outvoted the floor; door heads became the ceiling).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.scene.segmentation import find_floor_ceiling

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


def _levels(rng: np.random.Generator, parts: list[tuple[float, int]],
            spreads: list[tuple[float, float, int]]) -> np.ndarray:
    """Z values: horizontal levels (z, points) with 1 mm noise plus points spread
    uniformly over (z0, z1, points): walls, the sides of furniture."""
    z = [lvl + rng.normal(0.0, 0.001, n) for lvl, n in parts]
    z += [rng.uniform(z0, z1, n) for z0, z1, n in spreads]
    return rng.permutation(np.concatenate(z))


def test_floor_is_the_lowest_level_under_a_table():
    # the Z histogram of one_room with furniture (2 cm bins): ceiling 1.63 M points, floor
    # 181 k (the scanner's blind cone hides the floor near each station), table top 150 k at
    # 0.75 m and cabinet top 105 k at 0.90 m over ~36 k points per bin of walls and furniture
    # sides there (10 k per bin near the floor)
    z = _levels(np.random.default_rng(1), [(0.0, 181_000), (0.75, 150_000), (0.903, 105_000), (2.8, 1_630_000)],
                [(0.0, 2.8, 1_400_000), (0.55, 0.95, 520_000)])
    floor, ceiling = find_floor_ceiling(z)
    assert abs(floor) < 0.01 and abs(ceiling - 2.8) < 0.01


def test_no_ceiling_points_keeps_the_walls_whole():
    """A 4 x 3 m room scanned without its ceiling: the door and window heads at 2.1 m are a
    level of a few thin strips, not a ceiling; the walls end at the top of the cloud."""
    rng = np.random.default_rng(2)
    floor_xy = rng.uniform((0, 0), (4, 3), (1_000_000, 2))
    heads_xy = np.concatenate([rng.uniform((1.0, 0.0), (1.9, 0.1), (30_000, 2)),   # door head
                               rng.uniform((1.4, 2.9), (2.6, 3.0), (30_000, 2))])  # window head
    t = rng.uniform(0, 14, 1_500_000)  # walls: along the perimeter
    wall_xy = np.where(t[:, None] < 4, np.c_[t, 0 * t], np.where(t[:, None] < 7, np.c_[4 + 0 * t, t - 4],
                       np.where(t[:, None] < 11, np.c_[11 - t, 3 + 0 * t], np.c_[0 * t, 14 - t])))
    z = np.concatenate([rng.normal(0.0, 0.001, 1_000_000), rng.normal(2.1, 0.001, 60_000),
                        rng.uniform(0.0, 2.75, 1_500_000)])
    xy = np.concatenate([floor_xy, heads_xy, wall_xy])
    floor, ceiling = find_floor_ceiling(z, xy=xy)
    assert abs(floor) < 0.01 and ceiling > 2.7
    # by Z alone the heads are the highest level
    assert find_floor_ceiling(z)[1] == pytest.approx(2.1, abs=0.01)


def test_rigid_truth_transform_keeps_geometry():
    from bench_robustness import UTM, _rz, _transform_truth

    truth = {"objects": [{"class": "a", "position": [1.0, 2.0, 0.3], "normal": [0.0, -1.0, 0.0]},
                         {"class": "b", "position": [3.0, 0.0, 1.1], "normal": [1.0, 0.0, 0.0]}],
             "walls": [{"origin": [0.0, 3.0, 0.0], "axis_u": [1.0, 0.0, 0.0], "axis_v": [0.0, 0.0, 1.0],
                        "normal": [0.0, -1.0, 0.0]}]}
    rot = _rz(30.0)
    out = _transform_truth(truth, rot, UTM)
    p = np.array([o["position"] for o in out["objects"]])
    q = np.array([o["position"] for o in truth["objects"]])
    assert np.linalg.norm(p[0] - p[1]) == pytest.approx(np.linalg.norm(q[0] - q[1]), abs=1e-9)
    assert p[0] == pytest.approx(rot @ q[0] + UTM)
    assert out["objects"][0]["normal"] == pytest.approx([0.5, -np.sqrt(3) / 2, 0.0])
    assert truth["objects"][0]["position"] == [1.0, 2.0, 0.3]  # the input is left alone


def test_variants_are_unique_and_described():
    from bench_robustness import VARIANTS

    names = [v.name for v in VARIANTS]
    assert len(names) == len(set(names))
    assert all(v.what and (v.kind == "sim" or v.derive is not None or v.name == "baseline") for v in VARIANTS)
