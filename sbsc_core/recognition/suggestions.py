"""Possible misses: candidates the recognizers found but the consensus did not keep.

Every depth candidate passed rho_D >= mu_D and every colour candidate passed the colour
descriptor test (paper, sections 4.2 and 4.3); the consensus (section 4.4) then keeps those
that are coherent enough and within the expected counts. What it drops is still evidence: a
reviewer looking for what recognition missed starts there. This module lists them, one per
place and class, away from every kept detection, strongest first; ``sbsc detect`` writes
them to ``suggestions.json``::

    {"schema": "sbsc.suggestions/1",
     "suggestions": [{"class", "wall", "u", "v", "width_m", "height_m",
                      "source": "depth" | "colour" | "both", "score", "reason"}]}

``score`` is rho_D (higher is better) for depth and rho_C (lower is better) for colour.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..types import Candidate, Detection, Orthoimage

SCHEMA = "sbsc.suggestions/1"
MAX_PER_WALL = 30


def _strength(c: Candidate) -> float:
    return float(c.score) if c.source == "depth" else 1.0 - float(c.score)


def possible_misses(orthos: Mapping[str, Orthoimage], candidates: Sequence[Candidate],
                    detections: Sequence[Detection], max_per_wall: int = MAX_PER_WALL) -> list[dict]:
    """The candidates not kept, merged per place and class, away from every detection."""
    kept: dict[str, list[tuple[float, float, float]]] = {}
    for d in detections:
        kept.setdefault(d.wall_id, []).append((d.u, d.v, 0.5 * max(d.width_m, d.height_m)))
    out: list[dict] = []
    by_wall: dict[str, list[Candidate]] = {}
    for c in candidates:
        if c.wall_id in orthos:
            by_wall.setdefault(c.wall_id, []).append(c)
    for wid, cands in sorted(by_wall.items()):
        ortho = orthos[wid]
        px = ortho.pixel_m
        items: list[dict] = []
        for c in sorted(cands, key=_strength, reverse=True):
            u, v = (float(x) for x in ortho.pixel_to_uv(*c.centre))
            w_m, h_m = (c.box.c1 - c.box.c0) * px, (c.box.r1 - c.box.r0) * px
            reach = 0.5 * max(w_m, h_m)
            if any(np.hypot(u - ku, v - kv) < max(reach, kr) for ku, kv, kr in kept.get(wid, ())):
                continue
            same = next((s for s in items if s["class"] == c.class_id
                         and np.hypot(u - s["u"], v - s["v"]) < reach), None)
            if same is not None:
                if same["source"] != c.source:
                    same["source"] = "both"
                continue
            items.append({"class": c.class_id, "wall": wid, "u": round(u, 4), "v": round(v, 4),
                          "width_m": round(w_m, 4), "height_m": round(h_m, 4), "source": c.source,
                          "score": round(float(c.score), 4), "reason": "not_kept_by_consensus"})
        out.extend(items[:max_per_wall])
    return out


def suggestions_document(orthos: Mapping[str, Orthoimage], candidates: Sequence[Candidate],
                         detections: Sequence[Detection]) -> dict:
    return {"schema": SCHEMA, "suggestions": possible_misses(orthos, candidates, detections)}
