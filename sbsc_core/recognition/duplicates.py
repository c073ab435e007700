"""One object found twice, on two surfaces that are the same plane.

Segmentation may cut one wall into pieces that overlap along it (a short extra segment of
a long corridor wall, fitted to part of the same plane on a noisy scan); an object in the
overlap is then in both walls' orthoimages and each wall's consensus finds it. The
consensus (paper, section 4.4) keeps one object per place on a wall (``suppress_overlap``,
intersection over the smaller footprint); this module applies the same rule across walls
that are one plane: two hits whose footprints overlap by more than ``overlap`` in the
common plane, on surfaces facing the same way within ``plane_m`` of each other, are one
object, and only the better one is kept (confidence, then the kind of evidence, then
alpha). Two faces of a partition wall face opposite ways, so objects back to back on them
are both kept.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..types import WallFrame, pixel_to_uv
from .consensus import ConsensusHit

_SAME_FACING_COS = float(np.cos(np.deg2rad(10.0)))  # normals within 10 degrees face the same way
_EVIDENCE = {"both": 2, "depth": 1, "colour": 0}


def _footprint(hit: ConsensusHit, frame: WallFrame, pixel_m: float) -> tuple[np.ndarray, float, float]:
    """World centre and footprint size (width, height, metres) of a hit on its wall."""
    u, v = pixel_to_uv(frame, pixel_m, *hit.centre)
    box = hit.box
    w, h = (0.0, 0.0) if box is None else (box.width * pixel_m, box.height * pixel_m)
    return np.asarray(frame.to_world(float(u), float(v), 0.0), float).reshape(3), w, h


def _rank(hit: ConsensusHit) -> tuple[float, int, float]:
    return (-1.0 if hit.confidence is None else float(hit.confidence), _EVIDENCE.get(hit.source, 0), float(hit.alpha))


def cross_surface_duplicates(hits: list[ConsensusHit], frames: Mapping[str, tuple[WallFrame, float]], *,
                             overlap: float, plane_m: float = 0.05) -> list[ConsensusHit]:
    """The hits that repeat a better hit of another wall of the same plane (see the module).

    Parameters
    ----------
    hits
        Consensus hits of all walls (with their ``confidence`` when there is one).
    frames
        Wall id -> (frame, pixel size in metres) of each wall's orthoimage. Hits on a wall
        not listed, or whose frame is not a plane (no ``normal``), are never duplicates.
    overlap
        Two footprints overlapping by more than this (intersection over the smaller, in the
        plane) are one place: the consensus's ``suppress_overlap``.
    plane_m
        Two walls whose planes lie this close along their normal at the hit are one plane.

    Returns
    -------
    list of ConsensusHit
        The weaker hit of every such pair (each at most once), in the order of ``hits``.
    """
    placed = []
    for h in hits:
        fr = frames.get(h.wall_id)
        if fr is None or h.box is None or getattr(fr[0], "normal", None) is None:
            continue
        centre, w, ht = _footprint(h, fr[0], fr[1])
        placed.append((h, fr[0], centre, w, ht))
    drop: set[int] = set()
    order = sorted(range(len(placed)), key=lambda i: _rank(placed[i][0]), reverse=True)
    for a_pos, i in enumerate(order):
        if id(placed[i][0]) in drop:
            continue
        a, fa, ca, wa, ha = placed[i]
        for j in order[a_pos + 1:]:
            b, fb, cb, wb, hb = placed[j]
            if b.wall_id == a.wall_id or id(b) in drop:
                continue
            if float(np.linalg.norm(cb - ca)) > max(wa, ha, wb, hb):  # far apart: the footprints cannot overlap
                continue
            if float(np.dot(fa.normal, fb.normal)) < _SAME_FACING_COS:
                continue
            du, dv, dd = (fa.to_uvd(cb[None, :])[0] - fa.to_uvd(ca[None, :])[0])
            if abs(dd) > plane_m:
                continue
            iu = max(0.0, min(wa, wb, (wa + wb) / 2 - abs(du)))
            iv = max(0.0, min(ha, hb, (ha + hb) / 2 - abs(dv)))
            smaller = min(wa * ha, wb * hb)
            if smaller > 0 and iu * iv / smaller > overlap:
                drop.add(id(b))
    return [h for h in hits if id(h) in drop]
