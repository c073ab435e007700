"""A synthetic ``sbsc detect`` output (and scan) for the viewer's tests, demos and timings.

It writes exactly the layout of ``sbsc_core.pipeline.outputs.write_outputs``: ``detections.json``
(contract 4 + ``pixel_m``), ``rois.json``, ``orthoimages/<W>_colour.png``, ``_depth.png`` and
``_depth.npy``, plus ``scan.ply``: rectangular rooms in a row, four walls each, objects drawn
on the walls as coloured rectangles standing out 2 cm, one door per room.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from sbsc_core.io.ply import write_ply
from sbsc_core.types import WallFrame

CLASSES = ("socket_x1", "switch", "extinguisher", "exit_sign", "fire_alarm_switch")
WALL_RGB = np.array([214, 206, 190], np.uint8)


@dataclass
class SyntheticProject:
    out_dir: Path
    scan: Path
    detections: dict
    rois: dict


def room_walls(x0: float, y0: float, x1: float, y1: float, h: float) -> list[WallFrame]:
    """The four walls of a room (contract 4 frames: normal into the room, u x v = normal)."""
    z = np.array([0.0, 0.0, 1.0])

    def wf(origin, u, n, w):
        return WallFrame(np.array(origin, float), np.array(u, float), z, np.array(n, float), w, h)

    return [wf((x1, y0, 0), (-1, 0, 0), (0, 1, 0), x1 - x0),
            wf((x1, y1, 0), (0, -1, 0), (-1, 0, 0), y1 - y0),
            wf((x0, y1, 0), (1, 0, 0), (0, -1, 0), x1 - x0),
            wf((x0, y0, 0), (0, 1, 0), (1, 0, 0), y1 - y0)]


def write_synthetic_project(out: Path, *, rooms: int = 1, walls_per_room: int = 4,
                            objects_per_wall: int = 2, points: int = 20_000,
                            pixel_m: float = 0.005, seed: int = 0,
                            origin: tuple[float, float, float] = (500.0, 200.0, 10.0),
                            room_size: tuple[float, float] = (6.0, 4.5),
                            height_m: float = 2.7, columns: int = 0) -> SyntheticProject:
    """Write a synthetic detection directory and its scan under ``out``; return what was written.

    World coordinates are offset by ``origin`` (scans are rarely near 0, 0, 0), which the
    viewer must subtract again. Rooms stand in a row, or in a grid of ``columns``.
    """
    rng = np.random.default_rng(seed)
    out = Path(out)
    (out / "orthoimages").mkdir(parents=True, exist_ok=True)
    off = np.array(origin, float)
    walls: list[tuple[str, WallFrame]] = []
    cols = columns or rooms
    for r in range(rooms):
        x0, y0 = (r % cols) * room_size[0], (r // cols) * room_size[1]
        for f in room_walls(x0, y0, x0 + room_size[0], y0 + room_size[1], height_m)[:walls_per_room]:
            f = WallFrame(f.origin + off, f.axis_u, f.axis_v, f.normal, f.width_m, f.height_m)
            walls.append((f"W{len(walls) + 1:02d}", f))

    dets, openings, rois_doc = [], [], {}
    xyz_parts, rgb_parts = [], []
    wall_points = int(points * 0.7) // max(1, len(walls))
    for wi, (wid, f) in enumerate(walls):
        H, W = int(round(f.height_m / pixel_m)), int(round(f.width_m / pixel_m))
        colour = np.empty((H, W, 3), np.uint8)
        colour[:] = WALL_RGB
        depth = np.zeros((H, W), np.float32)
        d_rois, c_rois = [], []
        if wi % walls_per_room == 0:  # a door
            u0 = 0.4
            openings.append({"wall": wid, "kind": "door", "u_min": u0, "u_max": u0 + 0.9,
                             "v_min": 0.0, "v_max": 2.05})
            c0, c1 = int(u0 / pixel_m), int((u0 + 0.9) / pixel_m)
            colour[H - int(2.05 / pixel_m):, c0:c1] = (90, 60, 40)
        for k in range(objects_per_wall):
            cls = CLASSES[(wi + k) % len(CLASSES)]
            w_m, h_m = (0.08, 0.08) if cls in ("socket_x1", "switch") else (0.25, 0.3)
            u = 1.6 + (f.width_m - 2.2) * (k + 0.5) / objects_per_wall
            v = 0.3 if cls == "socket_x1" else 1.2 + 0.1 * (k % 3)
            r0, r1 = int((f.height_m - v - h_m / 2) / pixel_m), int((f.height_m - v + h_m / 2) / pixel_m)
            cc0, cc1 = int((u - w_m / 2) / pixel_m), int((u + w_m / 2) / pixel_m)
            rgb = rng.integers(30, 230, 3).astype(np.uint8)
            colour[r0:r1, cc0:cc1] = rgb
            depth[r0:r1, cc0:cc1] = 0.02
            did = f"D{len(dets) + 1:04d}"
            alpha = round(float(rng.uniform(0.5, 1.0)), 4)
            source = ("both", "depth", "colour")[k % 3]
            dets.append({
                "id": did, "class": cls, "wall": wid,
                "position": [round(float(x), 5) for x in f.to_world(u, v)],
                "u": round(u, 5), "v": round(v, 5), "width_m": w_m, "height_m": h_m,
                "alpha": alpha,
                "rho_depth": None if source == "colour" else round(float(rng.uniform(0.75, 0.95)), 4),
                "rho_colour": None if source == "depth" else round(float(rng.uniform(0.02, 0.2)), 4),
                "source": source})
            pad = 0.02
            box = {"u_min": round(u - w_m / 2 - pad, 4), "u_max": round(u + w_m / 2 + pad, 4),
                   "v_min": round(v - h_m / 2 - pad, 4), "v_max": round(v + h_m / 2 + pad, 4)}
            if source != "colour":
                d_rois.append(box)
            if source != "depth":
                c_rois.append({k2: round(x + 0.01, 4) for k2, x in box.items()})
        d_rois.append({"u_min": 0.2, "u_max": 0.35, "v_min": 2.3, "v_max": 2.4})  # a false RoI
        rois_doc[wid] = {"depth": d_rois, "colour": c_rois}
        img_dir = out / "orthoimages"
        cv2.imwrite(str(img_dir / f"{wid}_colour.png"), cv2.cvtColor(colour, cv2.COLOR_RGB2BGR))
        dvis = np.clip(128 - depth / 0.10 * 127, 0, 254).astype(np.uint8)
        cv2.imwrite(str(img_dir / f"{wid}_depth.png"), dvis)
        np.save(img_dir / f"{wid}_depth.npy", depth)
        # scan points of the wall, coloured from the orthoimage
        u = rng.uniform(0, f.width_m, wall_points)
        v = rng.uniform(0, f.height_m, wall_points)
        r = np.clip(((f.height_m - v) / pixel_m).astype(int), 0, H - 1)
        c = np.clip((u / pixel_m).astype(int), 0, W - 1)
        d = depth[r, c] + rng.normal(0, 0.002, wall_points)
        xyz_parts.append(f.to_world(u, v, d))
        rgb_parts.append(colour[r, c])
    # floor and ceiling
    n_fc = max(0, points - wall_points * len(walls))
    xs = rng.uniform(0, cols * room_size[0], n_fc)
    ys = rng.uniform(0, -(-rooms // cols) * room_size[1], n_fc)
    zs = np.where(rng.random(n_fc) < 0.5, 0.0, height_m)
    xyz_parts.append(np.stack([xs, ys, zs], axis=1) + off)
    rgb_parts.append(np.where((zs == 0)[:, None], np.array([[150, 150, 155]], np.uint8),
                              np.array([[240, 240, 240]], np.uint8)))
    doc = {"schema": "sbsc.detections/1",
           "walls": [{"id": wid, **f.to_dict()} for wid, f in walls],
           "openings": openings, "detections": dets, "pixel_m": pixel_m,
           "classes_searched": list(CLASSES)}
    rois = {"schema": "sbsc.rois/1", "pixel_m": pixel_m, "walls": rois_doc}
    (out / "detections.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    (out / "rois.json").write_text(json.dumps(rois, indent=1) + "\n", encoding="utf-8")
    scan = out / "scan.ply"
    write_ply(scan, np.concatenate(xyz_parts), np.concatenate(rgb_parts), double=True)
    return SyntheticProject(out, scan, doc, rois)
