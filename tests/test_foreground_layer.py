"""Objects beside furniture in front of the wall (depth_recognition.foreground_source, model_view).

Real data: crops of a simulated all-realism scan (standard design family, seed 6613) where a fully
visible socket stands just below a desk's modesty panel, between a desk's legs and beside a bin.
The panel, the legs and the bin stand within the wall's depth band and make one RoI with the
socket; their relief filled the socket's correlation window and its isolation strips.
"""

from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.recognition.depth_recognition import (
    depth_rois,
    foreground_regions,
    foreground_source,
    match_depth,
    model_view,
)
from sbsc_core.settings import DepthRecognitionSettings
from tests.depth_crops import bundled_templates, depth_crop

DATA = Path(__file__).parent / "data" / "furniture_sockets.npz"
_crop = partial(depth_crop, DATA, at_key="socket")  # (orthoimage, wall area, pixel of the object)
CROPS = {"desk_panel": "socket_x2", "desk_legs": "socket_x1", "bin": "socket_x1"}
SOCKETS = ("socket_x1", "socket_x2", "socket_x4", "switch", "builtin_socket")


templates = pytest.fixture(scope="module")(bundled_templates)


def _found(ortho, area, templates, s, cid, at, within_px: float = 3.0) -> list:
    cands = match_depth(ortho, area, depth_rois(ortho, area, s, templates), templates, s)
    return [x for x in cands if x.class_id == cid and np.hypot(x.centre[0] - at[0], x.centre[1] - at[1]) < within_px]


@pytest.mark.parametrize("name", sorted(CROPS))
def test_a_socket_beside_furniture_is_matched(templates, name) -> None:
    ortho, area, at = _crop(name)
    s = DepthRecognitionSettings()
    rois = depth_rois(ortho, area, s, templates)
    # the furniture and the socket are one RoI much larger than the socket
    roi = next(b for b in rois if b.r0 <= at[0] < b.r1 and b.c0 <= at[1] < b.c1)
    assert roi.height * roi.width > 10 * templates[CROPS[name]].height_px * templates[CROPS[name]].width_px
    best = max(_found(ortho, area, templates, s, CROPS[name], at), key=lambda x: x.score)
    assert best.score > 0.9
    assert np.hypot(best.centre[0] - at[0], best.centre[1] - at[1]) < 1.5
    # a larger model does not match it with its rest hidden behind the furniture (its footprint must be seen)
    larger = {"socket_x1": ("socket_x2", "socket_x4"), "socket_x2": ("socket_x4",)}[CROPS[name]]
    for cid in larger:
        assert not _found(ortho, area, templates, s, cid, at, 10.0), cid
    # without the depth layers (the paper's RoI step) the furniture hides it
    assert not _found(ortho, area, templates, replace(s, foreground_factor=0.0), CROPS[name], at)


@pytest.mark.parametrize("name", sorted(CROPS))
def test_furniture_itself_yields_no_socket_like_match(templates, name) -> None:
    """Only the socket: nothing on the panel, the legs, the bin or their edges."""
    ortho, area, at = _crop(name)
    s = DepthRecognitionSettings()
    cands = match_depth(ortho, area, depth_rois(ortho, area, s, templates), templates, s)
    far = [x for x in cands if np.hypot(x.centre[0] - at[0], x.centre[1] - at[1]) > 8]
    assert not [x for x in far if x.class_id in SOCKETS], far


def test_foreground_takes_the_edge_of_a_panel_down_to_the_wall() -> None:
    """A panel 6 cm deep whose lower edge ramps down (mixed pixels) onto a socket 1 cm deep."""
    col = np.array([0.06] * 6 + [0.045, 0.03, 0.018, 0.0115] + [0.011] * 6 + [0.0] * 6, np.float32)
    relief = np.repeat(col[:, None], 5, axis=1)
    src = foreground_source(relief, 0.0012, 8)
    deep = src > 0.036  # 3 x the socket's 12 mm
    assert deep[:10].all()  # the panel and its ramp
    assert not deep[10:].any()  # the socket (a level stretch) and the wall stay
    view = model_view(relief, np.ones_like(deep), foreground_regions(src, relief, 0.036), 35)
    assert (view.image[:10] == 0).all() and not view.known[:10].any() and view.known[10:].all()
    assert foreground_regions(src, relief, 0.1) is None  # a deep model: nothing in front
    # a region with fewer pixels beyond the limit (7 x 5 here) than the model's footprint is no furniture
    assert model_view(relief, np.ones_like(deep), foreground_regions(src, relief, 0.036), 36).known.all()
