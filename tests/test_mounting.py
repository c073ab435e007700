"""Candidates that cannot be mounted on their wall (mounting.py)."""

import numpy as np

from sbsc_core.recognition.matching import box_at
from sbsc_core.recognition.mounting import within_wall_height
from sbsc_core.settings import ConsensusSettings
from sbsc_core.types import Candidate, Orthoimage, WallFrame

PX = 0.005


def _ortho(wid: str, height_m: float = 3.0, width_m: float = 4.0) -> Orthoimage:
    h, w = round(height_m / PX), round(width_m / PX)
    frame = WallFrame(np.zeros(3), np.array([1.0, 0, 0]), np.array([0.0, 0, 1]), np.array([0.0, -1, 0]),
                      width_m, height_m)
    return Orthoimage(wid, frame, PX, np.zeros((h, w, 3), np.uint8), np.zeros((h, w), np.float32),
                      np.ones((h, w), bool))


def _at(ortho: Orthoimage, cls: str, u: float, v: float, w_m: float, h_m: float, wall: str | None = None) -> Candidate:
    r, c = ortho.uv_to_pixel(u, v)
    box = box_at((float(r), float(c)), round(h_m / PX), round(w_m / PX))
    return Candidate(cls, wall or ortho.wall_id, "depth", box, (float(r), float(c)), 0.9)


def test_a_footprint_reaching_into_the_floor_or_above_the_top_is_not_on_the_wall() -> None:
    wall = _ortho("W01")
    margin = ConsensusSettings().mount_margin_m
    on_wall = [
        _at(wall, "fire_extinguisher", 1.0, 1.2, 0.2, 0.6),  # hung at 1.2 m
        _at(wall, "radiator", 2.0, 0.31, 0.8, 0.6),  # standing 1 cm above the floor
        _at(wall, "socket_x1", 3.0, 0.04, 0.08, 0.08),  # a skirting socket, touching the floor
        _at(wall, "smoke_detector", 3.5, 2.94, 0.1, 0.1),  # just under the ceiling
    ]
    off_wall = [
        _at(wall, "fire_extinguisher", 2.5, 0.21, 0.2, 0.6),  # a waste bin on the floor, seen as a 0.6 m model
        _at(wall, "exit_light", 1.5, 2.99, 0.36, 0.14),  # half above the wall's top
    ]
    other = _at(wall, "fire_extinguisher", 2.5, 0.21, 0.2, 0.6, wall="W02")  # no orthoimage given: kept
    kept = within_wall_height(on_wall + off_wall + [other], {"W01": wall}, margin_m=margin)
    assert kept == on_wall + [other]
    # the margin is the only slack: without it a footprint touching a level is still on the wall ...
    assert within_wall_height(on_wall[2:3], {"W01": wall}, margin_m=0.0) == on_wall[2:3]
    # ... and the bin passes the floor by 9 cm: a margin that large would keep it
    assert within_wall_height(off_wall[:1], {"W01": wall}, margin_m=0.1) == off_wall[:1]


def test_a_parked_orthoimage_without_its_images_gives_the_same() -> None:
    """The consensus runs on parked walls (pipeline.park_wall): frame and pixel size only."""
    wall = _ortho("W01")
    parked = Orthoimage("W01", wall.frame, PX, np.zeros((0, 0, 3), np.uint8), np.zeros((0, 0), np.float32),
                        np.zeros((0, 0), bool))
    cands = [_at(wall, "fire_extinguisher", 1.0, 1.2, 0.2, 0.6), _at(wall, "fire_extinguisher", 2.5, 0.21, 0.2, 0.6)]
    margin = ConsensusSettings().mount_margin_m
    assert within_wall_height(cands, {"W01": parked}, margin_m=margin) == cands[:1]
