"""Textures of the virtual objects: safety signs, labels and front panels drawn with OpenCV.

Every function returns an RGB ``(H, W, 3) uint8`` image of a rectangle ``width_m`` x
``height_m`` seen straight on (row 0 at the top), drawn at ``px_per_m`` pixels per metre
(default 2000, i.e. 0.5 mm pixels). Shapes are laid out in metres (x right, y *down*
from the top-left corner) or, for pictograms, in a unit square mapped onto a region.
Only OpenCV primitives are used (polygons, circles, lines and its built-in Hershey
font), so there is no font or image-file dependency.

The safety signs follow the layout of ISO 7010 (F001 fire extinguisher, F005 fire alarm
call point, E001/E002 emergency exit) with ISO 3864 safety colours; they are
recognisable look-alikes, not reproductions of the registered graphics.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

PX_PER_M = 2000.0  # 0.5 mm texture pixels

# Colours (RGB). RAL / ISO 3864 approximations.
SAFETY_RED = (200, 30, 40)
SAFETY_GREEN = (0, 132, 80)
PHOTOLUM_WHITE = (238, 242, 218)  # photoluminescent "white" glows pale yellow-green
RAL_3000 = (175, 43, 30)
RAL_9010 = (236, 234, 225)
RAL_9016 = (241, 240, 234)
BLACK = (25, 25, 25)

_SHIFT = 4  # sub-pixel bits for cv2 drawing
_SCALE = 1 << _SHIFT


@dataclass
class Painter:
    """An RGB canvas addressed in metres from its top-left corner (y down)."""

    img: np.ndarray
    px_per_m: float

    @staticmethod
    def new(width_m: float, height_m: float, colour: Sequence[int],
            px_per_m: float = PX_PER_M) -> Painter:
        w = max(1, round(width_m * px_per_m))
        h = max(1, round(height_m * px_per_m))
        img = np.empty((h, w, 3), np.uint8)
        img[:] = np.asarray(colour, np.uint8)
        return Painter(img, float(px_per_m))

    def _fix(self, pts: np.ndarray) -> np.ndarray:
        """Metres -> fixed-point pixel coordinates for cv2 (pixel centres at +0.5)."""
        return np.round((np.asarray(pts, float) * self.px_per_m - 0.5) * _SCALE).astype(np.int32)

    def _len(self, metres: float) -> int:
        return max(1, round(metres * self.px_per_m * _SCALE))

    def poly(self, pts: np.ndarray, colour: Sequence[int]) -> None:
        cv2.fillPoly(self.img, [self._fix(pts).reshape(-1, 1, 2)], _c(colour), cv2.LINE_AA, _SHIFT)

    def line(self, pts: np.ndarray, colour: Sequence[int], width_m: float, closed: bool = False) -> None:
        """A thick polyline with round caps and joints."""
        p = self._fix(pts)
        th = max(1, round(width_m * self.px_per_m))
        cv2.polylines(self.img, [p.reshape(-1, 1, 2)], closed, _c(colour), th, cv2.LINE_AA, _SHIFT)
        r = self._len(width_m / 2)
        for q in p:  # round joints / caps
            cv2.circle(self.img, (int(q[0]), int(q[1])), r, _c(colour), -1, cv2.LINE_AA, _SHIFT)

    def circle(self, centre: Sequence[float], radius_m: float, colour: Sequence[int],
               width_m: float | None = None) -> None:
        c = self._fix(np.asarray(centre, float))
        th = -1 if width_m is None else max(1, round(width_m * self.px_per_m))
        cv2.circle(self.img, (int(c[0]), int(c[1])), self._len(radius_m), _c(colour), th,
                   cv2.LINE_AA, _SHIFT)

    def ellipse(self, centre: Sequence[float], axes_m: Sequence[float], colour: Sequence[int],
                *, angle_deg: float = 0.0, arc_deg: tuple[float, float] = (0.0, 360.0),
                width_m: float | None = None) -> None:
        c = self._fix(np.asarray(centre, float))
        axes = (self._len(axes_m[0]), self._len(axes_m[1]))
        th = -1 if width_m is None else max(1, round(width_m * self.px_per_m))
        cv2.ellipse(self.img, (int(c[0]), int(c[1])), axes, angle_deg, arc_deg[0], arc_deg[1],
                    _c(colour), th, cv2.LINE_AA, _SHIFT)

    def rect(self, x0: float, y0: float, x1: float, y1: float, colour: Sequence[int],
             *, width_m: float | None = None) -> None:
        pts = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        if width_m is None:
            self.poly(pts, colour)
        else:
            self.line(pts, colour, width_m, closed=True)

    def round_rect(self, x0: float, y0: float, x1: float, y1: float, radius_m: float,
                   *, colour: Sequence[int]) -> None:
        self.poly(rounded_rect_outline(x0, y0, x1, y1, radius_m), colour)

    def text(self, text: str, x: float, y: float, height_m: float, colour: Sequence[int],
             *, thickness_m: float | None = None, centred: bool = True) -> None:
        """Text with OpenCV's built-in Hershey font; (x, y) is the centre (or baseline start)."""
        font = cv2.FONT_HERSHEY_SIMPLEX
        base_h = cv2.getTextSize("H", font, 1.0, 1)[0][1]
        scale = height_m * self.px_per_m / base_h
        th = max(1, round((thickness_m or height_m * 0.16) * self.px_per_m))
        (tw, tht), _ = cv2.getTextSize(text, font, scale, th)
        px, py = x * self.px_per_m, y * self.px_per_m
        org = (round(px - tw / 2), round(py + tht / 2)) if centred else (round(px), round(py))
        cv2.putText(self.img, text, org, font, scale, _c(colour), th, cv2.LINE_AA)

    def text_lines(self, x0: float, y0: float, x1: float, n: int, *, pitch_m: float,
                   height_m: float, colour: Sequence[int], seed: int = 0) -> None:
        """Rows of word-like bars standing in for small print."""
        rng = np.random.default_rng(seed)
        for i in range(n):
            y = y0 + i * pitch_m
            x = x0
            end = x1 - (rng.uniform(0.0, 0.35) * (x1 - x0) if i == n - 1 else 0.0)
            while x < end:
                wlen = min(rng.uniform(0.8, 3.5) * height_m, end - x)
                self.rect(x, y, x + wlen, y + height_m, colour)
                x += wlen + 0.7 * height_m


def _c(colour: Sequence[int]) -> tuple[int, int, int]:
    return tuple(int(c) for c in colour)  # type: ignore[return-value]


def rounded_rect_outline(x0: float, y0: float, x1: float, y1: float, radius_m: float,
                         *, per_corner: int = 8) -> np.ndarray:
    """Outline points of a rounded rectangle (any consistent orientation)."""
    r = min(radius_m, (x1 - x0) / 2, (y1 - y0) / 2)
    pts = []
    corners = [(x1 - r, y0 + r, -90), (x1 - r, y1 - r, 0), (x0 + r, y1 - r, 90), (x0 + r, y0 + r, 180)]
    for cx, cy, a0 in corners:
        a = np.radians(np.linspace(a0, a0 + 90, per_corner))
        pts.append(np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)]))
    return np.vstack(pts)


def _bezier(p0: Sequence[float], p1: Sequence[float], p2: Sequence[float], n: int = 16) -> np.ndarray:
    t = np.linspace(0, 1, n)[:, None]
    a, b, c = (np.asarray(p, float) for p in (p0, p1, p2))
    return (1 - t) ** 2 * a + 2 * (1 - t) * t * b + t ** 2 * c


def _map(unit_pts: np.ndarray, x0: float, y0: float, size: float) -> np.ndarray:
    """Unit-square coordinates (y down) onto a square region of ``size`` metres."""
    return np.asarray(unit_pts, float) * size + np.array([x0, y0])


def flame_outline(cx: float, base_y: float, w: float, h: float, lean: float = 0.12) -> np.ndarray:
    """A stylised flame: round base at ``base_y`` (y down), tip ``h`` above, leaning right."""
    tip = (cx + lean * w, base_y - h)
    right = _bezier((cx + 0.5 * w, base_y - 0.3 * w), (cx + 0.55 * w, base_y - 0.7 * h), tip)
    left = _bezier(tip, (cx - 0.35 * w, base_y - 0.55 * h), (cx - 0.5 * w, base_y - 0.3 * w))
    a = np.radians(np.linspace(180, 360, 14))
    base = np.column_stack([cx - 0.5 * w * np.cos(a), base_y - 0.3 * w - 0.3 * w * np.sin(a)])
    # base runs from the left point down round to the right point
    base = base[::-1] if base[0, 0] > base[-1, 0] else base
    return np.vstack([right, left, base])


def _flames(p: Painter, x0: float, y0: float, size: float, colour: Sequence[int]) -> None:
    """Three tongues of fire in the unit region (x0, y0, size)."""
    for cx, by, w, h, lean in ((0.50, 1.0, 0.55, 0.95, 0.10), (0.22, 1.0, 0.38, 0.62, -0.25),
                               (0.78, 1.0, 0.36, 0.55, 0.25)):
        p.poly(_map(flame_outline(cx, by, w, h, lean), x0, y0, size), colour)


def _extinguisher_glyph(p: Painter, x0: float, y0: float, size: float, *, colour: Sequence[int],
                        bg: Sequence[int]) -> None:
    """A fire extinguisher with hose, in the unit square (x0, y0, size), y down."""
    m = lambda pts: _map(np.asarray(pts, float), x0, y0, size)  # noqa: E731
    # body: cylinder with a domed shoulder
    body = np.vstack([
        [[0.32, 0.97], [0.32, 0.40]],
        _bezier((0.32, 0.40), (0.32, 0.27), (0.44, 0.25), 10),
        _bezier((0.56, 0.25), (0.68, 0.27), (0.68, 0.40), 10),
        [[0.68, 0.97]],
    ])
    p.poly(m(body), colour)
    p.rect(*m([0.45, 0.17]), *m([0.55, 0.26]), colour)  # neck
    p.poly(m([[0.36, 0.12], [0.60, 0.12], [0.62, 0.19], [0.38, 0.19]]), colour)  # valve head
    p.line(m([[0.40, 0.10], [0.73, 0.03]]), colour, 0.05 * size)  # lever
    p.line(m([[0.37, 0.16], [0.22, 0.20]]), colour, 0.04 * size)  # carrying handle
    hose = np.vstack([_bezier((0.60, 0.16), (0.86, 0.16), (0.85, 0.40), 12),
                      _bezier((0.85, 0.40), (0.84, 0.62), (0.80, 0.72), 10)])
    p.line(m(hose), colour, 0.045 * size)
    p.poly(m([[0.76, 0.70], [0.84, 0.72], [0.83, 0.84], [0.78, 0.84]]), colour)  # nozzle
    # a thin separating line between body and hose, like the pictogram's white outline
    p.line(m([[0.70, 0.42], [0.70, 0.95]]), bg, 0.012 * size)


def extinguisher_sign(width_m: float = 0.21, height_m: float = 0.30,
                      px_per_m: float = PX_PER_M) -> np.ndarray:
    """ISO 7010 F001-style sign: red square with a white extinguisher and flames, plus a
    band with a down arrow and the word EXTINTOR (the usual Spanish photoluminescent sign)."""
    p = Painter.new(width_m, height_m, SAFETY_RED, px_per_m)
    s = width_m
    b = 0.015 * s
    p.rect(b, b, s - b, height_m - b, PHOTOLUM_WHITE, width_m=0.008 * s)  # inner border line
    # pictogram square (upper part)
    _extinguisher_glyph(p, 0.22 * s, 0.14 * s, 0.70 * s, colour=PHOTOLUM_WHITE, bg=SAFETY_RED)
    _flames(p, 0.07 * s, 0.10 * s, 0.28 * s, PHOTOLUM_WHITE)
    # lower band: arrow and text
    y_band = min(height_m - 0.02 * s, s * 1.0)
    if height_m > 1.2 * s:
        p.line(np.array([[0.06 * s, y_band], [s - 0.06 * s, y_band]]), PHOTOLUM_WHITE, 0.006 * s)
        yc = (y_band + height_m) / 2
        ah = 0.55 * (height_m - y_band)
        ax = 0.16 * s
        p.poly(np.array([[ax - 0.05 * s, yc - ah / 2], [ax + 0.05 * s, yc - ah / 2],
                         [ax + 0.05 * s, yc], [ax + 0.11 * s, yc], [ax, yc + ah / 2],
                         [ax - 0.11 * s, yc], [ax - 0.05 * s, yc]]), PHOTOLUM_WHITE)
        p.text("EXTINTOR", 0.60 * s, yc, 0.28 * (height_m - y_band), PHOTOLUM_WHITE)
    return p.img


def fire_alarm_sign(width_m: float = 0.21, height_m: float = 0.21,
                    px_per_m: float = PX_PER_M) -> np.ndarray:
    """ISO 7010 F005-style sign: a hand pressing a call point, flames and sound arcs."""
    p = Painter.new(width_m, height_m, SAFETY_RED, px_per_m)
    s = min(width_m, height_m)
    x0, y0 = (width_m - s) / 2, (height_m - s) / 2
    m = lambda pts: _map(np.asarray(pts, float), x0, y0, s)  # noqa: E731
    b = 0.015 * s
    p.rect(b, b, width_m - b, height_m - b, PHOTOLUM_WHITE, width_m=0.008 * s)
    w = PHOTOLUM_WHITE
    # call-point box (outline) with the push button
    p.line(m([[0.40, 0.30], [0.88, 0.30], [0.88, 0.78], [0.40, 0.78]]), w, 0.05 * s, closed=True)
    p.circle(m([[0.64, 0.54]])[0], 0.09 * s, w)
    p.circle(m([[0.64, 0.54]])[0], 0.05 * s, SAFETY_RED)
    # hand: palm from the lower right, index finger pointing at the button
    palm = np.array([[0.74, 0.78], [0.97, 0.72], [0.99, 0.98], [0.78, 0.99], [0.70, 0.90]])
    p.poly(m(palm), w)
    p.line(m([[0.79, 0.84], [0.67, 0.60]]), w, 0.075 * s)  # index finger
    p.line(m([[0.67, 0.60], [0.655, 0.57]]), w, 0.06 * s)
    for k, (a, bb) in enumerate((((0.83, 0.86), (0.77, 0.77)), ((0.86, 0.90), (0.81, 0.80)))):
        p.line(m([a, bb]), SAFETY_RED, 0.012 * s)  # finger gaps
        del k
    # flames top-left, sound arcs above the box
    _flames(p, 0.05 * s, 0.36 * s, 0.32 * s, w)
    for r in (0.10, 0.17):
        p.ellipse(m([[0.64, 0.24]])[0], (r * s, r * s * 0.8), w, arc_deg=(200, 340),
                  width_m=0.03 * s)
    return p.img


def running_man(p: Painter, x0: float, y0: float, size: float, *, colour: Sequence[int],
                facing_left: bool = True) -> None:
    """ISO 7010 E001/E002-like running figure in the unit square (x0, y0, size)."""
    def m(pts: Sequence[Sequence[float]]) -> np.ndarray:
        a = np.asarray(pts, float)
        if not facing_left:
            a = a.copy()
            a[:, 0] = 1.0 - a[:, 0]
        return _map(a, x0, y0, size)

    th = 0.12 * size
    p.circle(m([[0.38, 0.12]])[0], 0.095 * size, colour)  # head
    p.line(m([[0.46, 0.30], [0.58, 0.58]]), colour, 0.16 * size)  # torso, leaning forward (left)
    p.line(m([[0.44, 0.32], [0.24, 0.40], [0.14, 0.30]]), colour, th)  # front arm
    p.line(m([[0.50, 0.34], [0.70, 0.32], [0.82, 0.44]]), colour, th)  # back arm
    p.line(m([[0.56, 0.60], [0.38, 0.72], [0.34, 0.96]]), colour, th)  # front leg
    p.line(m([[0.58, 0.62], [0.72, 0.78], [0.90, 0.80]]), colour, th)  # back leg
    p.line(m([[0.34, 0.96], [0.24, 0.96]]), colour, 0.08 * size)  # foot


def exit_light_front(width_m: float = 0.36, height_m: float = 0.14,
                     px_per_m: float = PX_PER_M) -> np.ndarray:
    """Front of an emergency exit luminaire: white diffuser with a green ISO 7010 E001-style
    panel (running man heading left into a door, arrow pointing left)."""
    p = Painter.new(width_m, height_m, (246, 246, 242), px_per_m)
    mx, my = 0.05 * height_m + 0.02, 0.10 * height_m
    gx0, gy0, gx1, gy1 = mx, my, width_m - mx, height_m - my
    p.rect(gx0, gy0, gx1, gy1, SAFETY_GREEN)
    gh = gy1 - gy0
    white = (250, 250, 250)
    # door (left part of the panel) with the figure running into it
    d0 = gx0 + 0.08 * gh
    p.rect(d0, gy0 + 0.08 * gh, d0 + 0.62 * gh, gy1 - 0.08 * gh, white)
    p.rect(d0 + 0.10 * gh, gy0 + 0.18 * gh, d0 + 0.52 * gh, gy1 - 0.08 * gh, SAFETY_GREEN)
    running_man(p, d0 + 0.35 * gh, gy0 + 0.10 * gh, 0.82 * gh, colour=white, facing_left=True)
    # arrow to the left
    ax0, ax1, ay = gx1 - 1.25 * gh, gx1 - 0.15 * gh, (gy0 + gy1) / 2
    p.poly(np.array([[ax0, ay], [ax0 + 0.40 * gh, ay - 0.38 * gh], [ax0 + 0.40 * gh, ay - 0.14 * gh],
                     [ax1, ay - 0.14 * gh], [ax1, ay + 0.14 * gh], [ax0 + 0.40 * gh, ay + 0.14 * gh],
                     [ax0 + 0.40 * gh, ay + 0.38 * gh]]), white)
    return p.img


def extinguisher_label(width_m: float, height_m: float, px_per_m: float = PX_PER_M) -> np.ndarray:
    """The printed label band of a powder extinguisher (as seen straight on)."""
    cream = (238, 232, 212)
    p = Painter.new(width_m, height_m, cream, px_per_m)
    w, h = width_m, height_m
    p.rect(0, 0, w, 0.14 * h, RAL_3000)  # red title band
    p.text("EXTINTOR", w / 2, 0.07 * h, 0.07 * h, cream)
    p.text("POLVO ABC", w / 2, 0.22 * h, 0.055 * h, BLACK)
    # fire-class boxes A B C
    bw = 0.16 * w
    for i, letter in enumerate("ABC"):
        x = 0.20 * w + i * 0.22 * w
        p.rect(x, 0.31 * h, x + bw, 0.31 * h + bw, BLACK, width_m=0.006 * w)
        p.text(letter, x + bw / 2, 0.31 * h + bw / 2, 0.55 * bw, BLACK)
    y = 0.33 * h + bw
    # instruction pictogram row (small dark figures) and small print
    for i in range(4):
        x = 0.12 * w + i * 0.20 * w
        p.rect(x, y, x + 0.15 * w, y + 0.15 * w, (60, 60, 60), width_m=0.004 * w)
        p.circle((x + 0.075 * w, y + 0.05 * w), 0.02 * w, (60, 60, 60))
        p.line(np.array([[x + 0.075 * w, y + 0.07 * w], [x + 0.06 * w, y + 0.13 * w]]),
               (60, 60, 60), 0.02 * w)
    y += 0.19 * w
    p.text_lines(0.08 * w, y, 0.92 * w, max(1, int((0.95 * h - y) / (0.035 * h))), pitch_m=0.035 * h,
                 height_m=0.016 * h, colour=(70, 70, 70), seed=3)
    return p.img


def call_point_front(width_m: float = 0.10, height_m: float = 0.10,
                     px_per_m: float = PX_PER_M) -> np.ndarray:
    """Front of a manual call point (EN 54-11 style): red housing, white glass/element window
    with a black press mark and small print, key slot below."""
    p = Painter.new(width_m, height_m, RAL_3000, px_per_m)
    w, h = width_m, height_m
    win = 0.62 * w
    x0, y0 = (w - win) / 2, 0.16 * h
    p.rect(x0 - 0.01 * w, y0 - 0.01 * w, x0 + win + 0.01 * w, y0 + win + 0.01 * w, (120, 30, 25))
    p.rect(x0, y0, x0 + win, y0 + win, (238, 240, 238))
    cx, cy = x0 + win / 2, y0 + 0.45 * win
    # the house-with-flame type mark and a press dot
    p.poly(np.array([[cx - 0.14 * win, cy - 0.02 * win], [cx, cy - 0.16 * win],
                     [cx + 0.14 * win, cy - 0.02 * win], [cx + 0.14 * win, cy + 0.16 * win],
                     [cx - 0.14 * win, cy + 0.16 * win]]), BLACK)
    p.poly(flame_outline(cx, cy + 0.13 * win, 0.13 * win, 0.20 * win), (238, 240, 238))
    p.text_lines(x0 + 0.12 * win, y0 + 0.78 * win, x0 + 0.88 * win, 2, pitch_m=0.08 * win,
                 height_m=0.035 * win,
                 colour=(40, 40, 40), seed=5)
    # key slot and test hole under the window
    p.rect(w / 2 - 0.05 * w, 0.86 * h, w / 2 + 0.05 * w, 0.89 * h, BLACK)
    p.circle((0.83 * w, 0.875 * h), 0.015 * w, BLACK)
    return p.img


def electrical_panel_front(width_m: float, height_m: float, px_per_m: float = PX_PER_M) -> np.ndarray:
    """Door of a surface-mounted distribution board: smoked window showing two rows of DIN
    rail breakers, a yellow ISO 7010 W012 electricity warning triangle and the lock."""
    body = RAL_9016
    p = Painter.new(width_m, height_m, body, px_per_m)
    w, h = width_m, height_m
    wx0, wy0, wx1, wy1 = 0.10 * w, 0.08 * h, 0.90 * w, 0.62 * h
    p.round_rect(wx0 - 0.008, wy0 - 0.008, wx1 + 0.008, wy1 + 0.008, 0.01, colour=(200, 200, 196))
    p.round_rect(wx0, wy0, wx1, wy1, 0.006, colour=(78, 86, 92))  # smoked window
    rows = 2
    row_h = (wy1 - wy0) / rows
    rng = np.random.default_rng(11)
    for r in range(rows):
        yc = wy0 + (r + 0.5) * row_h
        mod_h = 0.085
        x = wx0 + 0.02
        while x + 0.018 <= wx1 - 0.02:
            wide = 2 if rng.random() < 0.25 else 1
            mw = 0.0175 * wide
            if x + mw > wx1 - 0.02:
                break
            p.rect(x + 0.0005, yc - mod_h / 2, x + mw - 0.0005, yc + mod_h / 2, (196, 198, 196))
            tog = (40, 40, 40) if rng.random() < 0.8 else (40, 90, 170)
            p.rect(x + mw / 2 - 0.004, yc - 0.012, x + mw / 2 + 0.004, yc + 0.008, tog)
            p.rect(x + 0.003, yc + 0.022, x + mw - 0.003, yc + 0.027, (140, 140, 138))
            x += mw
        p.rect(wx0 + 0.01, yc - row_h * 0.42, wx1 - 0.01, yc - row_h * 0.40, (60, 64, 66))
    # warning triangle (yellow with black border and lightning bolt) under the window
    tc, ty, ts = w / 2, 0.70 * h, 0.07
    tri = np.array([[tc, ty], [tc + ts / 2, ty + 0.866 * ts], [tc - ts / 2, ty + 0.866 * ts]])
    p.poly(tri, BLACK)
    inner = (tri - tri.mean(0)) * 0.80 + tri.mean(0)
    p.poly(inner, (249, 200, 0))
    bolt = np.array([[0.02, -0.30], [-0.10, 0.05], [0.0, 0.05], [-0.03, 0.30], [0.10, -0.05],
                     [0.0, -0.05], [0.06, -0.30]]) * ts * 0.9 + [tc, ty + 0.55 * ts]
    p.poly(bolt, BLACK)
    # lock on the right edge, maker plate at the bottom
    p.round_rect(0.90 * w, 0.40 * h, 0.96 * w, 0.56 * h, 0.006, colour=(150, 152, 150))
    p.circle((0.93 * w, 0.48 * h), 0.006, (50, 50, 50))
    p.rect(0.40 * w, 0.90 * h, 0.60 * w, 0.92 * h, (170, 172, 170))
    return p.img


def socket_cup_floor(diameter_m: float, px_per_m: float = PX_PER_M,
                     colour: Sequence[int] = (118, 118, 116)) -> np.ndarray:
    """Floor of a Schuko (CEE 7/3) outlet cup: two pin holes 19 mm apart and the earthing
    clips at top and bottom, seen straight on (square image over the cup's diameter)."""
    p = Painter.new(diameter_m, diameter_m, colour, px_per_m)
    c = diameter_m / 2
    for dx in (-0.0095, 0.0095):
        p.circle((c + dx, c), 0.0032, (200, 200, 196))  # pin bushing collar
        p.circle((c + dx, c), 0.0024, (20, 20, 20))
    for sy in (-1, 1):
        y = c + sy * (c - 0.0035)
        p.rect(c - 0.005, y - 0.002, c + 0.005, y + 0.002, (178, 176, 170))  # earthing clip
    return p.img


def smoke_detector_face(diameter_m: float, px_per_m: float = PX_PER_M) -> np.ndarray:
    """Front of an optical smoke detector: white with a ring of vent slots round the
    chamber, a red LED and a moulded centre ring (square image over the diameter)."""
    white = (240, 240, 235)
    p = Painter.new(diameter_m, diameter_m, white, px_per_m)
    c = diameter_m / 2
    r0, r1 = 0.33 * diameter_m, 0.40 * diameter_m
    n = 24
    for k in range(n):
        a0 = 2 * np.pi * k / n
        a1 = a0 + 2 * np.pi / n * 0.55
        arc = np.linspace(a0, a1, 6)
        outer = np.column_stack([c + r1 * np.cos(arc), c + r1 * np.sin(arc)])
        inner = np.column_stack([c + r0 * np.cos(arc[::-1]), c + r0 * np.sin(arc[::-1])])
        p.poly(np.vstack([outer, inner]), (92, 94, 94))
    p.circle((c, c), 0.22 * diameter_m, (226, 226, 221), width_m=0.003)
    p.circle((c + 0.17 * diameter_m, c + 0.17 * diameter_m), 0.022 * diameter_m, (210, 20, 25))
    return p.img
