"""Prints of the random design families: pictograms drawn from a small grammar.

A print is a background, an optional border line, one class glyph (what the sign means:
an extinguisher, a call point, a running figure) and optional extras (flames, an arrow,
rows of text-like bars), laid out in one of a few arrangements. A :class:`PrintStyle` holds
every choice; it is drawn once per family from the family's generator
(:func:`draw_print_style`), so drawing the print is deterministic and needs no generator.

Shapes are the ones real safety signs are made of (ISO 7010 layouts: a square pictogram
field, a text band below or beside it, arrows); glyph variants differ the way two
manufacturers' versions of one sign do. Textures follow :mod:`pictograms` (RGB, row 0 at
the top, 0.5 mm pixels).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import pictograms as pg
from .pictograms import Painter, flame_outline, running_man

RGB = tuple[int, int, int]

GLYPHS = ("extinguisher", "call_point", "exit")
LAYOUTS = ("glyph", "glyph_band", "glyph_side")  # glyph alone; text band below; extras beside


@dataclass(frozen=True)
class PrintStyle:
    """Every choice of one print (see the module docstring)."""

    background: RGB
    ink: RGB
    layout: str  # one of LAYOUTS
    variant: int  # glyph variant 0..2
    border: bool
    flames: bool
    arrow: int  # 0 none, else direction: 1 down, 2 left, 3 right
    text_rows: int  # rows of text-like bars in the band
    mirrored: bool
    bars_seed: int


def draw_print_style(rng: np.random.Generator, background: Sequence[int], ink: Sequence[int]) -> PrintStyle:
    """A print style in ``background`` and ``ink`` with the other choices drawn from ``rng``."""
    return PrintStyle(tuple(int(c) for c in background), tuple(int(c) for c in ink),
                      str(rng.choice(LAYOUTS)), int(rng.integers(3)), bool(rng.random() < 0.6),
                      bool(rng.random() < 0.5), int(rng.integers(4)), int(rng.integers(1, 3)),
                      bool(rng.random() < 0.5), int(rng.integers(1 << 30)))


def draw_print(glyph: str, width_m: float, height_m: float, style: PrintStyle) -> np.ndarray:
    """The print of ``glyph`` on a ``width_m`` x ``height_m`` face in ``style``."""
    p = Painter.new(width_m, height_m, style.background)
    s = min(width_m, height_m)
    if style.border:
        b = 0.04 * s
        p.rect(b, b, width_m - b, height_m - b, style.ink, width_m=0.025 * s)
    field, rest = _layout(width_m, height_m, style.layout)
    fx, fy, fs = field
    m = 0.12 * fs
    _GLYPH[glyph](p, fx + m, fy + m, fs - 2 * m, style)
    if style.flames and glyph != "exit":
        _flames(p, fx + 0.04 * fs, fy + 0.5 * fs, 0.34 * fs, ink=style.ink, mirrored=style.mirrored)
    if rest is not None:
        _extras(p, rest, style)
    return p.img


def _layout(w: float, h: float, layout: str) -> tuple[tuple[float, float, float], tuple | None]:
    """The square pictogram field (x, y, side) and the rectangle left for extras (or None)."""
    if layout == "glyph_band" and h > 1.15 * w:
        return (0.0, 0.0, w), (0.0, w, w, h)
    if layout == "glyph_side" and w > 1.15 * h:
        return (0.0, 0.0, h), (h, 0.0, w, h)
    s = min(w, h)
    return ((w - s) / 2, (h - s) / 2, s), None


def _extras(p: Painter, rect: tuple[float, float, float, float], style: PrintStyle) -> None:
    """An arrow and rows of text-like bars in ``rect`` (x0, y0, x1, y1)."""
    x0, y0, x1, y1 = rect
    w, h = x1 - x0, y1 - y0
    s = min(w, h)
    tx0 = x0 + 0.08 * w
    if style.arrow:
        _arrow(p, x0 + 0.08 * w + 0.35 * s, (y0 + y1) / 2, 0.6 * s, direction=style.arrow, ink=style.ink)
        tx0 = x0 + 0.16 * w + 0.7 * s
    rows = style.text_rows
    bar = min(0.16 * h, 0.5 * h / rows)
    pitch = 1.8 * bar
    top = (y0 + y1) / 2 - (rows * pitch - 0.8 * bar) / 2
    if x1 - 0.06 * w - tx0 > 2 * bar:
        p.text_lines(tx0, top, x1 - 0.06 * w, rows, pitch_m=pitch, height_m=bar, colour=style.ink,
                     seed=style.bars_seed)


def _arrow(p: Painter, cx: float, cy: float, size: float, *, direction: int, ink: RGB) -> None:
    """A block arrow of ``size`` centred at (cx, cy): 1 down, 2 left, 3 right."""
    unit = np.array([[-0.18, -0.5], [0.18, -0.5], [0.18, 0.05], [0.42, 0.05], [0.0, 0.5],
                     [-0.42, 0.05], [-0.18, 0.05]])  # pointing down (y down)
    turn = {1: np.eye(2), 2: np.array([[0.0, -1.0], [1.0, 0.0]]), 3: np.array([[0.0, 1.0], [-1.0, 0.0]])}[direction]
    p.poly(unit @ turn.T * size + (cx, cy), ink)


def _map(pts: Sequence[Sequence[float]], x0: float, y0: float, size: float, mirrored: bool) -> np.ndarray:
    a = np.asarray(pts, float)
    if mirrored:
        a = a.copy()
        a[:, 0] = 1.0 - a[:, 0]
    return a * size + (x0, y0)


def _flames(p: Painter, x0: float, y0: float, size: float, *, ink: RGB, mirrored: bool) -> None:
    """Two tongues of fire in the unit square (x0, y0, size)."""
    for cx, w, h, lean in ((0.35, 0.5, 0.9, 0.1), (0.72, 0.36, 0.6, 0.25)):
        outline = flame_outline(cx, 1.0, w, h, lean)
        p.poly(_map(outline, x0, y0, size, mirrored), ink)


def _extinguisher(p: Painter, x0: float, y0: float, size: float, style: PrintStyle) -> None:
    """An extinguisher in the unit square: body, valve, and a hose (three variants)."""
    ink, bg, v = style.ink, style.background, style.variant
    m = lambda pts: _map(pts, x0, y0, size, style.mirrored)  # noqa: E731
    body_w = (0.30, 0.38, 0.24)[v]
    left = 0.5 - body_w / 2
    top = (0.28, 0.34, 0.22)[v]
    p.poly(m([[left, 0.98], [left, top + 0.06], [left + 0.05, top], [left + body_w - 0.05, top],
              [left + body_w, top + 0.06], [left + body_w, 0.98]]), ink)
    p.poly(m([[0.42, top], [0.58, top], [0.58, top - 0.08], [0.42, top - 0.08]]), ink)  # valve
    p.line(m([[0.40, top - 0.1], [0.70, top - 0.16]]), ink, 0.05 * size)  # lever
    if v == 0:  # hose down the right side
        p.line(m([[0.58, top - 0.05], [0.84, top], [0.84, 0.70]]), ink, 0.05 * size)
    elif v == 1:  # short horn
        p.poly(m([[0.62, top - 0.04], [0.90, top + 0.20], [0.82, top + 0.26], [0.60, top + 0.04]]), ink)
    else:  # hose and a label band cut out of the body
        p.line(m([[0.58, top - 0.05], [0.78, top + 0.05], [0.74, 0.85]]), ink, 0.04 * size)
        p.rect(*m([[left + 0.04, 0.55]])[0], *m([[left + body_w - 0.04, 0.7]])[0], bg)


def _call_point(p: Painter, x0: float, y0: float, size: float, style: PrintStyle) -> None:
    """A call point in the unit square: a box with a button, and a hand or sound arcs."""
    ink, bg, v = style.ink, style.background, style.variant
    m = lambda pts: _map(pts, x0, y0, size, style.mirrored)  # noqa: E731
    box = [[0.34, 0.26], [0.90, 0.26], [0.90, 0.82], [0.34, 0.82]]
    p.line(m(box), ink, 0.06 * size, closed=True)
    centre = m([[0.62, 0.54]])[0]
    p.circle(centre, 0.11 * size, ink)
    p.circle(centre, 0.05 * size, bg)
    if v in (0, 2):  # a hand pressing from below
        p.poly(m([[0.70, 0.80], [0.98, 0.74], [1.0, 1.0], [0.76, 1.0]]), ink)
        p.line(m([[0.78, 0.84], [0.64, 0.58]]), ink, 0.08 * size)
    if v in (1, 2):  # sound arcs above the box
        for r in (0.10, 0.18):
            p.ellipse(m([[0.62, 0.22]])[0], (r * size, 0.8 * r * size), ink, arc_deg=(200, 340),
                      width_m=0.035 * size)


def _exit(p: Painter, x0: float, y0: float, size: float, style: PrintStyle) -> None:
    """A running figure, with a door outline in variants 1 and 2."""
    if style.variant:
        door = _map([[0.05, 0.02], [0.55, 0.02], [0.55, 0.98], [0.05, 0.98]], x0, y0, size, style.mirrored)
        p.line(door, style.ink, 0.05 * size, closed=True)
    running_man(p, x0 + 0.1 * size, y0, 0.9 * size, colour=style.ink, facing_left=not style.mirrored)


_GLYPH = {"extinguisher": _extinguisher, "call_point": _call_point, "exit": _exit}


def panel_front(width_m: float, height_m: float, *, door: RGB, rows: int, window: bool,
                label_seed: int) -> np.ndarray:
    """A distribution board's door: smoked windows onto ``rows`` breaker rows (or a plain
    door with a label) and a small label."""
    p = Painter.new(width_m, height_m, door)
    w, h = width_m, height_m
    if window:
        pitch = 0.7 * h / rows
        for k in range(rows):
            y = 0.12 * h + k * pitch
            p.rect(0.1 * w, y, 0.9 * w, y + 0.75 * pitch, (74, 78, 84))
            n = max(4, int(0.8 * w / 0.018))
            for i in range(n):
                x = 0.11 * w + i * 0.78 * w / n
                colour = (40, 90, 170) if (i + k) % 6 == 0 else (232, 232, 226)
                p.rect(x, y + 0.15 * pitch, x + 0.6 * 0.78 * w / n, y + 0.6 * pitch, colour)
    p.rect(0.35 * w, 0.88 * h, 0.65 * w, 0.94 * h, (250, 250, 246))
    p.text_lines(0.37 * w, 0.895 * h, 0.63 * w, 1, pitch_m=0.02, height_m=0.025 * h,
                 colour=pg.BLACK, seed=label_seed)
    return p.img
