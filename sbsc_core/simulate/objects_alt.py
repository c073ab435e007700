"""The ALTERNATIVE design set: the thirteen classes as another manufacturer makes them.

Same contract as :mod:`objects` (the standard set): every builder returns a
:class:`ColouredMesh` in the object-local frame (x along the wall, y up, z out of the wall
into the room), the footprint ``width_m`` x ``height_m`` of
:data:`~sbsc_core.simulate.catalogue.CATALOGUE` is centred at x = y = 0, the back lies on
the wall (z = 0) and nothing stands out further than ``depth_m``. The footprints are the
catalogue's; everything else differs, so that recognition can be measured on designs it
was not tuned on:

* relief: rounded, bevelled plates (lofted outlines) instead of boxes, Schuko outlets as
  square modules with a round recessed cup, a rocker tilted top-out, an aluminium COLUMN
  radiator (10 bowed elements, headers, brackets) instead of a panel convector, a revolved
  extinguisher with foot, gauge, lever and a hose down its right side, a smoke detector
  with a shoulder and a raised chamber;
* colour shades and prints: the textures of :mod:`pictograms_alt` (other layouts of the
  same ISO 7010 signs, three breaker rows, radial smoke vents, shutters in the cups) and
  slightly different reds and whites.

Designs follow common Spanish / European products; see :func:`build_object_alt`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..errors import InputError
from . import pictograms as pic
from . import pictograms_alt as alt
from .catalogue import CATALOGUE
from .mesh import ColouredMesh, box, cylinder, merge

Colour = Sequence[int]

WHITE_9010 = pic.RAL_9010  # pure white: switch plates, socket inserts
WHITE_9016 = pic.RAL_9016  # traffic white: housings
SOCKET_WHITE = (241, 239, 231)  # moulded socket plates, a touch brighter than RAL 9010
FRAME_GREY = (196, 196, 190)  # light-grey frame of the flush-mounted socket
RADIATOR_WHITE = (244, 244, 240)  # stove-enamelled aluminium
CUP_WALL = (150, 150, 147)
DARK_GAP = (95, 95, 92)
BLACK_PLASTIC = (30, 30, 30)
STEEL_DARK = (58, 58, 62)
SWITCH_FRAME = (246, 246, 244)  # RAL 9003 signal white, cooler than the standard set's RAL 9010
ROCKER_CREAM = (238, 234, 221)


# --------------------------------------------------------------------------- geometry helpers

def _loft(rings: Sequence[np.ndarray], colour: Colour, cap_start: bool = False,
          cap_end: bool = False, closed: bool = True) -> ColouredMesh:
    """Join consecutive rings of N 3-D points with triangle strips (optionally fan caps).

    ``closed`` joins the last point of each ring to the first (a tube); with ``False`` the
    strips form an open sheet (e.g. a partial surface of revolution).
    """
    rings = [np.asarray(r, float) for r in rings]
    n = len(rings[0])
    verts = list(rings)
    tris: list[tuple[int, int, int]] = []
    seg = n if closed else n - 1
    for i in range(len(rings) - 1):
        a, b = i * n, (i + 1) * n
        for k in range(seg):
            k1 = (k + 1) % n
            tris += [(a + k, a + k1, b + k1), (a + k, b + k1, b + k)]
    base = len(rings) * n
    for ring_i, on in ((0, cap_start), (len(rings) - 1, cap_end)):
        if on:
            verts.append(rings[ring_i].mean(axis=0, keepdims=True))
            c = base
            base += 1
            off = ring_i * n
            tris += [(c, off + (k + 1) % n, off + k) for k in range(n)]
    v = np.vstack(verts)
    t = np.array(tris, np.int64)
    return ColouredMesh(v, t, np.tile(np.asarray(colour, np.uint8), (len(t), 1)),
                        np.full(len(t), -1, np.int32), np.zeros((len(t), 3, 2), np.float32))


def _outline(hw: float, hh: float, r: float, centre: Sequence[float] = (0.0, 0.0),
             per_corner: int = 8) -> np.ndarray:
    """Rounded-rectangle outline (N, 2) with half sizes hw, hh and corner radius r."""
    cx, cy = centre
    return pic.rounded_rect_outline(cx - hw, cy - hh, cx + hw, cy + hh, max(r, 1e-4), per_corner=per_corner)


def _at_z(xy: np.ndarray, z: float | np.ndarray) -> np.ndarray:
    return np.column_stack([xy, np.broadcast_to(np.asarray(z, float), (len(xy),))])


def _plate(hw: float, hh: float, r: float, z0: float, z1: float, *, bevel: float, colour: Colour,
           centre: Sequence[float] = (0.0, 0.0)) -> ColouredMesh:
    """A rounded-rectangle plate from z0 to z1 whose front edge is bevelled by ``bevel``."""
    outer = _outline(hw, hh, r, centre)
    b = min(bevel, 0.45 * min(hw, hh), 0.9 * (z1 - z0))
    inner = _outline(hw - b, hh - b, max(r - b, 1e-4), centre)
    return _loft([_at_z(outer, z0), _at_z(outer, z1 - b), _at_z(inner, z1)], colour,
                 cap_start=True, cap_end=True)


def _ray_ring(hw: float, hh: float, r: float, angles: np.ndarray,
              centre: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """Points of a rounded rectangle's boundary in the given directions from its centre.

    Sampling by angle (not arc length) lets the outline be joined strip-wise to a
    concentric circle sampled at the same angles (a plate with a round hole).
    """
    d = np.column_stack([np.cos(angles), np.sin(angles)])
    lo = np.zeros(len(angles))
    hi = np.full(len(angles), 2.0 * max(hw, hh))
    half = np.array([hw - r, hh - r])
    for _ in range(40):  # bisection on the signed distance of a rounded box
        t = (lo + hi) / 2
        q = np.abs(d * t[:, None]) - half
        sdf = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0) - r
        inside = sdf < 0
        lo = np.where(inside, t, lo)
        hi = np.where(inside, hi, t)
    return d * ((lo + hi) / 2)[:, None] + np.asarray(centre, float)


def _circle(radius: float, angles: np.ndarray, centre: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    return np.column_stack([np.cos(angles), np.sin(angles)]) * radius + np.asarray(centre, float)


def _outlet_module(centre: Sequence[float], half: float, z_base: float, z_face: float,
                   colour: Colour, *, cup_r: float = 0.0195, cup_floor_z: float = 0.004,
                   corner_r: float = 0.004, bevel: float = 0.0015, n: int = 72) -> ColouredMesh:
    """A square socket module with a recessed Schuko cup (floor textured with pin holes)."""
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    outer = _ray_ring(half, half, corner_r, ang, centre)
    inner = _ray_ring(half - bevel, half - bevel, max(corner_r - bevel, 1e-4), ang, centre)
    rim = _circle(cup_r, ang, centre)
    body = _loft([_at_z(outer, z_base), _at_z(outer, z_face - bevel), _at_z(inner, z_face),
                  _at_z(rim, z_face)], colour)
    wall = _loft([_at_z(rim, z_face), _at_z(rim, cup_floor_z)], CUP_WALL, cap_end=True)
    floor_tex = alt.socket_cup_floor(2 * cup_r)
    cx, cy = centre
    wall = _texture_front(wall, floor_tex, x0=cx - cup_r, x1=cx + cup_r, y0=cy - cup_r, y1=cy + cup_r)
    return merge([body, wall])


def _revolve(profile: Sequence[tuple[float, float]], axis: int, centre: Sequence[float],
             colour: Colour, *, segments: int = 48, angle_range: tuple[float, float] | None = None,
             cap_start: bool = False, cap_end: bool = False) -> ColouredMesh:
    """Surface of revolution of (radius, position-along-axis) pairs.

    ``axis`` 1 (y): points (cx + r cos a, p, cz + r sin a), so a in (0, pi) faces +z.
    ``axis`` 2 (z): points (cx + r cos a, cy + r sin a, p).
    """
    closed = angle_range is None
    if closed:
        ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    else:
        ang = np.linspace(angle_range[0], angle_range[1], segments)
    c = np.asarray(centre, float)
    rings = []
    for r, p in profile:
        if axis == 1:
            ring = np.column_stack([c[0] + r * np.cos(ang), np.full_like(ang, p), c[2] + r * np.sin(ang)])
        elif axis == 2:
            ring = np.column_stack([c[0] + r * np.cos(ang), c[1] + r * np.sin(ang), np.full_like(ang, p)])
        else:
            raise ValueError("axis must be 1 or 2")
        rings.append(ring)
    return _loft(rings, colour, cap_start=cap_start, cap_end=cap_end, closed=closed)


def _prism_xy(outline: np.ndarray, z0: float, z1: float, colour: Colour) -> ColouredMesh:
    """A convex outline in the x-y plane extruded from z0 to z1, both ends capped."""
    return _loft([_at_z(outline, z0), _at_z(outline, z1)], colour, cap_start=True, cap_end=True)


def _texture_front(mesh: ColouredMesh, image: np.ndarray, *, x0: float, x1: float, y0: float,
                   y1: float, min_nz: float = 0.3) -> ColouredMesh:
    """Project an RGB image straight along z onto the mesh's front-ish triangles.

    The image covers the rectangle [x0, x1] x [y0, y1] (row 0 at y1); triangles whose unit
    normal has |n_z| >= ``min_nz`` take their colour from it, steeper ones keep theirs.
    """
    v = mesh.vertices[mesh.triangles]  # (T, 3, 3)
    nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    length = np.linalg.norm(nrm, axis=1)
    nz = np.abs(nrm[:, 2]) / np.where(length > 0, length, 1.0)
    sel = nz >= min_nz
    uv = np.stack([(v[..., 0] - x0) / (x1 - x0), (y1 - v[..., 1]) / (y1 - y0)], axis=-1)
    tri_tex = mesh.tri_texture.copy()
    tri_uv = mesh.tri_uv.copy()
    k = len(mesh.textures)
    tri_tex[sel] = k
    tri_uv[sel] = np.clip(uv[sel], 0.0, 1.0).astype(np.float32)
    return ColouredMesh(mesh.vertices, mesh.triangles, mesh.tri_colour, tri_tex.astype(np.int32),
                        tri_uv, [*mesh.textures, np.ascontiguousarray(image[..., :3], np.uint8)],
                        mesh.tri_label)


def _box_span(x0: float, x1: float, y0: float, y1: float, *, z0: float, z1: float,
              colour: Colour) -> ColouredMesh:
    return box((x1 - x0, y1 - y0, z1 - z0), colour, ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2))


# --------------------------------------------------------------------------- the classes

def _socket_row(n_outlets: int) -> Callable[[], ColouredMesh]:
    def build() -> ColouredMesh:
        spec = CATALOGUE[f"socket_x{n_outlets}"]
        hw, hh = spec.width_m / 2, spec.height_m / 2
        # the frame's face lies below the cup floors so that the cups are not covered
        frame = _plate(hw, hh, 0.006, 0.0, 0.005, bevel=0.0015, colour=SOCKET_WHITE)
        margin = 0.009
        pitch = (spec.width_m - 2 * margin) / n_outlets
        half = min(0.031, pitch / 2 - 0.002, hh - margin)
        modules = [
            _outlet_module((-hw + margin + (i + 0.5) * pitch, 0.0), half, 0.0045, spec.depth_m,
                           SOCKET_WHITE, cup_floor_z=0.0055)
            for i in range(n_outlets)
        ]
        return merge([frame, *modules])
    return build


def _builtin_socket() -> ColouredMesh:
    """Flush-mounted socket: a 3 mm light-grey square frame round a white insert with the
    Schuko cup, 4 mm in all."""
    spec = CATALOGUE["builtin_socket"]
    hw = spec.width_m / 2
    half_in = 0.035
    ang = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    outer = _ray_ring(hw, hw, 0.003, ang)
    bevelled = _ray_ring(hw - 0.001, hw - 0.001, 0.002, ang)
    hole = _ray_ring(half_in, half_in, 0.002, ang)
    frame = _loft([_at_z(outer, 0.0), _at_z(outer, 0.002), _at_z(bevelled, 0.003),
                   _at_z(hole, 0.003)], FRAME_GREY)  # an annulus: the insert fills its hole
    insert = _outlet_module((0.0, 0.0), half_in, 0.0, spec.depth_m, WHITE_9010,
                            cup_floor_z=0.0015, corner_r=0.002, bevel=0.0008)
    return merge([frame, insert])


def _switch() -> ColouredMesh:
    """Rocker light switch: signal-white frame, a wide dark gap round a cream rocker tilted
    top-out, with an orange locator light near its top."""
    spec = CATALOGUE["switch"]
    hw = spec.width_m / 2
    frame = _plate(hw, hw, 0.006, 0.0, 0.008, bevel=0.0015, colour=SWITCH_FRAME)
    gap = _plate(0.0300, 0.0300, 0.0025, 0.006, 0.0085, bevel=0.0002, colour=(70, 70, 68))
    half = 0.0275
    ring = _outline(half, half, 0.002)
    tilt_z = 0.0105 + 0.0015 * ring[:, 1] / half  # 9 mm at the bottom, 12 mm at the top
    inner = _outline(half - 0.001, half - 0.001, 0.001)
    inner_z = 0.0105 + 0.0015 * inner[:, 1] / half
    rocker = _loft([_at_z(ring, 0.0085), _at_z(ring, tilt_z - 0.0005), _at_z(inner, inner_z)],
                   ROCKER_CREAM, cap_end=True)
    p = pic.Painter.new(2 * half, 2 * half, ROCKER_CREAM)
    p.round_rect(half - 0.005, 0.008, half + 0.005, 0.012, 0.0015, colour=(235, 125, 35))  # locator light
    p.rect(0.004, half - 0.0004, 2 * half - 0.004, half + 0.0004, (205, 200, 186))  # parting line
    rocker = _texture_front(rocker, p.img, x0=-half, x1=half, y0=-half, y1=half, min_nz=0.9)
    return merge([frame, gap, rocker])


def _fire_extinguisher() -> ColouredMesh:
    """6 kg powder extinguisher on a wall bracket; hose down its right side."""
    spec = CATALOGUE["fire_extinguisher"]
    top = spec.height_m / 2
    bottom = -top
    r_body = 0.080
    label_r, a0 = r_body + 0.0006, np.radians(25)
    cx, cz = -spec.width_m / 2 + r_body, spec.depth_m - label_r  # body back ~2 cm off the wall
    red = alt.HOUSING_RED
    body = _revolve([(0.0745, bottom + 0.030), (0.080, bottom + 0.035), (0.080, 0.120),
                     (0.076, 0.145), (0.064, 0.168), (0.045, 0.182), (0.024, 0.190),
                     (0.0, 0.191)], 1, (cx, 0, cz), red, segments=48)
    foot = _revolve([(0.0, bottom), (0.076, bottom), (0.0800, bottom + 0.004),
                     (0.0800, bottom + 0.032), (0.0, bottom + 0.032)], 1, (cx, 0, cz),
                    BLACK_PLASTIC, segments=48)
    label = _revolve([(label_r, -0.165), (label_r, 0.070)], 1, (cx, 0, cz), (238, 232, 212),
                     segments=40, angle_range=(a0, np.pi - a0))
    lw = label_r * np.cos(a0)
    label = _texture_front(label, alt.extinguisher_label(2 * lw, 0.235), x0=cx - lw, x1=cx + lw,
                           y0=-0.165, y1=0.070, min_nz=0.0)
    neck = cylinder(0.018, 0.035, (150, 120, 60), segments=24, centre=(cx, 0.205, cz), axis=1)  # brass
    valve = _box_span(cx - 0.026, cx + 0.026, 0.218, 0.250, z0=cz - 0.02, z1=cz + 0.02, colour=BLACK_PLASTIC)
    gauge = cylinder(0.014, 0.007, (235, 235, 228), segments=24, centre=(cx, 0.234, cz + 0.0235), axis=2)
    lever = _prism_xy(np.array([[cx - 0.055, 0.256], [cx + 0.060, 0.286], [cx + 0.057, top],
                                [cx - 0.058, 0.268]]), cz - 0.012, cz + 0.012, BLACK_PLASTIC)
    handle = _box_span(cx - 0.060, cx + 0.020, 0.250, 0.256, z0=cz - 0.011, z1=cz + 0.011,
                       colour=BLACK_PLASTIC)
    pin = _box_span(cx + 0.026, cx + 0.034, 0.238, 0.246, z0=cz - 0.004, z1=cz + 0.004, colour=(230, 190, 0))
    hose_x, hose_r = spec.width_m / 2 - 0.0095, 0.0085
    hose_top = 0.232
    hose_h = cylinder(hose_r, hose_x - cx - 0.02, BLACK_PLASTIC, segments=16,
                      centre=((hose_x + cx + 0.02) / 2, hose_top, cz), axis=0)
    hose_v = cylinder(hose_r, hose_top + 0.125, BLACK_PLASTIC, segments=16,
                      centre=(hose_x, (hose_top - 0.125) / 2, cz), axis=1)
    nozzle = cylinder(0.0095, 0.05, (25, 25, 25), segments=16, centre=(hose_x, -0.150, cz), axis=1)
    clip = _box_span(cx + r_body - 0.004, hose_x, -0.005, 0.005, z0=cz - 0.006, z1=cz + 0.006,
                     colour=STEEL_DARK)
    bracket = merge([
        _box_span(cx - 0.025, cx + 0.025, -0.05, 0.13, z0=0.0, z1=0.004, colour=STEEL_DARK),
        _box_span(cx - 0.020, cx + 0.020, 0.10, 0.13, z0=0.0, z1=0.026, colour=STEEL_DARK),
        _box_span(cx - 0.035, cx + 0.035, -0.02, 0.00, z0=0.0, z1=0.022, colour=STEEL_DARK),
    ])
    return merge([body, foot, label, neck, valve, gauge, lever, handle, pin, hose_h, hose_v,
                  nozzle, clip, bracket])


def _radiator() -> ColouredMesh:
    """Aluminium column radiator: 10 elements of 80 mm, each with a bowed front face,
    joined by top and bottom headers and hung on two brackets."""
    spec = CATALOGUE["radiator"]
    hw, hh, d = spec.width_m / 2, spec.height_m / 2, spec.depth_m
    n = round(spec.width_m / 0.08)
    pitch = spec.width_m / n
    ew = pitch / 2 - 0.002  # 4 mm gaps between elements
    section = np.array([[-ew, 0.030], [-ew, d - 0.008], [-0.4 * ew, d], [0.4 * ew, d],
                        [ew, d - 0.008], [ew, 0.030]])  # (x, z) of one element, convex

    def ring(y: float, shrink: float) -> np.ndarray:
        s = section.copy()
        s[:, 0] *= 1 - shrink
        s[:, 1] = 0.030 + (s[:, 1] - 0.030) * (1 - shrink)
        return np.column_stack([s[:, 0], np.full(len(s), y), s[:, 1]])

    parts = []
    for i in range(n):
        xc = -hw + (i + 0.5) * pitch
        rings = [ring(-hh, 0.10), ring(-hh + 0.008, 0.0), ring(hh - 0.008, 0.0), ring(hh, 0.10)]
        element = _loft([r + [xc, 0, 0] for r in rings], RADIATOR_WHITE, cap_start=True,
                        cap_end=True)
        parts.append(element)
    for y in (-hh + 0.05, hh - 0.05):
        # headers run through all elements; their end plugs reach the footprint's sides
        parts.append(cylinder(0.020, spec.width_m, (228, 228, 222), segments=20,
                              centre=(0, y, 0.052), axis=0))
    for x in (-0.6 * hw, 0.6 * hw):
        parts.append(_box_span(x - 0.015, x + 0.015, hh - 0.09, hh - 0.04, z0=0.0, z1=0.034,
                               colour=(120, 120, 118)))
    return merge(parts)


def _fire_alarm_switch() -> ColouredMesh:
    """Manual call point: red housing with a white element window (front texture)."""
    spec = CATALOGUE["fire_alarm_switch"]
    hw, hh = spec.width_m / 2, spec.height_m / 2
    housing = _plate(hw, hh, 0.006, 0.0, spec.depth_m, bevel=0.004, colour=alt.HOUSING_RED)
    return _texture_front(housing, alt.call_point_front(spec.width_m, spec.height_m),
                          x0=-hw, x1=hw, y0=-hh, y1=hh, min_nz=0.5)


def _smoke_detector() -> ColouredMesh:
    """Optical smoke detector: round base, rounded shoulder and a raised sensing chamber."""
    spec = CATALOGUE["smoke_detector"]
    r, d = spec.width_m / 2, spec.depth_m
    profile = [(r, 0.0), (r, 0.016), (r - 0.002, 0.024), (r - 0.006, 0.030), (r - 0.012, 0.034),
               (0.040, 0.036), (0.038, 0.037), (0.038, d - 0.005), (0.035, d - 0.001),
               (0.028, d), (0.0, d)]
    shell = _revolve(profile, 2, (0, 0, 0), (240, 240, 235), segments=64, cap_start=True)
    return _texture_front(shell, alt.smoke_detector_face(spec.width_m), x0=-r, x1=r, y0=-r, y1=r, min_nz=0.3)


def _exit_light() -> ColouredMesh:
    """Emergency exit luminaire: white housing, diffuser with a green exit pictogram."""
    spec = CATALOGUE["exit_light"]
    hw, hh = spec.width_m / 2, spec.height_m / 2
    housing = _plate(hw, hh, 0.010, 0.0, spec.depth_m, bevel=0.008, colour=WHITE_9016)
    return _texture_front(housing, alt.exit_light_front(spec.width_m, spec.height_m),
                          x0=-hw, x1=hw, y0=-hh, y1=hh, min_nz=0.5)


def _sign(class_id: str, draw: Callable[[float, float], np.ndarray]) -> Callable[[], ColouredMesh]:
    def build() -> ColouredMesh:
        spec = CATALOGUE[class_id]
        hw, hh = spec.width_m / 2, spec.height_m / 2
        plate = _box_span(-hw, hw, -hh, hh, z0=0.0, z1=spec.depth_m, colour=alt.SIGN_RED)
        return _texture_front(plate, draw(spec.width_m, spec.height_m), x0=-hw, x1=hw, y0=-hh, y1=hh,
                              min_nz=0.5)
    return build


def _electrical_panel() -> ColouredMesh:
    """Surface-mounted distribution board: white enclosure, door with smoked window."""
    spec = CATALOGUE["electrical_panel"]
    hw, hh, d = spec.width_m / 2, spec.height_m / 2, spec.depth_m
    body = _plate(hw, hh, 0.012, 0.0, d - 0.010, bevel=0.006, colour=WHITE_9016)
    dw, dh = hw - 0.005, hh - 0.005
    door = _plate(dw, dh, 0.010, d - 0.012, d - 0.003, bevel=0.002, colour=WHITE_9016)
    door = _texture_front(door, alt.electrical_panel_front(2 * dw, 2 * dh), x0=-dw, x1=dw, y0=-dh, y1=dh,
                          min_nz=0.5)
    # lock / handle on the door's right edge (matches the texture's lock plate)
    lx = -dw + 0.95 * 2 * dw
    ly = dh - 0.50 * 2 * dh
    handle = _box_span(lx - 0.008, lx + 0.008, ly - 0.045, ly + 0.045, z0=d - 0.003, z1=d,
                       colour=(90, 92, 94))
    return merge([body, door, handle])


BUILDERS_ALT: dict[str, Callable[[], ColouredMesh]] = {
    "electrical_panel": _electrical_panel,
    "socket_x1": _socket_row(1),
    "socket_x2": _socket_row(2),
    "socket_x4": _socket_row(4),
    "builtin_socket": _builtin_socket,
    "switch": _switch,
    "fire_extinguisher": _fire_extinguisher,
    "radiator": _radiator,
    "fire_alarm_switch": _fire_alarm_switch,
    "smoke_detector": _smoke_detector,
    "exit_light": _exit_light,
    "extinguisher_sign": _sign("extinguisher_sign", alt.extinguisher_sign),
    "fire_alarm_switch_sign": _sign("fire_alarm_switch_sign", alt.fire_alarm_sign),
}


def build_object_alt(class_id: str) -> ColouredMesh:
    """The alternative design of ``class_id`` in its object-local frame (see module doc).

    Deterministic: the same class always gives the same mesh. Unknown ids raise
    ``InputError("class", ...)``.
    """
    try:
        builder = BUILDERS_ALT[class_id]
    except KeyError:
        raise InputError("class", f"unknown class '{class_id}'") from None
    return builder()
