"""A finished ``sbsc detect`` output with a ceiling and two columns (issue 11), for the app tests.

Two walls with a few objects (as ``app_support._fake_output``), plus contract 4's
``surfaces``: the room's ceiling ``C01`` seen from below, the four faces of a rectangular column
``COL1`` and the unrolled face of a round column ``COL2``, each with its orthoimages and an
object on it (``"surface": "ceiling"`` / ``"column"``).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from sbsc_core.scene.columns import FoundColumn, column_faces

from .app_support import PIXEL_M, _fake_output

ROOM_H = 2.5
CEILING = {"id": "C01", "kind": "ceiling", "origin": [0.0, 3.0, ROOM_H], "axis_u": [1.0, 0.0, 0.0],
           "axis_v": [0.0, -1.0, 0.0], "normal": [0.0, 0.0, -1.0], "width_m": 4.0, "height_m": 3.0}
COLUMNS = [FoundColumn("COL1", None, "rect", (1.0, 1.2), (0.4, 0.4), 0.0, 0.0, ROOM_H),
           FoundColumn("COL2", None, "round", (3.0, 2.0), (0.5, 0.5), 0.0, 0.0, ROOM_H)]
# (id, class, surface id, u, v, width, height, colour)
SURFACE_OBJECTS = [("D0101", "smoke_detector", "C01", 2.0, 1.5, 0.11, 0.11, (245, 245, 240)),
                   ("D0102", "fire_alarm_switch", "COL1-S", 0.2, 1.4, 0.10, 0.10, (220, 30, 30)),
                   ("D0103", "socket_x1", "COL2", 0.25 * np.pi * 0.5, 0.4, 0.08, 0.08, (250, 250, 250))]


def surfaces() -> list[dict]:
    """The ceiling and the column faces of the output, as contract 4's ``surfaces``."""
    return [dict(CEILING), *[f.surface() for f in column_faces(COLUMNS)]]


def world(surface: dict, u: float, v: float) -> list[float]:
    for f in column_faces(COLUMNS):
        if f.id == surface["id"]:
            return [round(float(x), 5) for x in f.to_world(u, v)]
    o, a, b = (np.asarray(surface[k], float) for k in ("origin", "axis_u", "axis_v"))
    return [round(float(x), 5) for x in o + u * a + v * b]


def write_surfaces_output(out: Path, n_wall_objects: int = 4) -> dict:
    """Write the output folder; returns its ``detections.json`` document."""
    _fake_output(out, n_wall_objects, lambda stage, f: None, 0.0)
    doc = json.loads((out / "detections.json").read_text())
    doc["surfaces"] = surfaces()
    by_id = {s["id"]: s for s in doc["surfaces"]}
    ortho = out / "orthoimages"
    for s in doc["surfaces"]:
        H, W = int(round(s["height_m"] / PIXEL_M)), int(round(s["width_m"] / PIXEL_M))
        colour = np.full((H, W, 3), (180, 185, 190) if s["kind"] == "column" else (235, 235, 230), np.uint8)
        depth = np.zeros((H, W), np.float32)
        for _, _, sid, u, v, w, h, rgb in SURFACE_OBJECTS:
            if sid != s["id"]:
                continue
            c0, c1 = int((u - w / 2) / PIXEL_M), int((u + w / 2) / PIXEL_M)
            r0, r1 = int((s["height_m"] - v - h / 2) / PIXEL_M), int((s["height_m"] - v + h / 2) / PIXEL_M)
            colour[r0:r1, c0:c1] = rgb
            depth[r0:r1, c0:c1] = 0.03
        cv2.imwrite(str(ortho / f"{s['id']}_colour.png"), colour[:, :, ::-1])
        np.save(ortho / f"{s['id']}_depth.npy", depth)
        cv2.imwrite(str(ortho / f"{s['id']}_depth.png"), (128 - depth * 1270).astype(np.uint8))
    for did, cls, sid, u, v, w, h, _ in SURFACE_OBJECTS:
        s = by_id[sid]
        doc["detections"].append({"id": did, "class": cls, "wall": sid, "surface": s["kind"],
                                  "position": world(s, u, v), "u": round(float(u), 4), "v": v,
                                  "width_m": w, "height_m": h, "alpha": 0.9, "rho_depth": 0.85,
                                  "rho_colour": 0.1, "source": "both"})
    (out / "detections.json").write_text(json.dumps(doc, indent=1))
    return doc
