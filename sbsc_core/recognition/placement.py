"""Recognized instances placed on their walls and in 3-D (paper, section 4.4, last step).

A hit's centre (row, col) in its wall's orthoimage becomes (u, v) metres in the wall frame
(``Orthoimage.pixel_to_uv``) and the world point ``frame.to_world(u, v, 0)``: the centre of
the object's footprint on the wall plane (contract 4). The footprint size is the model's;
a model matched turned nearer to 90 or 270 than to 0 or 180 degrees has its width and
height exchanged (the sides nearest to horizontal and vertical); ``rotation_deg`` is the
model's full turn, counter-clockwise seen from the room, in (-180, 180].
A hit marked ``unknown`` keeps its footprint and gets the class ``unknown``.
Detections are numbered "D0001", ... by wall id, then top to bottom (v descending), then
left to right (u ascending), so the same result always gets the same ids.
"""

from __future__ import annotations

from ..errors import SbscError
from ..types import Detection, Orthoimage
from .consensus import ConsensusHit
from .templates import ModelTemplate

UNKNOWN = "unknown"  # the class of a hit too weak, ambiguous or like no class to name (for review)


def place_hits(hits: list[ConsensusHit], orthos: dict[str, Orthoimage],
               templates: dict[str, ModelTemplate]) -> list[Detection]:
    """Detections (contract 4) for consensus hits, in a deterministic order with ids D0001..."""
    rows = []
    for h in hits:
        if h.wall_id not in orthos:
            raise SbscError(f"hit of class '{h.class_id}' on unknown wall '{h.wall_id}'")
        if h.class_id not in templates and not (h.unknown and h.box is not None):
            raise SbscError(f"hit of unknown class '{h.class_id}'")
        o = orthos[h.wall_id]
        u, v = o.pixel_to_uv(h.centre[0], h.centre[1])
        rows.append((h.wall_id, -round(float(v), 6), round(float(u), 6), h.class_id, h, float(u), float(v)))
    rows.sort(key=lambda x: x[:4])
    out = []
    for k, (wid, _, _, cid, h, u, v) in enumerate(rows, start=1):
        quarter = int(round(float(h.rotation_deg) / 90.0)) % 2  # nearer to 90 or 270 than to 0 or 180
        if cid in templates:
            t = templates[cid]
            w_m, h_m = (t.height_m, t.width_m) if quarter else (t.width_m, t.height_m)
        else:  # a region like no class: its box
            w_m, h_m = h.box.width * orthos[wid].pixel_m, h.box.height * orthos[wid].pixel_m
        turn = float(h.rotation_deg) % 360.0
        out.append(Detection(
            id=f"D{k:04d}", class_id=UNKNOWN if h.unknown else cid, wall_id=wid, u=u, v=v,
            position=orthos[wid].frame.to_world(u, v, 0.0),
            width_m=w_m, height_m=h_m, alpha=h.alpha,
            rho_depth=h.rho_depth, rho_colour=h.rho_colour, source=h.source,
            rotation_deg=turn - 360.0 if turn > 180.0 else turn, confidence=h.confidence,
        ))
    return out
