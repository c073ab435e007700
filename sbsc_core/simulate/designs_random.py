"""Procedurally randomized design families (``sbsc simulate --designs random --seed N``).

Each seed draws a new design family for all thirteen classes, as another manufacturer
(or a mix of them) would make them, within each class's realistic envelope:

* **outline and size**: switches 70-90 mm, socket plates 70-95 mm per gang (one series:
  x1 < x2 < x4 share gang size and frame), flush sockets 80-130 mm, call points
  85-135 mm, smoke detectors 90-130 mm, signs 150-300 mm (square, portrait or
  landscape), radiators 0.4-1.2 x 0.3-0.7 m, panels 0.3-0.6 x 0.35-0.75 m, ...
* **relief**: flat, recessed (a cup or a square well), tilted (a rocker, 8-16 mm deep in
  all), domed (a smoke detector's cap), ribbed, tubes, raised buttons;
* **colours and prints**: plate colours of the usual ranges (whites, ivory, greys,
  anthracite, aluminium), reds of fire equipment and signs, green exit panels, prints
  drawn from the grammar of :mod:`pictograms_random`.

Look-alike pairs then arise by chance, as between manufacturers: a switch may share the
socket series' plate; the two signs may share one format. The envelopes keep every family
placeable in the bundled scenes (one_room, Scenarios I and II, the building's floors):
a scene's object spacing assumes at most these sizes.

Deterministic per seed: every choice comes from ``numpy`` generators keyed by the seed
(one per class, plus one for the family's series), nothing global. The family is
callable like the fixed design sets (class id -> mesh) and carries its sizes as
``specs``, which the scene (:func:`~sbsc_core.simulate.building.sized_for`), the truth
and the model library (:mod:`library`) take their footprints from.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from . import pictograms_random as pr
from .catalogue import CATALOGUE, CLASS_ORDER, ObjectSpec
from .mesh import ColouredMesh, cylinder, merge
from .objects import _front_texture as _front
from .objects_alt import _box_span as _span
from .objects_alt import _loft, _outlet_module, _plate, _revolve, _texture_front
from .pictograms import Painter

Colour = tuple[int, int, int]
EPS = 0.0004  # prints float this far in front of their face

# (colour, weight): switch and socket plates, flush sockets
PLATE_COLOURS: tuple[tuple[Colour, float], ...] = (
    ((236, 234, 225), 4.0), ((246, 246, 244), 3.0), ((232, 224, 204), 2.0), ((214, 214, 208), 1.0),
    ((62, 64, 68), 1.0), ((32, 32, 34), 0.5), ((168, 170, 172), 1.0), ((196, 184, 160), 0.5),
)
HOUSING_COLOURS: tuple[tuple[Colour, float], ...] = (  # panels, radiators, detectors, luminaires
    ((244, 244, 240), 4.0), ((236, 234, 225), 2.0), ((203, 208, 204), 2.0), ((62, 64, 68), 1.0),
    ((168, 170, 172), 1.0), ((226, 220, 200), 1.0),
)
WHITES: tuple[tuple[Colour, float], ...] = (((244, 244, 240), 3.0), ((236, 236, 231), 2.0), ((246, 246, 244), 1.0),
                                          ((230, 228, 218), 1.0))
INKS: tuple[tuple[Colour, float], ...] = (((250, 250, 250), 2.0), ((238, 242, 218), 1.0))  # white, photoluminescent
DARK = (30, 30, 32)


@dataclass(frozen=True)
class Design:
    """One class of a family: its size, a word on its relief, and its mesh builder."""

    spec: ObjectSpec
    relief: str  # e.g. "tilted rocker", "recessed cup", "dome"
    build: Callable[[], ColouredMesh]


@dataclass(frozen=True)
class RandomFamily:
    """A design family drawn for ``seed`` (see the module docstring); call it with a class id."""

    seed: int
    designs: dict[str, Design]

    @property
    def specs(self) -> dict[str, ObjectSpec]:
        """The sizes of the family's objects (``CATALOGUE``'s fields, own width, height, depth)."""
        return {c: d.spec for c, d in self.designs.items()}

    def __call__(self, class_id: str) -> ColouredMesh:
        try:
            design = self.designs[class_id]
        except KeyError:
            raise InputError("class", f"unknown class '{class_id}'") from None
        return design.build()

    def describe(self) -> str:
        """One line per class: size in mm and relief."""
        return "\n".join(f"{c}: {1000 * d.spec.width_m:.0f} x {1000 * d.spec.height_m:.0f} x "
                         f"{1000 * d.spec.depth_m:.0f} mm, {d.relief}" for c, d in self.designs.items())


def random_family(seed: int) -> RandomFamily:
    """The design family of ``seed`` (a whole number >= 0); the same seed gives the same family."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**63:
        raise InputError("--design-seed", f"expected a whole number from 0 to 2**63-1, got {seed!r}")
    seed = int(seed)
    series = _Series.draw(np.random.default_rng([seed, 0x5E1E5]))
    designs = {}
    for k, cls in enumerate(CLASS_ORDER):
        rng = np.random.default_rng([seed, 0xC1A55, k])
        designs[cls] = _DRAW[cls](rng, series)
    return RandomFamily(seed, designs)


def sibling_family(family: RandomFamily, seed: int) -> RandomFamily:
    """Another manufacturer's products at ``family``'s sizes: the designs of ``seed``, each
    scaled to the width, height and depth of ``family``'s object of its class.

    What ``alt`` is to ``standard`` (the same catalogue sizes, other reliefs, colours and
    prints), drawn per seed: a scene of ``family`` with the library of its sibling has
    objects whose design differs from their model, as a real building's do, while the
    library still gives each class's size right. Prints stretch with their faces.
    """
    other = random_family(seed)
    if other.seed == family.seed:
        raise InputError("--library-design-seed", f"a sibling family needs another seed than the family's ({seed})")
    designs = {}
    for cls, target in family.designs.items():
        source = other.designs[cls]
        spec = target.spec
        scale = (spec.width_m / source.spec.width_m, spec.height_m / source.spec.height_m,
                 spec.depth_m / source.spec.depth_m)
        designs[cls] = Design(spec, f"{source.relief} (sibling {seed})", _scaled(source.build, scale))
    return RandomFamily(other.seed, designs)


def _scaled(build: Callable[[], ColouredMesh], scale: tuple[float, float, float]) -> Callable[[], ColouredMesh]:
    """``build`` with its mesh's vertices scaled by ``scale`` (x, y, z) about the object's origin."""
    def scaled() -> ColouredMesh:
        return build().transformed(np.diag(scale), np.zeros(3))
    return scaled


# --------------------------------------------------------------------------- drawing helpers


def _pick(rng: np.random.Generator, options: Sequence[tuple[Colour, float]], jitter: int = 4) -> Colour:
    """A weighted choice of colour, shifted by up to ``jitter`` levels per channel."""
    w = np.array([o[1] for o in options], float)
    base = np.array(options[int(rng.choice(len(options), p=w / w.sum()))][0])
    return tuple(int(c) for c in np.clip(base + rng.integers(-jitter, jitter + 1, 3), 0, 255))  # type: ignore[return-value]


def _red(rng: np.random.Generator) -> Colour:
    """A red of fire equipment and fire signs (RAL 3000 to signal red)."""
    return (int(rng.integers(160, 216)), int(rng.integers(18, 46)), int(rng.integers(22, 50)))


def _green(rng: np.random.Generator) -> Colour:
    """A safety green of exit signs."""
    return (int(rng.integers(0, 30)), int(rng.integers(118, 156)), int(rng.integers(60, 96)))


def _spec(class_id: str, w: float, h: float, d: float) -> ObjectSpec:
    return dataclasses.replace(CATALOGUE[class_id], width_m=round(float(w), 4), height_m=round(float(h), 4),
                               depth_m=round(float(d), 4))


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    """Uniform in lo..hi, to 0.1 mm (sizes are given to 0.1 mm, so meshes and specs agree)."""
    return round(float(rng.uniform(lo, hi)), 4)


@dataclass(frozen=True)
class _Series:
    """What one manufacturer's series shares: the sockets' gang and the switch plate, the
    plate colour, corner radius; and the signs' format when they come as a pair."""

    gang_m: float  # side of one socket gang's module
    frame_m: float  # frame border round the gangs
    plate: Colour
    corner_m: float
    switch_plate_m: float  # the switch's plate side (the socket's in about half the families)
    sign_format: tuple[float, float] | None  # (w, h) both signs share, or None: each its own

    @staticmethod
    def draw(rng: np.random.Generator) -> _Series:
        plate_m = _u(rng, 0.070, 0.095)  # the one-gang socket's plate
        frame = _u(rng, 0.002, 0.009)
        switch = plate_m if rng.random() < 0.5 and plate_m <= 0.09 else _u(rng, 0.070, 0.090)
        return _Series(plate_m - 2 * frame, frame, _pick(rng, PLATE_COLOURS), _u(rng, 0.0005, 0.012), switch,
                       _sign_format(rng) if rng.random() < 0.5 else None)


def _sign_format(rng: np.random.Generator) -> tuple[float, float]:
    """A sign's (w, h): square, portrait or landscape, sides 150-300 mm."""
    shape = int(rng.integers(3))
    if shape == 0:
        s = _u(rng, 0.15, 0.30)
        return s, s
    a, b = _u(rng, 0.15, 0.22), 0.0
    b = _u(rng, max(1.2 * a, 0.18), 0.30)
    return (a, b) if shape == 1 else (b, a)


def _tilted(x0: float, x1: float, y0: float, y1: float, *, z0: float, z_bottom: float, z_top: float,
            colour: Colour) -> ColouredMesh:
    """A block on z0 whose front is tilted from z_bottom (at y0) to z_top (at y1): a rocker."""
    back = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]])
    front = np.array([[x0, y0, z_bottom], [x1, y0, z_bottom], [x1, y1, z_top], [x0, y1, z_top]])
    return _loft([back, front], colour, cap_start=True, cap_end=True)


def _ring(x0: float, x1: float, y0: float, y1: float, *, hole: float, z0: float, z1: float,
          colour: Colour) -> list[ColouredMesh]:
    """A rectangle z0..z1 with a centred square hole of side ``hole``: four blocks."""
    cx, cy, a = (x0 + x1) / 2, (y0 + y1) / 2, hole / 2
    return [_span(x0, x1, cy + a, y1, z0=z0, z1=z1, colour=colour),
            _span(x0, x1, y0, cy - a, z0=z0, z1=z1, colour=colour),
            _span(x0, cx - a, cy - a, cy + a, z0=z0, z1=z1, colour=colour),
            _span(cx + a, x1, cy - a, cy + a, z0=z0, z1=z1, colour=colour)]


def _face(w: float, h: float, colour: Colour, dots: Sequence[tuple[float, float, float]],
          ink: Colour = DARK) -> np.ndarray:
    """A plain face with round marks (x, y, r as fractions of the side) such as pin holes."""
    p = Painter.new(w, h, colour)
    for x, y, r in dots:
        p.circle((x * w, y * h), r * min(w, h), ink)
    return p.img


# --------------------------------------------------------------------------- sockets and switch


def _draw_socket(n: int) -> Callable[[np.random.Generator, _Series], Design]:
    def draw(rng: np.random.Generator, s: _Series) -> Design:
        cls = f"socket_x{n}"
        w, h = n * s.gang_m + 2 * s.frame_m, s.gang_m + 2 * s.frame_m
        d = _u(rng, 0.008, 0.016)
        kind = ("recessed cup", "square well", "flat face")[int(rng.choice(3, p=[0.5, 0.25, 0.25]))]
        frame_z = d * _u(rng, 0.2, 0.5)
        insert = _pick(rng, ((s.plate, 3.0), ((110, 110, 108), 1.0), ((222, 220, 212), 1.0)), jitter=2)
        cup_r = _u(rng, 0.015, 0.021)
        floor_z = frame_z + _u(rng, 0.0005, d - frame_z - 0.003)  # the recess floor stands on the frame
        spec = _spec(cls, w, h, d)

        def build() -> ColouredMesh:
            parts = [_plate(w / 2, h / 2, s.corner_m, 0.0, frame_z, bevel=min(0.0015, frame_z / 2),
                            colour=s.plate)]
            half = s.gang_m / 2 - 0.001
            for i in range(n):
                x = -w / 2 + s.frame_m + (i + 0.5) * s.gang_m
                if kind == "recessed cup":
                    parts.append(_outlet_module((x, 0.0), half, frame_z, d, s.plate,
                                                cup_r=min(cup_r, half - 0.004), cup_floor_z=floor_z,
                                                corner_r=min(s.corner_m, half / 3), bevel=0.001))
                elif kind == "square well":
                    a = 2 * min(cup_r, half - 0.004)
                    parts += _ring(x - half, x + half, -half, half, hole=a, z0=frame_z, z1=d, colour=s.plate)
                    parts.append(_span(x - a / 2, x + a / 2, -a / 2, a / 2, z0=frame_z, z1=floor_z,
                                       colour=insert))
                    parts.append(_front(a, a, floor_z + EPS, _face(a, a, insert, ((0.33, 0.5, 0.07), (0.67, 0.5, 0.07))),
                                        (x, 0.0)))
                else:
                    parts.append(_span(x - half, x + half, -half, half, z0=frame_z, z1=d, colour=insert))
                    parts.append(_front(2 * half, 2 * half, d + EPS,
                                        _face(2 * half, 2 * half, insert,
                                              ((0.38, 0.45, 0.05), (0.62, 0.45, 0.05), (0.5, 0.7, 0.06))), (x, 0.0)))
            return merge(parts)
        return Design(spec, kind, build)
    return draw


def _draw_switch(rng: np.random.Generator, s: _Series) -> Design:
    side = s.switch_plate_m
    d = _u(rng, 0.008, 0.016)
    kind = ("tilted rocker", "two tilted rockers", "flat push button")[int(rng.choice(3, p=[0.5, 0.25, 0.25]))]
    plate_z = _u(rng, 0.003, min(0.007, d - 0.004))
    key = _pick(rng, ((s.plate, 3.0), ((246, 246, 244), 1.0), ((62, 64, 68), 0.5)), jitter=3)
    a = side * _u(rng, 0.55, 0.82)  # the key's side
    low = plate_z + _u(rng, 0.25, 0.7) * (d - plate_z)  # the tilted front's low edge
    top_out = bool(rng.random() < 0.5)
    led = bool(rng.random() < 0.4)

    def build() -> ColouredMesh:
        parts = [_plate(side / 2, side / 2, s.corner_m, 0.0, plate_z,
                        bevel=min(0.0015, plate_z / 2), colour=s.plate)]
        if kind == "tilted rocker":
            lo, hi = (low, d) if top_out else (d, low)
            parts.append(_tilted(-a / 2, a / 2, -a / 2, a / 2, z0=plate_z, z_bottom=lo, z_top=hi, colour=key))
        elif kind == "two tilted rockers":
            for k, x0 in enumerate((-a / 2, 0.0005)):
                lo, hi = (low, d) if (k == 0) == top_out else (d, low)
                parts.append(_tilted(x0, x0 + a / 2 - 0.0005, -a / 2, a / 2, z0=plate_z,
                                     z_bottom=lo, z_top=hi, colour=key))
        else:
            parts.append(_span(-a / 2, a / 2, -a / 2, a / 2, z0=plate_z, z1=d, colour=key))
            dots = ((0.5, 0.15, 0.04),) if led else ()
            parts.append(_front(a, a, d + EPS, _face(a, a, key, dots, (235, 125, 35)), (0.0, 0.0)))
        return merge(parts)
    return Design(_spec("switch", side, side, d), kind, build)


def _draw_builtin_socket(rng: np.random.Generator, s: _Series) -> Design:
    side = _u(rng, 0.08, 0.13)
    d = _u(rng, 0.0015, 0.006)
    colour = _pick(rng, ((s.plate, 2.0), ((168, 170, 172), 2.0), ((196, 196, 190), 2.0), ((62, 64, 68), 0.5)))
    kind = "flat lid" if rng.random() < 0.6 else "flat with a printed outlet"
    lid = side * _u(rng, 0.6, 0.85)
    lid_colour = _pick(rng, ((colour, 2.0), ((236, 234, 225), 1.0)), jitter=3)

    def build() -> ColouredMesh:
        parts = [_plate(side / 2, side / 2, s.corner_m, 0.0, d / 2, bevel=d / 4, colour=colour),
                 _span(-lid / 2, lid / 2, -lid / 2, lid / 2, z0=d / 2, z1=d, colour=lid_colour)]
        if kind == "flat lid":
            img = _face(lid, lid, lid_colour, ((0.5, 0.1, 0.04),), (90, 90, 92))  # finger notch
        else:
            img = _face(lid, lid, lid_colour, ((0.5, 0.5, 0.32), (0.38, 0.5, 0.05), (0.62, 0.5, 0.05)),
                        (150, 150, 147))
        parts.append(_front(lid, lid, d + EPS, img))
        return merge(parts)
    return Design(_spec("builtin_socket", side, side, d), kind, build)


# --------------------------------------------------------------------------- larger equipment


def _draw_panel(rng: np.random.Generator, s: _Series) -> Design:
    w, h, d = _u(rng, 0.30, 0.60), _u(rng, 0.35, 0.75), _u(rng, 0.08, 0.16)
    body = _pick(rng, HOUSING_COLOURS)
    door = _pick(rng, ((body, 3.0), ((232, 232, 226), 1.0)), jitter=3)
    rows = int(rng.integers(1, 5))
    window = bool(rng.random() < 0.65)
    handle_left = bool(rng.random() < 0.5)
    inset = _u(rng, 0.003, 0.015)
    seed = int(rng.integers(1 << 30))

    def build() -> ColouredMesh:
        dw, dh = w - 2 * inset, h - 2 * inset
        hx = (-1 if handle_left else 1) * (dw / 2 - 0.02)
        return merge([_plate(w / 2, h / 2, 0.006, 0.0, d - 0.006, bevel=0.003, colour=body),
                      _span(-dw / 2, dw / 2, -dh / 2, dh / 2, z0=d - 0.006, z1=d - 0.003, colour=door),
                      _front(dw, dh, d - 0.003 + EPS,
                             pr.panel_front(dw, dh, door=door, rows=rows, window=window, label_seed=seed)),
                      _span(hx - 0.007, hx + 0.007, -0.04, 0.04, z0=d - 0.003, z1=d, colour=(60, 60, 62))])
    return Design(_spec("electrical_panel", w, h, d), "door with windows" if window else "plain door", build)


def _draw_extinguisher(rng: np.random.Generator, s: _Series) -> Design:
    w, h, d = _u(rng, 0.15, 0.26), _u(rng, 0.42, 0.68), _u(rng, 0.12, 0.20)
    r = min(_u(rng, 0.05, 0.085), d / 2 - 0.005, (w - 0.03) / 2)
    red = _red(rng)
    hose_right = bool(rng.random() < 0.5)
    horn = bool(rng.random() < 0.3)
    body_frac = _u(rng, 0.62, 0.78)
    colour, frac = _pick(rng, (((238, 232, 212), 2.0), ((246, 246, 240), 1.0))), _u(rng, 0.25, 0.45)  # label
    seed = int(rng.integers(1 << 30))

    def build() -> ColouredMesh:
        side = 1 if hose_right else -1
        xb = -side * (w / 2 - r)  # the body on one side, the hose on the other
        zc = d - r
        y0 = -h / 2
        body_h = body_frac * h
        top = y0 + body_h
        xh = side * (w / 2 - 0.012)
        band = cylinder(r, frac * body_h, colour, segments=32, centre=(xb, y0 + 0.45 * body_h, zc),
                        axis=1, capped=False)
        p = Painter.new(1.6 * r, frac * body_h, colour)
        p.rect(0, 0, 1.6 * r, 0.15 * frac * body_h, red)
        p.text_lines(0.15 * r, 0.3 * frac * body_h, 1.45 * r, 4, pitch_m=0.03 * body_h,
                     height_m=0.012 * body_h, colour=DARK, seed=seed)
        band = _texture_front(band, p.img, x0=xb - 0.8 * r, x1=xb + 0.8 * r,
                              y0=y0 + 0.45 * body_h - frac * body_h / 2,
                              y1=y0 + 0.45 * body_h + frac * body_h / 2, min_nz=0.6)
        lo, hi = y0 + 0.45 * body_h - frac * body_h / 2, y0 + 0.45 * body_h + frac * body_h / 2
        parts = [cylinder(r, lo - y0, red, segments=32, centre=(xb, (y0 + lo) / 2, zc), axis=1),
                 band,
                 cylinder(r, top - hi, red, segments=32, centre=(xb, (hi + top) / 2, zc), axis=1),
                 cylinder(0.6 * r, 0.03, red, segments=24, centre=(xb, top + 0.015, zc), axis=1),
                 _span(xb - 0.03, xb + 0.03, top + 0.03, top + 0.07, z0=zc - 0.02, z1=zc + 0.02,
                       colour=(60, 60, 62)),
                 _span(min(xb, xh), max(xb, xh), h / 2 - 0.015, h / 2, z0=zc - 0.01, z1=zc + 0.01,
                       colour=DARK),  # lever
                 _span(xb - 0.03, xb + 0.03, y0 + 0.5 * body_h, y0 + 0.8 * body_h, z0=0.0,
                       z1=zc - r + 0.002, colour=(70, 70, 72))]
        if horn:
            parts.append(_span(xh - 0.012, xh + 0.012, y0 + 0.1 * h, y0 + 0.55 * h, z0=zc - 0.02,
                               z1=zc + 0.02, colour=DARK))
        else:
            parts.append(cylinder(0.008, 0.6 * h, DARK, segments=12,
                                  centre=(xh + side * 0.004, y0 + 0.45 * h, zc), axis=1))
        return merge(parts)
    return Design(_spec("fire_extinguisher", w, h, d), "cylinder with " + ("horn" if horn else "hose"), build)


def _draw_radiator(rng: np.random.Generator, s: _Series) -> Design:
    w, h, d = _u(rng, 0.40, 1.20), _u(rng, 0.30, 0.70), _u(rng, 0.06, 0.12)
    colour = _pick(rng, HOUSING_COLOURS)
    kind = ("ribbed panel", "columns", "horizontal tubes", "flat panel")[int(rng.integers(4))]
    pitch = _u(rng, 0.025, 0.06)
    fill = _u(rng, 0.5, 0.8)

    def build() -> ColouredMesh:
        back = 0.015
        parts = [_span(x - 0.02, x + 0.02, 0.1 * h, 0.1 * h + 0.08, z0=0.0, z1=back, colour=(120, 120, 118))
                 for x in (-0.3 * w, 0.3 * w)]
        if kind == "ribbed panel":
            parts.append(_span(-w / 2, w / 2, -h / 2, h / 2, z0=back, z1=back + 0.3 * (d - back),
                               colour=colour))
            n = max(4, round(w / pitch))
            for i in range(n):
                x = -w / 2 + (i + 0.5) * w / n
                parts.append(_span(x - fill * w / n / 2, x + fill * w / n / 2, -h / 2 + 0.02, h / 2 - 0.02,
                                   z0=back + 0.3 * (d - back), z1=d, colour=colour))
        elif kind == "columns":
            n = max(3, round(w / (2 * pitch)))
            for i in range(n):
                x = -w / 2 + (i + 0.5) * w / n
                parts.append(_span(x - fill * w / n / 2, x + fill * w / n / 2, -h / 2, h / 2,
                                   z0=back, z1=d, colour=colour))
            for y in (-h / 2 + 0.04, h / 2 - 0.04):
                parts.append(cylinder(0.015, w, colour, segments=16, centre=(0.0, y, back + 0.02), axis=0))
        elif kind == "horizontal tubes":
            for x in (-w / 2 + 0.02, w / 2 - 0.02):
                parts.append(_span(x - 0.02, x + 0.02, -h / 2, h / 2, z0=back, z1=d - 0.005, colour=colour))
            n = max(3, round(h / pitch))
            for k in range(n):
                y = -h / 2 + (k + 0.5) * h / n
                parts.append(_span(-w / 2 + 0.04, w / 2 - 0.04, y - fill * h / n / 2, y + fill * h / n / 2,
                                   z0=back + 0.01, z1=d, colour=colour))
        else:
            parts.append(_plate(w / 2, h / 2, 0.01, back, d, bevel=0.004, colour=colour))
        return merge(parts)
    return Design(_spec("radiator", w, h, d), kind, build)


def _draw_call_point(rng: np.random.Generator, s: _Series) -> Design:
    w = _u(rng, 0.085, 0.135)
    h = round(min(0.14, w * _u(rng, 0.95, 1.15)), 4)
    d = _u(rng, 0.025, 0.06)
    red = _red(rng)
    kind = ("flat glass window", "raised push button", "recessed window")[int(rng.integers(3))]
    win = min(w, h) * _u(rng, 0.5, 0.72)
    style = pr.draw_print_style(rng, (244, 244, 240), _pick(rng, ((DARK, 1.0), (red, 1.0))))
    button_r = min(_u(rng, 0.018, 0.03), win / 2)
    button_h = _u(rng, 0.006, 0.015)
    recess = _u(rng, 0.004, 0.01)

    def build() -> ColouredMesh:
        if kind == "raised push button":
            z = d - button_h
            return merge([_plate(w / 2, h / 2, 0.004, 0.0, z, bevel=0.003, colour=red),
                          cylinder(button_r, button_h, (236, 236, 230), segments=28,
                                   centre=(0.0, 0.0, z + button_h / 2), axis=2),
                          _front(win, win, z + EPS, pr.draw_print("call_point", win, win, style))])
        if kind == "recessed window":
            floor = d - recess
            return merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=floor, colour=red),
                          *_ring(-w / 2, w / 2, -h / 2, h / 2, hole=win, z0=floor, z1=d, colour=red),
                          _front(win, win, floor + EPS, pr.draw_print("call_point", win, win, style))])
        return merge([_plate(w / 2, h / 2, 0.004, 0.0, d, bevel=0.003, colour=red),
                      _front(win, win, d + EPS, pr.draw_print("call_point", win, win, style))])
    return Design(_spec("fire_alarm_switch", w, h, d), kind, build)


def _draw_smoke_detector(rng: np.random.Generator, s: _Series) -> Design:
    side, d = _u(rng, 0.09, 0.13), _u(rng, 0.035, 0.065)
    colour = _pick(rng, WHITES, jitter=2)
    kind = ("dome", "stacked discs", "square")[int(rng.choice(3, p=[0.45, 0.35, 0.2]))]
    base_frac = _u(rng, 0.3, 0.6)
    vents = int(rng.integers(4, 9))
    led = (int(rng.integers(150, 240)), int(rng.integers(30, 210)), 40)

    def face(size: float) -> np.ndarray:
        """Radial vent slots round the centre and the LED."""
        p = Painter.new(size, size, colour)
        c = size / 2
        for k in range(vents):
            a = 2 * np.pi * k / vents
            p.line(np.array([[c + 0.45 * c * np.cos(a), c + 0.45 * c * np.sin(a)],
                             [c + 0.7 * c * np.cos(a), c + 0.7 * c * np.sin(a)]]), (150, 150, 148), 0.003)
        p.circle((1.25 * c, 0.75 * c), 0.002, led)
        return p.img

    def build() -> ColouredMesh:
        r = side / 2
        zb = base_frac * d
        if kind == "dome":
            t = np.linspace(0.0, np.pi / 2, 9)
            profile = [(r, 0.0), (r, 0.9 * zb)] + [(r * 0.92 * np.cos(a) + 1e-4, zb + (d - zb) * np.sin(a)) for a in t]
            shell = _revolve(profile, 2, (0, 0, 0), colour, segments=48, cap_start=True, cap_end=True)
        elif kind == "stacked discs":
            shell = merge([cylinder(r, zb, colour, segments=48, centre=(0, 0, zb / 2), axis=2),
                           cylinder(0.8 * r, d - zb, colour, segments=48,
                                    centre=(0, 0, (zb + d) / 2), axis=2)])
        else:
            m = 0.1 * side
            return merge([_span(-r, r, -r, r, z0=0.0, z1=zb, colour=colour),
                          _span(-r + m, r - m, -r + m, r - m, z0=zb, z1=d, colour=colour),
                          _front(side - 2 * m, side - 2 * m, d + EPS, face(side - 2 * m))])
        return _texture_front(shell, face(side), x0=-r, x1=r, y0=-r, y1=r, min_nz=0.3)
    return Design(_spec("smoke_detector", side, side, d), kind, build)


def _draw_exit_light(rng: np.random.Generator, s: _Series) -> Design:
    w, h, d = _u(rng, 0.25, 0.45), _u(rng, 0.10, 0.17), _u(rng, 0.03, 0.07)
    housing = _pick(rng, HOUSING_COLOURS)
    green = _green(rng)
    white = _pick(rng, INKS, jitter=2)
    style = pr.draw_print_style(rng, *((green, white) if rng.random() < 0.75 else (white, green)))
    style = dataclasses.replace(style, layout="glyph_side", flames=False)
    kind = ("box", "rounded box", "blade")[int(rng.integers(3))]
    margin = _u(rng, 0.005, 0.015)

    def build() -> ColouredMesh:
        pw, ph = w - 2 * margin, h - 2 * margin
        face = pr.draw_print("exit", pw, ph, style)
        if kind == "blade":
            base_h = min(0.03, 0.3 * h)
            ph2 = h - base_h - 0.004
            return merge([_span(-w / 2, w / 2, h / 2 - base_h, h / 2, z0=0.0, z1=d, colour=housing),
                          _span(-pw / 2, pw / 2, -h / 2, h / 2 - base_h, z0=d / 2 - 0.004,
                                z1=d / 2 + 0.004, colour=white),
                          _front(pw, ph2, d / 2 + 0.004 + EPS, pr.draw_print("exit", pw, ph2, style),
                                 (0.0, -h / 2 + ph2 / 2))])
        if kind == "rounded box":
            return merge([_plate(w / 2, h / 2, 0.01, 0.0, d, bevel=0.006, colour=housing),
                          _front(pw, ph, d + EPS, face)])
        return merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d, colour=housing),
                      _front(pw, ph, d + EPS, face)])
    return Design(_spec("exit_light", w, h, d), kind, build)


def _draw_sign(class_id: str, glyph: str) -> Callable[[np.random.Generator, _Series], Design]:
    def draw(rng: np.random.Generator, s: _Series) -> Design:
        w, h = _sign_format(rng)
        if s.sign_format is not None:
            w, h = s.sign_format
        d = _u(rng, 0.0015, 0.004)
        style = pr.draw_print_style(rng, _red(rng), _pick(rng, INKS, jitter=2))

        def build() -> ColouredMesh:
            return merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0.0, z1=d, colour=style.background),
                          _front(w, h, d + EPS, pr.draw_print(glyph, w, h, style))])
        shape = "square" if abs(w - h) < 1e-9 else ("portrait" if h > w else "landscape")
        return Design(_spec(class_id, w, h, d), f"flat {shape} plate, {style.layout} print", build)
    return draw


_DRAW: dict[str, Callable[[np.random.Generator, _Series], Design]] = {
    "electrical_panel": _draw_panel,
    "socket_x1": _draw_socket(1),
    "socket_x2": _draw_socket(2),
    "socket_x4": _draw_socket(4),
    "builtin_socket": _draw_builtin_socket,
    "switch": _draw_switch,
    "fire_extinguisher": _draw_extinguisher,
    "radiator": _draw_radiator,
    "fire_alarm_switch": _draw_call_point,
    "smoke_detector": _draw_smoke_detector,
    "exit_light": _draw_exit_light,
    "extinguisher_sign": _draw_sign("extinguisher_sign", "extinguisher"),
    "fire_alarm_switch_sign": _draw_sign("fire_alarm_switch_sign", "call_point"),
}
