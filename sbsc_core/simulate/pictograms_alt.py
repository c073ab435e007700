"""Textures of the ALTERNATIVE design set (:mod:`objects_alt`): another maker's prints.

Same conventions as :mod:`pictograms` (RGB ``(H, W, 3) uint8``, metres from the top-left
corner, y down, 0.5 mm pixels by default) and the same drawing helpers, but every front is
laid out differently, the way a second manufacturer's product differs from the first:
the signs keep their ISO 7010 meaning (F001, F005, E001/E002) with a different drawing and
layout, the luminaire runs right instead of left, the distribution board shows three rows
of breakers behind a lighter window, the call point has a larger window with a diagonal
press mark, the smoke detector has radial vent slots.

The drawings of :mod:`pictograms` (the standard set) are not touched.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .pictograms import (
    BLACK,
    PX_PER_M,
    Painter,
    _bezier,
    _flames,
    _map,
    flame_outline,
    running_man,
)

# The alternative maker's shades (ISO 3864 / RAL tolerances allow this much).
SIGN_RED = (214, 42, 46)
SIGN_GREEN = (0, 145, 95)
PHOTOLUM = (242, 240, 206)  # a yellower photoluminescent pigment
HOUSING_RED = (190, 38, 34)  # red of the call point and extinguisher print
PANEL_WHITE = (236, 237, 233)


def _extinguisher_glyph_alt(p: Painter, x0: float, y0: float, size: float, *, colour: Sequence[int],
                            bg: Sequence[int]) -> None:
    """A slimmer extinguisher with a flat shoulder and the hose looping to the left."""
    m = lambda pts: _map(np.asarray(pts, float), x0, y0, size)  # noqa: E731
    body = np.vstack([
        [[0.40, 0.97], [0.40, 0.36]],
        _bezier((0.40, 0.36), (0.40, 0.28), (0.50, 0.27), 8),
        _bezier((0.56, 0.27), (0.66, 0.28), (0.66, 0.36), 8),
        [[0.66, 0.97]],
    ])
    p.poly(m(body), colour)
    p.rect(*m([0.48, 0.18]), *m([0.58, 0.28]), colour)  # neck
    p.poly(m([[0.42, 0.13], [0.64, 0.13], [0.64, 0.19], [0.42, 0.19]]), colour)  # valve head
    p.line(m([[0.46, 0.11], [0.78, 0.07]]), colour, 0.045 * size)  # lever
    p.line(m([[0.44, 0.15], [0.30, 0.09]]), colour, 0.04 * size)  # carrying handle
    hose = np.vstack([_bezier((0.44, 0.17), (0.22, 0.18), (0.22, 0.42), 12),
                      _bezier((0.22, 0.42), (0.22, 0.60), (0.27, 0.70), 10)])
    p.line(m(hose), colour, 0.05 * size)
    p.poly(m([[0.23, 0.68], [0.31, 0.70], [0.31, 0.82], [0.25, 0.82]]), colour)  # nozzle
    p.line(m([[0.38, 0.42], [0.38, 0.95]]), bg, 0.014 * size)
    p.rect(*m([0.42, 0.52]), *m([0.64, 0.74]), bg, width_m=0.012 * size)  # label outline


def extinguisher_sign(width_m: float = 0.21, height_m: float = 0.30,
                      px_per_m: float = PX_PER_M) -> np.ndarray:
    """F001-style sign of the second maker: no border line, flames on the right, the text
    band at the bottom with the arrow on the RIGHT and the word on the left."""
    p = Painter.new(width_m, height_m, SIGN_RED, px_per_m)
    s = width_m
    _extinguisher_glyph_alt(p, 0.04 * s, 0.08 * s, 0.74 * s, colour=PHOTOLUM, bg=SIGN_RED)
    _flames(p, 0.68 * s, 0.08 * s, 0.26 * s, PHOTOLUM)
    y_band = min(height_m - 0.02 * s, 1.02 * s)
    if height_m > 1.2 * s:
        p.rect(0.0, y_band, s, height_m, PHOTOLUM)  # a light band with red print
        yc = (y_band + height_m) / 2
        ah = 0.60 * (height_m - y_band)
        ax = 0.84 * s
        p.poly(np.array([[ax - 0.045 * s, yc - ah / 2], [ax + 0.045 * s, yc - ah / 2],
                         [ax + 0.045 * s, yc], [ax + 0.10 * s, yc], [ax, yc + ah / 2],
                         [ax - 0.10 * s, yc], [ax - 0.045 * s, yc]]), SIGN_RED)
        p.text("EXTINTOR", 0.40 * s, yc, 0.30 * (height_m - y_band), SIGN_RED)
    return p.img


def fire_alarm_sign(width_m: float = 0.21, height_m: float = 0.21,
                    px_per_m: float = PX_PER_M) -> np.ndarray:
    """F005-style sign of the second maker: a rounded fist pressing a filled call-point box,
    three sound arcs, flames at the bottom left, a thin rounded border."""
    p = Painter.new(width_m, height_m, SIGN_RED, px_per_m)
    s = min(width_m, height_m)
    x0, y0 = (width_m - s) / 2, (height_m - s) / 2
    m = lambda pts: _map(np.asarray(pts, float), x0, y0, s)  # noqa: E731
    w = PHOTOLUM
    p.round_rect(0.03 * s, 0.03 * s, width_m - 0.03 * s, height_m - 0.03 * s, 0.04 * s, colour=w)
    p.round_rect(0.045 * s, 0.045 * s, width_m - 0.045 * s, height_m - 0.045 * s, 0.03 * s,
                 colour=SIGN_RED)
    # filled call-point box with a red push button ring
    p.rect(*m([0.42, 0.26]), *m([0.86, 0.70]), w)
    p.circle(m([[0.64, 0.48]])[0], 0.11 * s, SIGN_RED)
    p.circle(m([[0.64, 0.48]])[0], 0.06 * s, w)
    # hand from the lower right: a rounded fist with the index finger on the button
    a = np.radians(np.linspace(0, 360, 24, endpoint=False))
    fist = np.column_stack([0.84 + 0.12 * np.cos(a), 0.86 + 0.10 * np.sin(a)])
    p.poly(m(fist), w)
    p.line(m([[0.78, 0.80], [0.665, 0.545]]), w, 0.075 * s)  # index finger
    p.line(m([[0.76, 0.88], [0.68, 0.82]]), w, 0.06 * s)  # thumb
    p.line(m([[0.78, 0.91], [0.93, 0.82]]), SIGN_RED, 0.012 * s)  # knuckle crease
    _flames(p, 0.08 * s, 0.62 * s, 0.30 * s, w)
    for r in (0.08, 0.13, 0.18):
        p.ellipse(m([[0.64, 0.22]])[0], (r * s, r * s * 0.7), w, arc_deg=(210, 330),
                  width_m=0.022 * s)
    return p.img


def exit_light_front(width_m: float = 0.36, height_m: float = 0.14,
                     px_per_m: float = PX_PER_M) -> np.ndarray:
    """Diffuser of the second maker's exit luminaire: a green panel almost to the edges,
    E002-style (arrow on the LEFT pointing right, figure running right into a door)."""
    p = Painter.new(width_m, height_m, (240, 242, 240), px_per_m)
    mx, my = 0.012, 0.06 * height_m
    gx0, gy0, gx1, gy1 = mx, my, width_m - mx, height_m - my
    p.round_rect(gx0, gy0, gx1, gy1, 0.006, colour=SIGN_GREEN)
    gh = gy1 - gy0
    white = (248, 250, 246)
    # arrow to the right, at the left end
    ax0, ax1, ay = gx0 + 0.12 * gh, gx0 + 1.10 * gh, (gy0 + gy1) / 2
    p.poly(np.array([[ax1, ay], [ax1 - 0.40 * gh, ay - 0.36 * gh], [ax1 - 0.40 * gh, ay - 0.12 * gh],
                     [ax0, ay - 0.12 * gh], [ax0, ay + 0.12 * gh], [ax1 - 0.40 * gh, ay + 0.12 * gh],
                     [ax1 - 0.40 * gh, ay + 0.36 * gh]]), white)
    # door at the right end with the figure running into it
    d1 = gx1 - 0.10 * gh
    d0 = d1 - 0.58 * gh
    p.rect(d0, gy0 + 0.10 * gh, d1, gy1 - 0.06 * gh, white)
    p.rect(d0 + 0.08 * gh, gy0 + 0.20 * gh, d1 - 0.08 * gh, gy1 - 0.06 * gh, SIGN_GREEN)
    running_man(p, d0 - 0.62 * gh, gy0 + 0.12 * gh, 0.80 * gh, colour=white, facing_left=False)
    return p.img


def extinguisher_label(width_m: float, height_m: float, px_per_m: float = PX_PER_M) -> np.ndarray:
    """Label of the second maker's extinguisher: white, black title, coloured fire-class
    pictograms in a row and dense small print."""
    bg = (244, 243, 236)
    p = Painter.new(width_m, height_m, bg, px_per_m)
    w, h = width_m, height_m
    p.text("EXTINTOR", w / 2, 0.06 * h, 0.065 * h, BLACK)
    p.rect(0.06 * w, 0.11 * h, 0.94 * w, 0.12 * h, HOUSING_RED)
    p.text("POLVO ABC 6 kg", w / 2, 0.17 * h, 0.045 * h, HOUSING_RED)
    bw = 0.20 * w
    for i, col in enumerate(((40, 120, 60), (200, 60, 40), (40, 70, 160))):
        x = 0.12 * w + i * 0.27 * w
        p.round_rect(x, 0.24 * h, x + bw, 0.24 * h + bw, 0.004, colour=col)
        p.text("ABC"[i], x + bw / 2, 0.24 * h + bw / 2, 0.5 * bw, bg)
    y = 0.27 * h + bw
    p.text_lines(0.08 * w, y, 0.92 * w, max(1, int((0.95 * h - y) / (0.03 * h))), pitch_m=0.03 * h,
                 height_m=0.009 * h, colour=(110, 108, 100), seed=7)
    return p.img


def call_point_front(width_m: float = 0.10, height_m: float = 0.10,
                     px_per_m: float = PX_PER_M) -> np.ndarray:
    """Front of the second maker's call point: a large square element with a diagonal
    press-here band and a small house-and-flame mark, no key slot (test key at the side)."""
    p = Painter.new(width_m, height_m, HOUSING_RED, px_per_m)
    w, h = width_m, height_m
    win = 0.74 * w
    x0, y0 = (w - win) / 2, (h - win) / 2
    p.rect(x0, y0, x0 + win, y0 + win, (244, 244, 240))
    # diagonal band across the element (lower left to upper right)
    band = np.array([[x0, y0 + 0.80 * win], [x0 + 0.80 * win, y0], [x0 + win, y0],
                     [x0 + win, y0 + 0.20 * win], [x0 + 0.20 * win, y0 + win], [x0, y0 + win]])
    p.poly(band, (215, 215, 210))
    cx, cy = x0 + 0.30 * win, y0 + 0.30 * win
    p.poly(np.array([[cx - 0.11 * win, cy], [cx, cy - 0.11 * win], [cx + 0.11 * win, cy],
                     [cx + 0.11 * win, cy + 0.12 * win], [cx - 0.11 * win, cy + 0.12 * win]]), BLACK)
    p.poly(flame_outline(cx, cy + 0.10 * win, 0.10 * win, 0.15 * win), (244, 244, 240))
    p.text_lines(x0 + 0.50 * win, y0 + 0.70 * win, x0 + 0.92 * win, 3, pitch_m=0.07 * win,
                 height_m=0.03 * win,
                 colour=(50, 50, 50), seed=9)
    p.circle((0.06 * w, 0.50 * h), 0.012 * w, BLACK)  # test key hole in the side border
    return p.img


def electrical_panel_front(width_m: float, height_m: float, px_per_m: float = PX_PER_M) -> np.ndarray:
    """Door of the second maker's distribution board: a tall lighter window with three rows
    of breakers, the warning triangle at the top left, a slim handle on the right."""
    p = Painter.new(width_m, height_m, PANEL_WHITE, px_per_m)
    w, h = width_m, height_m
    wx0, wy0, wx1, wy1 = 0.08 * w, 0.18 * h, 0.86 * w, 0.86 * h
    p.round_rect(wx0 - 0.005, wy0 - 0.005, wx1 + 0.005, wy1 + 0.005, 0.008, colour=(180, 182, 180))
    p.round_rect(wx0, wy0, wx1, wy1, 0.004, colour=(120, 132, 140))  # lighter smoked window
    rows = 3
    row_h = (wy1 - wy0) / rows
    rng = np.random.default_rng(23)
    for r in range(rows):
        yc = wy0 + (r + 0.5) * row_h
        mod_h = 0.070
        x = wx0 + 0.015
        while x + 0.018 <= wx1 - 0.015:
            wide = 3 if rng.random() < 0.15 else 1
            mw = 0.018 * wide
            if x + mw > wx1 - 0.015:
                break
            p.rect(x + 0.0005, yc - mod_h / 2, x + mw - 0.0005, yc + mod_h / 2, (212, 212, 206))
            tog = (30, 30, 30) if rng.random() < 0.6 else (200, 40, 40)
            p.rect(x + mw / 2 - 0.0035, yc - 0.010, x + mw / 2 + 0.0035, yc + 0.006, tog)
            x += mw
        p.rect(wx0 + 0.005, yc + row_h * 0.40, wx1 - 0.005, yc + row_h * 0.43, (70, 74, 76))
    # warning triangle top-left, maker strip top-right
    tc, ty, ts = 0.16 * w, 0.03 * h, 0.055
    tri = np.array([[tc, ty], [tc + ts / 2, ty + 0.866 * ts], [tc - ts / 2, ty + 0.866 * ts]])
    p.poly(tri, BLACK)
    inner = (tri - tri.mean(0)) * 0.78 + tri.mean(0)
    p.poly(inner, (250, 205, 10))
    bolt = np.array([[0.02, -0.30], [-0.10, 0.05], [0.0, 0.05], [-0.03, 0.30], [0.10, -0.05],
                     [0.0, -0.05], [0.06, -0.30]]) * ts * 0.9 + [tc, ty + 0.55 * ts]
    p.poly(bolt, BLACK)
    p.rect(0.55 * w, 0.07 * h, 0.85 * w, 0.09 * h, (150, 152, 150))
    # slim handle on the right edge
    p.round_rect(0.925 * w, 0.40 * h, 0.975 * w, 0.60 * h, 0.006, colour=(90, 92, 94))
    p.circle((0.95 * w, 0.45 * h), 0.005, (30, 30, 30))
    return p.img


def socket_cup_floor(diameter_m: float, px_per_m: float = PX_PER_M,
                     colour: Sequence[int] = (168, 166, 160)) -> np.ndarray:
    """Floor of the second maker's Schuko cup: lighter plastic, child-protection shutters
    over the pin holes (dark slots), earthing clips at top and bottom."""
    p = Painter.new(diameter_m, diameter_m, colour, px_per_m)
    c = diameter_m / 2
    for dx in (-0.0095, 0.0095):
        p.circle((c + dx, c), 0.0036, (214, 212, 206))  # shutter disc
        p.rect(c + dx - 0.0026, c - 0.0007, c + dx + 0.0026, c + 0.0007, (45, 45, 45))
    for sy in (-1, 1):
        y = c + sy * (c - 0.003)
        p.rect(c - 0.006, y - 0.0018, c + 0.006, y + 0.0018, (190, 186, 150))  # brass clip
    return p.img


def smoke_detector_face(diameter_m: float, px_per_m: float = PX_PER_M) -> np.ndarray:
    """Front of the second maker's smoke detector: radial vent slots, a solid centre cap,
    the LED next to the centre."""
    white = (236, 236, 230)
    p = Painter.new(diameter_m, diameter_m, white, px_per_m)
    c = diameter_m / 2
    n = 16
    for k in range(n):
        a = 2 * np.pi * (k + 0.5) / n
        r0, r1 = 0.20 * diameter_m, 0.34 * diameter_m
        p.line(np.array([[c + r0 * np.cos(a), c + r0 * np.sin(a)],
                         [c + r1 * np.cos(a), c + r1 * np.sin(a)]]), (120, 122, 120), 0.0025)
    p.circle((c, c), 0.17 * diameter_m, (246, 246, 242))
    p.circle((c, c), 0.17 * diameter_m, (210, 210, 205), width_m=0.0015)
    p.circle((c + 0.09 * diameter_m, c - 0.02 * diameter_m), 0.02 * diameter_m, (220, 40, 30))
    return p.img

