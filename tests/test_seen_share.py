"""Matches in the shadow of furniture (depth_recognition.SeenShare, ``min_seen_share``).

Real data: crops of simulated all-realism scans (standard seed 6613, alt seed 5501) where depth
alone found a switch or an extinguisher that is not there, with confidences of 0.995-0.998: beside
a shelf and beside a bin, where the wall is seen sparsely through gaps and the mixed pixels of the
furniture's edges scatter relief blobs over it, and on the side of a shelf standing at the wall's
end. Each correlated 0.80-0.81; every real object of those scenes matched in depth correlates at
least 0.84 and lies in a window seen at least 0.85 as densely as its wall.
"""

from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.recognition.depth_recognition import SeenShare, depth_rois, match_depth, seen_share
from sbsc_core.settings import DepthRecognitionSettings
from sbsc_core.types import Box, Orthoimage, WallArea, WallFrame
from tests.depth_crops import PIXEL_M, bundled_templates, depth_crop

DATA = Path(__file__).parent / "data" / "furniture_shadows.npz"
_crop = partial(depth_crop, DATA, at_key="at")  # (orthoimage, wall area, pixel of the object)
CROPS = {"shelf_switch": "switch", "bin_switch": "switch", "shelf_extinguisher": "fire_extinguisher"}


templates = pytest.fixture(scope="module")(bundled_templates)


def _found(ortho, area, templates, s, cid, at, within_px: float = 6.0) -> list:
    tm = {cid: templates[cid]}
    cands = match_depth(ortho, area, depth_rois(ortho, area, s, templates), tm, s)
    return [x for x in cands if np.hypot(x.centre[0] - at[0], x.centre[1] - at[1]) < within_px]


@pytest.mark.parametrize("name", sorted(CROPS))
def test_no_match_in_a_furniture_shadow(templates, name) -> None:
    ortho, area, at = _crop(name)
    s = DepthRecognitionSettings()
    assert not _found(ortho, area, templates, s, CROPS[name], at)
    # the rule is what refuses it: without it the match is there, below foreground_mu_d, in a sparse window
    off = _found(ortho, area, templates, replace(s, min_seen_share=0.0), CROPS[name], at)
    assert off and max(x.score for x in off) < s.foreground_mu_d
    seen = seen_share(ortho, area)
    reach = s.template_pad_px + s.isolation_gap_px + s.isolation_width_px
    best = max(off, key=lambda x: x.score)
    window = Box(best.box.r0 - reach, best.box.c0 - reach, best.box.r1 + reach, best.box.c1 + reach)
    assert seen.of(window) < s.min_seen_share


def _wall(seen: np.ndarray, opening: np.ndarray | None = None, visible: np.ndarray | None = None):
    h, w = seen.shape
    depth = np.where(seen, 0.0, np.nan).astype(np.float32)
    frame = WallFrame(origin=np.zeros(3), axis_u=np.array([1.0, 0.0, 0.0]), axis_v=np.array([0.0, 0.0, 1.0]),
                      normal=np.array([0.0, -1.0, 0.0]), width_m=w * PIXEL_M, height_m=h * PIXEL_M)
    ortho = Orthoimage("W01", frame, PIXEL_M, np.zeros((h, w, 3), np.uint8), depth, seen)
    area = WallArea(visible=np.ones((h, w), bool) if visible is None else visible, openings=[],
                    opening_mask=np.zeros((h, w), bool) if opening is None else opening,
                    wall_colour=np.array([200.0, 200.0, 200.0]))
    return ortho, area


def test_an_objects_own_shadow_is_seen_a_lattice_of_gaps_is_not() -> None:
    seen = np.ones((60, 60), bool)
    seen[10:22, 10:22] = False  # a solid hole enclosed by data: an object's own shadow, a recess
    seen[35:50, 35:50:2] = False  # sampling gaps of a patch seen only through gaps
    seen[0:12, 45:60] = False  # unseen wall reaching the image's border
    s = seen_share(*_wall(seen))
    assert isinstance(s, SeenShare)
    assert s.of(Box(10, 10, 22, 22)) > 0.65  # its interior counts as seen, only its rim does not
    assert s.of(Box(35, 35, 50, 50)) < 0.6
    assert s.of(Box(0, 45, 12, 60)) == 0.0
    assert s.of(Box(24, 24, 34, 34)) == pytest.approx(1.0 / s.wall_share)  # plain wall: denser than the wall overall
    assert s.of(Box(-10, 24, 4, 34)) == pytest.approx(s.of(Box(0, 24, 4, 34)))  # beyond the border: not counted
    assert s.of(Box(70, 70, 80, 80)) == 1.0  # nothing inside the image: no evidence either way
    opening = np.zeros_like(seen)
    opening[24:34, 24:34] = True  # an opening is not seen: no wall there to verify
    assert seen_share(*_wall(seen, opening)).of(Box(24, 24, 34, 34)) == 0.0


def test_seen_share_is_relative_to_the_wall() -> None:
    seen = np.ones((40, 40), bool)
    seen[:, ::2] = False  # a wall sampled on every other column everywhere: half its pixels hold points
    s = seen_share(*_wall(seen, visible=seen.copy()))  # the visible wall is where it has data
    assert s.wall_share == pytest.approx(0.5, abs=0.05)
    assert s.of(Box(10, 10, 30, 30)) == pytest.approx(1.0, abs=0.1)  # no shadow: as dense as its wall
