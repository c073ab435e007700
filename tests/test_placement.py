"""Hits placed on their walls and in 3-D (placement.py)."""

import numpy as np
import pytest

from sbsc_core.errors import SbscError
from sbsc_core.recognition.consensus import ConsensusHit
from sbsc_core.recognition.matching import box_at
from sbsc_core.recognition.templates import make_templates
from sbsc_core.types import Orthoimage, WallFrame
from tests.recognition_synth import synthetic_library


def _ortho(wid: str, origin, axis_u, normal, w_px=400, h_px=300) -> Orthoimage:
    frame = WallFrame(np.asarray(origin, float), np.asarray(axis_u, float), np.array([0.0, 0.0, 1.0]),
                      np.asarray(normal, float), w_px * 0.005, h_px * 0.005)
    return Orthoimage(wid, frame, 0.005, np.zeros((h_px, w_px, 3), np.uint8),
                      np.zeros((h_px, w_px), np.float32), np.ones((h_px, w_px), bool))


def _hit(cls, wall, centre, rot=0, source="depth") -> ConsensusHit:
    return ConsensusHit(cls, wall, centre, 0.5, 0.9 if source != "colour" else None,
                        0.1 if source != "depth" else None, source, box=box_at(centre, 16, 16), rotation_deg=rot)


@pytest.fixture(scope="module")
def templates():
    return make_templates(synthetic_library(), 0.005)


def test_position_against_the_wall_frame(templates) -> None:
    # W02 runs along -Y from (5, 3, 0.1), facing +X
    orthos = {"W02": _ortho("W02", (5.0, 3.0, 0.1), (0.0, -1.0, 0.0), (1.0, 0.0, 0.0))}
    det = place_hits_one(templates, orthos, _hit("socket", "W02", (279.5, 59.5)))
    # centre of pixel (279.5, 59.5): u = 60 * 0.005 = 0.30, v = 1.5 - 280 * 0.005 = 0.10
    assert det.u == pytest.approx(0.30) and det.v == pytest.approx(0.10)
    assert det.position == pytest.approx([5.0, 3.0 - 0.30, 0.1 + 0.10])
    assert det.width_m == pytest.approx(templates["socket"].width_m)
    assert det.source == "depth" and det.rho_depth == 0.9 and det.rho_colour is None
    assert det.to_dict()["class"] == "socket"


def place_hits_one(templates, orthos, hit):
    from sbsc_core.recognition.placement import place_hits

    (det,) = place_hits([hit], orthos, templates)
    return det


def test_rotated_model_exchanges_width_and_height(templates) -> None:
    orthos = {"W01": _ortho("W01", (0, 0, 0), (1, 0, 0), (0, -1, 0))}
    det = place_hits_one(templates, orthos, _hit("arrow", "W01", (100, 100), rot=90))
    assert (det.width_m, det.height_m) == pytest.approx((templates["arrow"].height_m, templates["arrow"].width_m))


def test_ids_by_wall_then_top_to_bottom_then_left_to_right(templates) -> None:
    from sbsc_core.recognition.placement import place_hits

    orthos = {w: _ortho(w, (0, 0, 0), (1, 0, 0), (0, -1, 0)) for w in ("W01", "W02")}
    hits = [_hit("socket", "W02", (10, 10)), _hit("sign", "W01", (200, 50)), _hit("knob", "W01", (20, 300)),
            _hit("panel", "W01", (20, 100))]
    dets = place_hits(hits, orthos, templates)
    assert [d.id for d in dets] == ["D0001", "D0002", "D0003", "D0004"]
    assert [(d.wall_id, d.class_id) for d in dets] == [("W01", "panel"), ("W01", "knob"), ("W01", "sign"), ("W02", "socket")]
    assert [d.id for d in place_hits(hits[::-1], orthos, templates)] == [d.id for d in dets]


def test_unknown_wall_or_class_is_an_error(templates) -> None:
    from sbsc_core.recognition.placement import place_hits

    orthos = {"W01": _ortho("W01", (0, 0, 0), (1, 0, 0), (0, -1, 0))}
    with pytest.raises(SbscError):
        place_hits([_hit("socket", "W09", (1, 1))], orthos, templates)
    with pytest.raises(SbscError):
        place_hits([_hit("nope", "W01", (1, 1))], orthos, templates)
