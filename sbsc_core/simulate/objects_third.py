"""The THIRD design set (``--designs third``): a third manufacturer's thirteen classes.

**For testing only, never for tuning.** No threshold, template or setting of recognition may
be chosen by looking at results on these designs; they exist so that a figure measured on
them says how recognition does on products it has never seen. Keep it that way.

Same contract as :mod:`objects` and :mod:`objects_alt` (object-local frame: x along the
wall, y up, z out of the wall; footprint of :data:`~sbsc_core.simulate.catalogue.CATALOGUE`
centred at x = y = 0, nothing deeper than ``depth_m``), but unlike both:

* shades: anthracite switch and radiator, ivory sockets, a light-grey (RAL 7035) steel
  panel, a stainless flush socket, a dark-red CO2 extinguisher with a black horn;
* reliefs: sockets as separate square gangs with rounded-square recesses and two round
  pin holes, a switch with two square push buttons, a radiator of horizontal flat tubes,
  a square smoke detector, a call point with a round raised push button, an exit blade
  (edge-lit acrylic panel hanging under a slim base);
* prints: the two signs are SAME-SIZE SQUARE red plates (0.20 x 0.20 m, centred in their
  catalogue footprints) with different pictograms: an extinguisher and a hand pressing a
  call point; plus other labels and breaker rows.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from ..errors import InputError
from . import pictograms as pic
from .catalogue import CATALOGUE
from .mesh import ColouredMesh, box, cylinder, merge, quad

Colour = Sequence[int]

IVORY = (232, 224, 204)
ANTHRACITE = (62, 64, 68)
RAL_7035 = (203, 208, 204)
STAINLESS = (168, 170, 172)
CO2_RED = (150, 24, 28)
SIGN_RED = (196, 24, 34)
WHITE = (244, 244, 240)
BLACK = (22, 22, 24)
EPS = 0.0004
SIGN_SIDE_M = 0.20


def _span(x0: float, x1: float, y0: float, y1: float, *, z0: float, z1: float,
          colour: Colour) -> ColouredMesh:
    return box((x1 - x0, y1 - y0, z1 - z0), colour, ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2))


def _front(w: float, h: float, z: float, image: np.ndarray, centre: Sequence[float] = (0.0, 0.0)) -> ColouredMesh:
    cx, cy = centre
    return quad((cx - w / 2, cy - h / 2, z), (w, 0, 0), (0, h, 0), texture=image)


# --------------------------------------------------------------------------- sockets and switch


def _gang_face(side: float) -> np.ndarray:
    """One socket gang seen straight on: rounded-square recess, two round pin holes, earth clips."""
    p = pic.Painter.new(side, side, IVORY)
    m = side * 0.16
    p.round_rect(m, m, side - m, side - m, side * 0.12, colour=(190, 182, 164))
    for x in (0.36, 0.64):
        p.circle((side * x, side * 0.5), side * 0.045, BLACK)
    p.rect(side * 0.46, m + side * 0.02, side * 0.54, m + side * 0.07, (150, 150, 150))
    p.rect(side * 0.46, side - m - side * 0.07, side * 0.54, side - m - side * 0.02, (150, 150, 150))
    return p.img


def _sockets(n: int) -> Callable[[], ColouredMesh]:
    def build() -> ColouredMesh:
        spec = CATALOGUE[f"socket_x{n}"]
        w, h, d = spec.width_m, spec.height_m, spec.depth_m
        parts = [_span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d * 0.35,
                       colour=(214, 206, 186))]  # mounting frame
        pitch = w / n
        side = min(pitch - 0.006, h - 0.006)
        for k in range(n):
            x = -w / 2 + (k + 0.5) * pitch
            parts.append(_span(x - side / 2, x + side / 2, -side / 2, side / 2, z0=d * 0.35, z1=d,
                               colour=IVORY))
            # rounded-square recess as a sunken inner block (darker floor)
            r = side * 0.34
            parts.append(_span(x - r, x + r, -r, r, z0=d * 0.35, z1=d - 0.004, colour=(190, 182, 164)))
            parts.append(_front(side, side, d + EPS, _gang_face(side), (x, 0.0)))
        return merge(parts)
    return build


def _builtin_socket() -> ColouredMesh:
    spec = CATALOGUE["builtin_socket"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    p = pic.Painter.new(w, h, STAINLESS)
    for k in range(0, int(w * 1000), 2):  # brushed lines
        p.rect(k / 1000, 0, k / 1000 + 0.0004, h, (158, 160, 162))
    p.round_rect(w * 0.15, h * 0.15, w * 0.85, h * 0.85, 0.01, colour=(120, 122, 126))  # flip lid seam
    p.rect(w * 0.4, h * 0.78, w * 0.6, h * 0.83, (70, 70, 72))  # finger slot
    return merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d, colour=STAINLESS),
                  _front(w, h, d + EPS, p.img)])


def _switch() -> ColouredMesh:
    spec = CATALOGUE["switch"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    plate = _span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d * 0.6, colour=ANTHRACITE)
    b = 0.026
    buttons = [_span(x - b / 2, x + b / 2, -b, b, z0=d * 0.6, z1=d,
                     colour=(86, 88, 92)) for x in (-0.016, 0.016)]
    p = pic.Painter.new(b, 2 * b, (86, 88, 92))
    p.circle((b / 2, 0.3 * b), 0.0015, (230, 160, 40))  # orientation LED
    leds = [_front(b, 2 * b, d + EPS, p.img, (x, 0.0)) for x in (-0.016, 0.016)]
    return merge([plate, *buttons, *leds])


# --------------------------------------------------------------------------- larger equipment


def _panel_front(w: float, h: float) -> np.ndarray:
    p = pic.Painter.new(w, h, RAL_7035)
    for k, y in enumerate((0.18, 0.46)):  # two windows onto breaker rows
        p.rect(w * 0.12, h * y, w * 0.88, h * (y + 0.2), (70, 76, 82))
        for i in range(12):
            x = w * 0.14 + i * w * 0.06
            p.rect(x, h * (y + 0.03), x + w * 0.045, h * (y + 0.17), [(235, 235, 230), (40, 90, 170)][(i + k) % 5 == 0])
    p.rect(w * 0.3, h * 0.8, w * 0.7, h * 0.86, WHITE)  # label strip
    p.text("UV-1", w * 0.5, h * 0.83, h * 0.03, BLACK)
    p.rect(w * 0.04, h * 0.42, w * 0.07, h * 0.58, (40, 40, 42))  # handle on the left
    return p.img


def _electrical_panel() -> ColouredMesh:
    spec = CATALOGUE["electrical_panel"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    body = _span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d - 0.006, colour=RAL_7035)
    door = _span(-w / 2 + 0.004, w / 2 - 0.004, -h / 2 + 0.004, h / 2 - 0.004, z0=d - 0.006,
                 z1=d - 0.002, colour=RAL_7035)
    handle = _span(-w / 2 + 0.016, -w / 2 + 0.028, -0.04, 0.04, z0=d - 0.002, z1=d, colour=(40, 40, 42))
    return merge([body, door, handle, _front(w - 0.008, h - 0.008, d - 0.002 + EPS, _panel_front(w - 0.008, h - 0.008))])


def _fire_extinguisher() -> ColouredMesh:
    """A CO2 extinguisher: slim dark-red cylinder, grey valve, black horn on the left, strap."""
    spec = CATALOGUE["fire_extinguisher"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    r = 0.07
    zc = d - r
    body_h = h * 0.72
    y0 = -h / 2
    parts = [cylinder(r, body_h, CO2_RED, segments=28, centre=(0.02, y0 + body_h / 2, zc), axis=1),
             cylinder(r * 0.55, 0.04, CO2_RED, segments=20, centre=(0.02, y0 + body_h + 0.02, zc), axis=1),
             _span(0.0, 0.04, y0 + body_h + 0.04, y0 + body_h + 0.1, z0=zc - 0.02, z1=zc + 0.02,
                   colour=(150, 150, 152)),
             _span(0.04, 0.09, y0 + body_h + 0.085, y0 + body_h + 0.1, z0=zc - 0.01, z1=zc + 0.01,
                   colour=BLACK),  # lever
             _span(-w / 2, -w / 2 + 0.035, y0 + 0.12, y0 + body_h * 0.7, z0=zc - 0.02, z1=zc + 0.02,
                   colour=BLACK),  # horn
             _span(-0.06, 0.1, y0 + body_h * 0.75, y0 + body_h * 0.78, z0=0.0, z1=zc + 0.002,
                   colour=(40, 40, 40)),  # strap
             _span(-0.03, 0.07, y0 + body_h * 0.55, y0 + body_h * 0.8, z0=0.0, z1=0.03,
                   colour=(60, 60, 62))]  # bracket
    p = pic.Painter.new(0.09, body_h * 0.3, WHITE)
    p.text("CO2", 0.045, body_h * 0.08, 0.02, BLACK)
    p.text_lines(0.01, body_h * 0.14, 0.08, 5, pitch_m=0.012, height_m=0.005, colour=BLACK, seed=3)
    parts.append(_front(0.09, body_h * 0.3, zc + r + EPS, p.img, (0.02, y0 + body_h * 0.4)))
    return merge(parts)


def _radiator() -> ColouredMesh:
    """A designer radiator of horizontal flat tubes on two vertical collectors, anthracite."""
    spec = CATALOGUE["radiator"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    parts = [_span(x - 0.025, x + 0.025, -h / 2, h / 2, z0=0.02, z1=d - 0.01,
                   colour=ANTHRACITE) for x in (-w / 2 + 0.025, w / 2 - 0.025)]
    n = 12
    pitch = h / n
    for k in range(n):
        y = -h / 2 + (k + 0.5) * pitch
        parts.append(_span(-w / 2 + 0.05, w / 2 - 0.05, y - pitch * 0.3, y + pitch * 0.3, z0=0.04,
                           z1=d, colour=ANTHRACITE))
    parts += [_span(x - 0.01, x + 0.01, -0.02, 0.02, z0=0.0, z1=0.02,
                    colour=(50, 50, 52)) for x in (-w / 3, w / 3)]
    return merge(parts)


def _fire_alarm_switch() -> ColouredMesh:
    spec = CATALOGUE["fire_alarm_switch"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    housing = _span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d - 0.012, colour=SIGN_RED)
    button = cylinder(0.026, 0.012, (236, 236, 230), segments=28, centre=(0.0, 0.0, d - 0.006), axis=2)
    p = pic.Painter.new(w, h, SIGN_RED)
    p.text("PUSH", w / 2, h * 0.88, h * 0.07, WHITE)
    ring = pic.Painter.new(0.052, 0.052, (236, 236, 230))
    ring.circle((0.026, 0.026), 0.015, (205, 40, 40))
    return merge([housing, _front(w, h, d - 0.012 + EPS, p.img), button,
                  _front(0.052 * 0.7, 0.052 * 0.7, d + EPS, ring.img[8:-8, 8:-8])])


def _smoke_detector() -> ColouredMesh:
    spec = CATALOGUE["smoke_detector"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    base = _span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d * 0.5, colour=(236, 236, 232))
    top = _span(-w / 2 + 0.012, w / 2 - 0.012, -h / 2 + 0.012, h / 2 - 0.012, z0=d * 0.5, z1=d,
                colour=(236, 236, 232))
    p = pic.Painter.new(w - 0.024, h - 0.024, (236, 236, 232))
    for k in range(5):  # slot vents
        y = 0.012 + k * 0.016
        p.rect(0.01, y, w - 0.034, y + 0.005, (150, 150, 148))
    p.circle((w - 0.04, h - 0.04), 0.002, (40, 200, 60))
    return merge([base, top, _front(w - 0.024, h - 0.024, d + EPS, p.img)])


def _exit_light() -> ColouredMesh:
    """An exit blade: a slim base on the wall and an edge-lit acrylic panel under it."""
    spec = CATALOGUE["exit_light"]
    w, h, d = spec.width_m, spec.height_m, spec.depth_m
    base = _span(-w / 2, w / 2, h / 2 - 0.03, h / 2, z0=0.0, z1=d, colour=(200, 202, 206))
    pw, ph = w * 0.9, h - 0.035
    panel = _span(-pw / 2, pw / 2, -h / 2, h / 2 - 0.03, z0=d / 2 - 0.004, z1=d / 2 + 0.004,
                  colour=(236, 242, 238))
    p = pic.Painter.new(pw, ph, (236, 242, 238))
    p.rect(0.01, 0.01, pw - 0.01, ph - 0.01, pic.SAFETY_GREEN)
    pic.running_man(p, pw * 0.58, 0.015, ph - 0.03, colour=WHITE)
    p.poly(np.array([[0.03, ph / 2], [0.09, ph * 0.2], [0.09, ph * 0.8]]), WHITE)  # arrow to the left
    p.rect(0.085, ph * 0.42, 0.16, ph * 0.58, WHITE)
    return merge([base, panel, _front(pw, ph, d / 2 + 0.004 + EPS, p.img, (0.0, -0.015))])


# --------------------------------------------------------------------------- the two signs


def _extinguisher_pictogram(side: float) -> np.ndarray:
    p = pic.Painter.new(side, side, SIGN_RED)
    m = 0.012
    p.rect(m, m, side - m, side - m, WHITE, width_m=0.004)  # white border line
    cx = side * 0.42
    p.round_rect(cx - 0.024, side * 0.33, cx + 0.024, side * 0.82, 0.012, colour=WHITE)  # cylinder
    p.rect(cx - 0.008, side * 0.25, cx + 0.008, side * 0.33, WHITE)  # valve
    p.line(np.array([[cx + 0.006, side * 0.27], [cx + 0.05, side * 0.24], [cx + 0.07, side * 0.3],
                     [cx + 0.07, side * 0.6]]), WHITE, 0.006)  # hose
    p.poly(np.array([[side * 0.72, side * 0.62], [side * 0.8, side * 0.74], [side * 0.64, side * 0.74]]), WHITE)
    return p.img


def _call_point_pictogram(side: float) -> np.ndarray:
    p = pic.Painter.new(side, side, SIGN_RED)
    m = 0.012
    p.rect(m, m, side - m, side - m, WHITE, width_m=0.004)
    p.rect(side * 0.22, side * 0.22, side * 0.62, side * 0.62, WHITE, width_m=0.007)  # the call point box
    p.circle((side * 0.42, side * 0.42), side * 0.07, WHITE)
    # a hand pressing it from the lower right
    p.poly(np.array([[side * 0.5, side * 0.5], [side * 0.62, side * 0.46], [side * 0.82, side * 0.66],
                     [side * 0.74, side * 0.82], [side * 0.56, side * 0.62]]), WHITE)
    p.line(np.array([[side * 0.5, side * 0.5], [side * 0.44, side * 0.44]]), WHITE, 0.01)  # finger
    return p.img


def _sign(class_id: str, draw: Callable[[float], np.ndarray]) -> Callable[[], ColouredMesh]:
    def build() -> ColouredMesh:
        d = CATALOGUE[class_id].depth_m
        s = SIGN_SIDE_M
        return merge([_span(-s / 2, s / 2, -s / 2, s / 2, z0=0.0, z1=d, colour=SIGN_RED),
                      _front(s, s, d + EPS, draw(s))])
    return build


BUILDERS_THIRD: dict[str, Callable[[], ColouredMesh]] = {
    "electrical_panel": _electrical_panel,
    "socket_x1": _sockets(1),
    "socket_x2": _sockets(2),
    "socket_x4": _sockets(4),
    "builtin_socket": _builtin_socket,
    "switch": _switch,
    "fire_extinguisher": _fire_extinguisher,
    "radiator": _radiator,
    "fire_alarm_switch": _fire_alarm_switch,
    "smoke_detector": _smoke_detector,
    "exit_light": _exit_light,
    "extinguisher_sign": _sign("extinguisher_sign", _extinguisher_pictogram),
    "fire_alarm_switch_sign": _sign("fire_alarm_switch_sign", _call_point_pictogram),
}


def build_object_third(class_id: str) -> ColouredMesh:
    """The third design of ``class_id`` in its object-local frame (testing only; see module doc)."""
    try:
        builder = BUILDERS_THIRD[class_id]
    except KeyError:
        raise InputError("class", f"unknown class '{class_id}'") from None
    return builder()

