"""One object seen on two overlapping pieces of a wall (duplicates.py, confidence.screened_consensus)."""

from __future__ import annotations

import numpy as np

from sbsc_core.recognition.confidence import screened_consensus
from sbsc_core.recognition.consensus import make_hit
from sbsc_core.recognition.duplicates import cross_surface_duplicates
from sbsc_core.settings import ConfidenceSettings, ConsensusSettings
from sbsc_core.types import Box, Candidate, WallFrame

PIXEL_M = 0.01


def _frame(x0: float, x1: float, y: float = 8.6, facing: float = 1.0) -> WallFrame:
    """A vertical wall from x0 to x1 at y, 3 m high, facing +y (facing 1) or -y (-1)."""
    axis_u = np.array([np.sign(x1 - x0), 0.0, 0.0])
    normal = np.array([0.0, facing, 0.0])
    axis_v = np.array([0.0, 0.0, 1.0])
    return WallFrame(np.array([x0, y, 0.0]), axis_u, axis_v, normal, abs(x1 - x0), 3.0)


def _pixel(frame: WallFrame, x: float, z: float) -> tuple[float, float]:
    u, v, _ = frame.to_uvd(np.array([[x, frame.origin[1], z]]))[0]
    return frame.height_m / PIXEL_M - 0.5 - v / PIXEL_M, u / PIXEL_M - 0.5


def _cand(cid: str, wall: str, frame: WallFrame, x: float, z: float, score: float, source: str = "depth") -> Candidate:
    r, c = _pixel(frame, x, z)
    return Candidate(cid, wall, source, Box(int(r) - 15, int(c) - 10, int(r) + 15, int(c) + 10), (r, c), score)


def test_the_weaker_of_two_hits_of_one_place_on_one_plane_is_the_duplicate() -> None:
    long, short = _frame(22.65, 0.25), _frame(18.7, 20.56)  # a corridor wall and a piece of it, as segmented
    strong = make_hit(_cand("sign", "W18", long, 19.65, 1.95, 0.95), None, 0.5)
    strong.confidence = 0.92
    weak = make_hit(_cand("sign", "W19", short, 19.655, 1.95, 0.9), None, 0.5)
    weak.confidence = 0.68
    elsewhere = make_hit(_cand("sign", "W19", short, 20.2, 1.95, 0.9), None, 0.5)
    frames = {"W18": (long, PIXEL_M), "W19": (short, PIXEL_M)}
    assert cross_surface_duplicates([weak, strong, elsewhere], frames, overlap=0.25) == [weak]
    # the other face of a partition wall, 0.15 m behind, faces the other way: objects back to back stay
    back = _frame(0.25, 22.65, y=8.45, facing=-1.0)
    behind = make_hit(_cand("sign", "W20", back, 19.65, 1.95, 0.9), None, 0.5)
    frames["W20"] = (back, PIXEL_M)
    assert cross_surface_duplicates([strong, behind], frames, overlap=0.25) == []
    # a wall not in ``frames`` is never compared
    assert cross_surface_duplicates([strong, weak], {"W18": (long, PIXEL_M)}, overlap=0.25) == []


def test_screened_consensus_drops_the_duplicate_and_it_spends_no_count() -> None:
    """Two signs expected: the one seen on both pieces of the wall counts once and the count
    goes to the second sign; without frames the duplicate takes the count."""
    long, short = _frame(22.65, 0.25), _frame(18.7, 20.56)
    frames = {"W18": (long, PIXEL_M), "W19": (short, PIXEL_M)}
    seen_twice = [_cand("sign", "W18", long, 19.65, 1.95, 0.97), _cand("sign", "W19", short, 19.65, 1.95, 0.96)]
    other = _cand("sign", "W18", long, 5.0, 1.95, 0.90)
    off = ConfidenceSettings(enabled=False)
    free = screened_consensus(seen_twice + [other], [], None, ["sign"],
                              consensus_settings=ConsensusSettings(), settings=off, frames=frames)
    assert sorted(h.wall_id for h in free) == ["W18", "W18"]
    counted = screened_consensus(seen_twice + [other], [], {"sign": 2}, ["sign"],
                                 consensus_settings=ConsensusSettings(), settings=off,
                                 frames=frames)
    assert sorted(round(h.centre[1]) for h in counted) == sorted(round(_pixel(long, x, 1.95)[1]) for x in (19.65, 5.0))
    plain = screened_consensus(seen_twice + [other], [], {"sign": 2}, ["sign"],
                               consensus_settings=ConsensusSettings(), settings=off)
    assert sorted(h.wall_id for h in plain) == ["W18", "W19"]
