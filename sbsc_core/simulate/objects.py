"""The thirteen object classes as procedural coloured meshes.

Every builder returns a :class:`ColouredMesh` in the object-local frame: x along the wall
(to the right seen from the room), y up, z out of the wall into the room. The footprint
(``width_m`` x ``height_m`` of :mod:`catalogue`) is centred at x = y = 0, the back of the
object lies on the wall surface z = 0 and nothing stands out further than ``depth_m``.
Fronts carry the textures of :mod:`pictograms` (0.5 mm texels).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..errors import InputError
from . import pictograms as pg
from .catalogue import CATALOGUE, ObjectSpec
from .mesh import ColouredMesh, box, cylinder, merge, quad

PLATE = pg.RAL_9010  # off-white of sockets and switches
PLATE_FACE = (241, 239, 231)
CUP_GREY = (118, 118, 116)
EPS = 0.0004  # textures float this far in front of the face they decorate


def _front_texture(width: float, height: float, z: float, image: np.ndarray,
                   centre: Sequence[float] = (0.0, 0.0)) -> ColouredMesh:
    """A textured rectangle facing +z, centred at ``centre`` (x, y)."""
    cx, cy = centre
    return quad((cx - width / 2, cy - height / 2, z), (width, 0, 0), (0, height, 0), texture=image)


def textured_disc(radius: float, z: float, image: np.ndarray, centre: Sequence[float] = (0, 0),
                  segments: int = 32) -> ColouredMesh:
    """A disc facing +z with a square texture mapped over its bounding square."""
    cx, cy = centre
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.column_stack([cx + radius * np.cos(ang), cy + radius * np.sin(ang), np.full(segments, z)])
    verts = np.vstack([[cx, cy, z], ring])
    tris = np.array([[0, 1 + i, 1 + (i + 1) % segments] for i in range(segments)])
    uv = np.column_stack([0.5 + 0.5 * np.cos(ang), 0.5 - 0.5 * np.sin(ang)])
    uv = np.vstack([[0.5, 0.5], uv]).astype(np.float32)
    n = len(tris)
    return ColouredMesh(verts, tris, np.zeros((n, 3), np.uint8), np.zeros(n, np.int32),
                        uv[tris], [np.ascontiguousarray(image[..., :3], dtype=np.uint8)])


def _plate_with_square_holes(w: float, h: float, z0: float, z1: float, colour: Sequence[int],
                             *, hole_xs: Sequence[float], side: float) -> ColouredMesh:
    """A plate layer between z0 and z1 with square holes of ``side`` centred at y = 0."""
    parts = []
    edges = [-w / 2]
    for x in sorted(hole_xs):
        edges += [x - side / 2, x + side / 2]
    edges.append(w / 2)
    zc, dz = (z0 + z1) / 2, z1 - z0
    for k in range(0, len(edges) - 1):
        a, b = edges[k], edges[k + 1]
        if b - a <= 1e-6:
            continue
        if k % 2 == 0:  # solid column
            parts.append(box((b - a, h, dz), colour, ((a + b) / 2, 0, zc)))
        else:  # hole column: strips above and below the hole
            strip = (h - side) / 2
            parts.append(box((b - a, strip, dz), colour, ((a + b) / 2, side / 2 + strip / 2, zc)))
            parts.append(box((b - a, strip, dz), colour, ((a + b) / 2, -side / 2 - strip / 2, zc)))
    return merge(parts)


def _socket(spec: ObjectSpec, n: int) -> ColouredMesh:
    """A plate of ``n`` Schuko outlets in a row, each a recessed cup with a pin pattern."""
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    pitch = (w - h) / (n - 1) if n > 1 else 0.0
    xs = [(-(n - 1) / 2 + i) * pitch for i in range(n)]
    cup_d, hole = 0.038, 0.044
    floor_z = 0.45 * d
    parts = [box((w, h, floor_z), PLATE, (0, 0, floor_z / 2)),
             _plate_with_square_holes(w - 0.002, h - 0.002, floor_z, d, PLATE_FACE, hole_xs=xs, side=hole)]
    cup = pg.socket_cup_floor(cup_d)
    for x in xs:
        parts.append(textured_disc(cup_d / 2, floor_z + EPS, cup, centre=(x, 0)))
    return merge(parts)


def socket_x1(spec: ObjectSpec) -> ColouredMesh:
    return _socket(spec, 1)


def socket_x2(spec: ObjectSpec) -> ColouredMesh:
    return _socket(spec, 2)


def socket_x4(spec: ObjectSpec) -> ColouredMesh:
    return _socket(spec, 4)


def builtin_socket(spec: ObjectSpec) -> ColouredMesh:
    """A flush-mounted socket: a thin grey frame, a lid and the outlet, all within 4 mm."""
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    lid = 0.75 * w
    parts = [box((w, h, d / 2), (196, 196, 190), (0, 0, d / 4)),
             box((lid, lid, d / 2), PLATE, (0, 0, 0.75 * d)),
             textured_disc(0.019, d + EPS, pg.socket_cup_floor(0.038))]
    return merge(parts)


def switch(spec: ObjectSpec) -> ColouredMesh:
    """A rocker switch: plate, a slightly proud rocker split into two tilted halves."""
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    plate_d = 0.7 * d
    rocker = 0.055
    parts = [box((w, h, plate_d), PLATE, (0, 0, plate_d / 2)),
             box((rocker + 0.004, rocker + 0.004, 0.001), (170, 170, 165), (0, 0, plate_d + 0.0005)),
             box((rocker, rocker / 2, d - plate_d), PLATE_FACE, (0, rocker / 4, (plate_d + d) / 2)),
             box((rocker, rocker / 2, 0.8 * (d - plate_d)), (234, 232, 223),
                 (0, -rocker / 4, plate_d + 0.4 * (d - plate_d)))]
    return merge(parts)


def electrical_panel(spec: ObjectSpec) -> ColouredMesh:
    """A surface-mounted distribution board: enclosure and a door with a smoked window."""
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    door_t = 0.006
    body = d - door_t
    parts = [box((w, h, body), pg.RAL_9016, (0, 0, body / 2)),
             box((w - 0.01, h - 0.01, door_t), (236, 235, 229), (0, 0, body + door_t / 2)),
             _front_texture(w - 0.01, h - 0.01, d + EPS, pg.electrical_panel_front(w - 0.01, h - 0.01))]
    return merge(parts)


def fire_extinguisher(spec: ObjectSpec) -> ColouredMesh:
    """A 6 kg powder extinguisher on a wall bracket: red body, label, valve, hose."""
    h, d = spec.height_m, spec.depth_m
    r = 0.075
    zc = d - r  # cylinder axis distance from the wall
    xb = -0.012  # body axis, left of centre so that body and hose fill the footprint
    y0 = -h / 2
    body_top = y0 + 0.46
    red, black = pg.RAL_3000, (30, 30, 30)
    parts = [
        box((0.07, 0.12, zc - r + 0.004), (60, 60, 60), (xb, 0.02, (zc - r + 0.004) / 2)),  # bracket
        cylinder(r, 0.12, red, centre=(xb, y0 + 0.06, zc), axis=1),
        _label_band(r, 0.20, zc, y0 + 0.12 + 0.10).transformed(np.eye(3), (xb, 0, 0)),
        cylinder(r, 0.14, red, centre=(xb, body_top - 0.07, zc), axis=1),
        cylinder(0.055, 0.03, red, centre=(xb, body_top + 0.015, zc), axis=1),  # shoulder
        cylinder(0.022, 0.04, (150, 150, 150), centre=(xb, body_top + 0.05, zc), axis=1),  # neck
        box((0.09, 0.035, 0.05), black, (xb + 0.005, body_top + 0.085, zc)),  # valve head
        box((0.11, 0.012, 0.03), (40, 40, 40), (xb + 0.02, h / 2 - 0.006, zc)),  # lever
        cylinder(0.009, 0.40, black, centre=(xb + 0.088, y0 + 0.32, zc), axis=1),  # hose
        cylinder(0.014, 0.05, black, centre=(xb + 0.088, y0 + 0.10, zc), axis=1),  # nozzle
    ]
    return merge(parts)


def _label_band(r: float, height: float, zc: float, yc: float) -> ColouredMesh:
    """The cylindrical middle of the extinguisher, its front third carrying the label."""
    band = cylinder(r, height, pg.RAL_3000, segments=36, centre=(0, yc, zc), axis=1, capped=False)
    centroids = band.vertices[band.triangles].mean(axis=1)
    front = centroids[:, 2] > zc + 0.5 * r
    band.tri_colour[front] = (238, 232, 212)
    text = front & (np.abs(centroids[:, 1] - yc) < 0.25 * height) & (np.abs(centroids[:, 0]) < 0.3 * r)
    band.tri_colour[text] = (70, 60, 55)
    return band


def radiator(spec: ObjectSpec) -> ColouredMesh:
    """A white panel convector: back panel, vertical ribs, top grille and brackets."""
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    white = (244, 244, 240)
    panel_z0, panel_t = 0.015, 0.035
    parts = [box((0.04, 0.10, panel_z0), (200, 200, 198), (x, 0.15, panel_z0 / 2)) for x in (-0.3, 0.3)]
    parts.append(box((w, h, panel_t), white, (0, 0, panel_z0 + panel_t / 2)))
    n_ribs = 20
    rib_w = w / n_ribs
    for i in range(n_ribs):
        x = -w / 2 + (i + 0.5) * rib_w
        parts.append(box((0.7 * rib_w, h - 0.04, d - panel_z0 - panel_t), white,
                         (x, 0, (panel_z0 + panel_t + d) / 2)))
    parts.append(box((w, 0.02, d - panel_z0), (232, 232, 228), (0, h / 2 - 0.01, (panel_z0 + d) / 2)))
    return merge(parts)


def fire_alarm_switch(spec: ObjectSpec) -> ColouredMesh:
    """A manual call point: red housing with a white glass window."""
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    parts = [box((w, h, d), pg.RAL_3000, (0, 0, d / 2)),
             _front_texture(w, h, d + EPS, pg.call_point_front(w, h))]
    return merge(parts)


def smoke_detector(spec: ObjectSpec) -> ColouredMesh:
    """An optical smoke detector on its base: two white discs, vents and a red LED."""
    d = spec.depth_m
    r = spec.width_m / 2
    white = (240, 240, 235)
    base_t = 0.6 * d
    parts = [cylinder(r, base_t, white, segments=40, centre=(0, 0, base_t / 2), axis=2),
             cylinder(0.85 * r, d - base_t, (236, 236, 231), segments=40,
                      centre=(0, 0, (base_t + d) / 2), axis=2),
             textured_disc(0.85 * r, d + EPS, pg.smoke_detector_face(2 * 0.85 * r), segments=40)]
    return merge(parts)


def exit_light(spec: ObjectSpec) -> ColouredMesh:
    """An emergency exit luminaire: white housing, green running-man diffuser."""
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    parts = [box((w, h, d), (246, 246, 242), (0, 0, d / 2)),
             _front_texture(w, h, d + EPS, pg.exit_light_front(w, h))]
    return merge(parts)


def _sign(spec: ObjectSpec, draw: Callable[[float, float], np.ndarray]) -> ColouredMesh:
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    return merge([box((w, h, d), pg.SAFETY_RED, (0, 0, d / 2)),
                  _front_texture(w, h, d + EPS, draw(w, h))])


def extinguisher_sign(spec: ObjectSpec) -> ColouredMesh:
    return _sign(spec, pg.extinguisher_sign)


def fire_alarm_switch_sign(spec: ObjectSpec) -> ColouredMesh:
    return _sign(spec, pg.fire_alarm_sign)


BUILDERS: dict[str, Callable[[ObjectSpec], ColouredMesh]] = {
    "electrical_panel": electrical_panel,
    "socket_x1": socket_x1,
    "socket_x2": socket_x2,
    "socket_x4": socket_x4,
    "builtin_socket": builtin_socket,
    "switch": switch,
    "fire_extinguisher": fire_extinguisher,
    "radiator": radiator,
    "fire_alarm_switch": fire_alarm_switch,
    "smoke_detector": smoke_detector,
    "exit_light": exit_light,
    "extinguisher_sign": extinguisher_sign,
    "fire_alarm_switch_sign": fire_alarm_switch_sign,
}


def build_object(class_id: str) -> ColouredMesh:
    """The mesh of one object of ``class_id`` in its local frame (see the module docstring)."""
    spec = CATALOGUE.get(class_id)
    if spec is None or class_id not in BUILDERS:
        raise InputError("class", f"unknown class '{class_id}'")
    return BUILDERS[class_id](spec)
