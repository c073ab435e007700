"""Possible misses: candidates the consensus did not keep, merged and away from detections."""

from __future__ import annotations

import numpy as np

from sbsc_core.recognition.suggestions import possible_misses
from sbsc_core.types import Box, Candidate, Detection, Orthoimage, WallFrame

PX = 0.005


def ortho() -> Orthoimage:
    f = WallFrame(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), np.array([0, 1.0, 0]), 4.0, 2.5)
    h, w = 500, 800
    return Orthoimage("W01", f, PX, np.zeros((h, w, 3), np.uint8), np.zeros((h, w), np.float32),
                      np.ones((h, w), bool))


def cand(cls: str, source: str, r: float, c: float, score: float) -> Candidate:
    return Candidate(cls, "W01", source, Box(int(r) - 8, int(c) - 8, int(r) + 8, int(c) + 8), (r, c), score)


def test_not_kept_candidates_are_offered_once_per_place_and_never_on_a_detection():
    o = ortho()
    det = Detection("D0001", "switch", "W01", u=(100 + 0.5) * PX, v=2.5 - (200 + 0.5) * PX, position=np.zeros(3),
                    width_m=0.08, height_m=0.08, alpha=0.9, rho_depth=0.9, rho_colour=0.1, source="both")
    cands = [cand("switch", "depth", 200, 100, 0.95),  # the kept detection itself
             cand("socket_x1", "depth", 202, 101, 0.8),  # another class on the kept object
             cand("socket_x1", "depth", 300, 500, 0.78),  # a possible miss ...
             cand("socket_x1", "colour", 302, 502, 0.3),  # ... seen in colour too
             cand("switch", "colour", 100, 700, 0.3)]  # another possible miss
    out = possible_misses({"W01": o}, cands, [det])
    assert [(s["class"], s["source"]) for s in out] == [("socket_x1", "both"), ("switch", "colour")]
    s = out[0]
    assert (s["u"], s["v"]) == (round((500 + 0.5) * PX, 4), round(2.5 - (300 + 0.5) * PX, 4))
    assert s["width_m"] == 0.08 and s["score"] == 0.78 and s["reason"] == "not_kept_by_consensus"
    assert possible_misses({"W01": o}, cands, [det], max_per_wall=1) == out[:1]
