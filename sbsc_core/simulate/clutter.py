"""Things on and in front of walls that are none of the thirteen classes (distractors).

Wall clutter (``clutter``): framed pictures and posters, notice boards and whiteboards,
clocks, thermostats and room controllers (both look much like a light switch), cable
trunking, coat hooks and door stops. Furniture (``furniture``): desks, low and tall
cabinets, shelves, chairs and bins standing against the walls, which hide parts of the
walls and of the objects behind them.

Both are laid out at random for a seed (:func:`place_clutter`, :func:`place_furniture`)
around the scene's objects and openings, built as coloured meshes (label -2, like the
building, never an object index) and recorded in the ground truth's top-level
``distractors`` list (contract 5): kind, wall, ``u``, ``v``, size and the world box
(``centre``, ``axis_u``, ``axis_v``, ``normal``, ``size_m`` along them), so that the
evaluator can tell a false positive that falls on one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import mesh as M
from . import pictograms as pic
from .mesh import ColouredMesh
from .scene import Layout, SceneDescription, footprint, point_in_outline

DISTRACTOR_LABEL = -2  # triangle label of distractors (objects are >= 0, the building -1)

# kind: (probability weight, width range, height range, depth, centre height range)
WALL_KINDS: dict[str, tuple[float, tuple[float, float], tuple[float, float], float, tuple[float, float]]] = {
    "picture": (3.0, (0.30, 0.70), (0.30, 0.60), 0.025, (1.45, 1.70)),
    "poster": (2.0, (0.42, 0.60), (0.59, 0.84), 0.001, (1.40, 1.60)),
    "notice_board": (1.0, (0.90, 1.20), (0.60, 0.90), 0.020, (1.35, 1.50)),
    "whiteboard": (1.0, (1.20, 1.80), (0.90, 1.20), 0.020, (1.35, 1.50)),
    "clock": (1.0, (0.25, 0.35), (0.0, 0.0), 0.040, (2.00, 2.20)),
    "thermostat": (2.0, (0.08, 0.09), (0.08, 0.12), 0.025, (1.40, 1.55)),
    "room_controller": (2.0, (0.086, 0.086), (0.086, 0.086), 0.015, (1.05, 1.20)),
    "trunking": (1.5, (1.00, 3.00), (0.06, 0.06), 0.025, (0.10, 0.14)),
    "coat_hooks": (1.0, (0.40, 0.80), (0.08, 0.08), 0.060, (1.65, 1.75)),
    "door_stop": (1.0, (0.04, 0.04), (0.04, 0.04), 0.060, (0.08, 0.12)),
}
# kind: (weight, width range, height range, depth range)
FURNITURE_KINDS: dict[str, tuple[float, tuple[float, float], tuple[float, float], tuple[float, float]]] = {
    "desk": (3.0, (1.20, 1.60), (0.72, 0.76), (0.60, 0.80)),
    "cabinet": (2.0, (0.80, 1.20), (0.75, 1.10), (0.40, 0.50)),
    "tall_cabinet": (1.0, (0.80, 1.00), (1.80, 2.00), (0.40, 0.50)),
    "shelf": (1.0, (0.80, 1.00), (1.60, 1.90), (0.28, 0.35)),
    "chair": (2.0, (0.45, 0.50), (0.85, 0.95), (0.45, 0.55)),
    "bin": (2.0, (0.28, 0.32), (0.35, 0.45), (0.28, 0.32)),
}
GLOSS = {"picture": 0.8, "whiteboard": 0.8, "clock": 0.6, "poster": 0.2, "thermostat": 0.2,
         "room_controller": 0.25, "trunking": 0.15, "tall_cabinet": 0.2, "cabinet": 0.2}
MARGIN_M = 0.05  # free space kept round objects, openings and other distractors


@dataclass
class Distractor:
    """One piece of clutter or furniture, as a box in the wall frame (u, v centre; d out of the wall)."""

    kind: str
    wall: str
    u: float
    v: float
    width_m: float
    height_m: float
    depth_m: float
    gap_m: float = 0.0  # distance of its back from the wall (furniture clears protruding objects)
    variant: int = 0  # seed of its look (colours, print)

    @property
    def furniture(self) -> bool:
        return self.kind in FURNITURE_KINDS

    def box(self) -> tuple[float, float, float, float]:
        return (self.u - self.width_m / 2, self.u + self.width_m / 2,
                self.v - self.height_m / 2, self.v + self.height_m / 2)

    def to_truth(self, layout: Layout) -> dict:
        fr = layout.walls[self.wall].frame
        centre = fr.to_world(self.u, self.v, self.gap_m + self.depth_m / 2)
        r = lambda x: [round(float(c), 5) for c in x]  # noqa: E731
        return {"kind": self.kind, "furniture": self.furniture, "wall": self.wall,
                "u": round(self.u, 4), "v": round(self.v, 4), "width_m": round(self.width_m, 4),
                "height_m": round(self.height_m, 4), "depth_m": round(self.depth_m, 4),
                "position": r(fr.to_world(self.u, self.v)), "normal": r(fr.normal),
                "centre": r(centre), "axis_u": r(fr.axis_u), "axis_v": r(fr.axis_v),
                "size_m": [round(self.width_m, 4), round(self.height_m, 4), round(self.depth_m, 4)]}


# --------------------------------------------------------------------------- layout


def _overlap(a, b, margin: float = 0.0) -> bool:
    return (min(a[1], b[1]) - max(a[0], b[0]) > -margin) and (min(a[3], b[3]) - max(a[2], b[2]) > -margin)


def _blocked(scene: SceneDescription, layout: Layout, wall: str, box, placed: list[Distractor],
             *, fw: float, margin: float = MARGIN_M, objects: bool = True) -> bool:
    w = layout.walls[wall].frame
    if box[0] < 0.02 or box[1] > w.width_m - 0.02 or box[2] < 0.0 or box[3] > w.height_m - 0.05:
        return True
    for o in layout.openings_on(wall):
        if _overlap(box, (o.u_min - fw, o.u_max + fw, o.v_min - fw, o.v_max + fw), margin):
            return True
    if objects and any(p.wall == wall and _overlap(box, footprint(p, scene.specs), margin) for p in scene.objects):
        return True
    return any(d.wall == wall and _overlap(box, d.box(), margin) for d in placed)


def _key(seed: int | tuple[int, ...]) -> list[int]:
    """A seed, or a tuple of them (a building's ``(seed, storey)``), as a generator key."""
    return [int(s) for s in seed] if isinstance(seed, tuple) else [int(seed)]


def place_clutter(scene: SceneDescription, layout: Layout, seed: int | tuple[int, ...], per_metre: float = 0.4,
                  existing: list[Distractor] | None = None) -> list[Distractor]:
    """Wall clutter for a scene: about ``per_metre`` items per metre of wall, clear of the
    objects, the openings and each other (deterministic for a seed; a tuple such as
    ``(seed, storey)`` gives each storey of a building its own layout)."""
    rng = np.random.default_rng([*_key(seed), 0xC107])
    kinds = list(WALL_KINDS)
    weights = np.array([WALL_KINDS[k][0] for k in kinds])
    placed = list(existing or [])
    out: list[Distractor] = []
    fw = scene.door_frame_width_m
    for wid, wall in layout.walls.items():
        n = rng.poisson(per_metre * wall.frame.width_m)
        for _ in range(n):
            kind = kinds[rng.choice(len(kinds), p=weights / weights.sum())]
            _, wr, hr, depth, vr = WALL_KINDS[kind]
            w = float(rng.uniform(*wr))
            h = w if kind == "clock" else float(rng.uniform(*hr))
            for _try in range(25):
                u = float(rng.uniform(w / 2 + 0.02, max(w / 2 + 0.03, wall.frame.width_m - w / 2 - 0.02)))
                v = float(rng.uniform(*vr))
                d = Distractor(kind, wid, u, v, w, h, depth, 0.0, int(rng.integers(1 << 30)))
                if not _blocked(scene, layout, wid, d.box(), placed, fw=fw):
                    placed.append(d)
                    out.append(d)
                    break
    return out


def place_furniture(scene: SceneDescription, layout: Layout, stations: np.ndarray, seed: int | tuple[int, ...],
                    *, per_metre: float = 0.15, existing: list[Distractor] | None = None) -> list[Distractor]:
    """Furniture against the walls: about ``per_metre`` pieces per metre of wall.

    A piece stands in front of any object or wall clutter (its back clears what stands
    out of the wall there by 1 cm) but never in a door, in front of a window unless it is
    lower than the sill, inside another piece or within 0.6 m of a scanner station. Tall
    pieces (cabinets, shelves) stand only where no object is behind them, so an object is
    at most partly hidden.
    """
    rng = np.random.default_rng([*_key(seed), 0xF0F0])
    kinds = list(FURNITURE_KINDS)
    weights = np.array([FURNITURE_KINDS[k][0] for k in kinds])
    placed: list[Distractor] = []
    others = list(existing or [])
    plan_boxes: list[np.ndarray] = []
    rooms = {r.id: r for r in scene.rooms}
    for wid, wall in layout.walls.items():
        fr = wall.frame
        for _ in range(rng.poisson(per_metre * fr.width_m)):
            kind = kinds[rng.choice(len(kinds), p=weights / weights.sum())]
            _, wr, hr, dr = FURNITURE_KINDS[kind]
            w, h, depth = (float(rng.uniform(*x)) for x in (wr, hr, dr))
            for _try in range(25):
                u = float(rng.uniform(w / 2 + 0.03, max(w / 2 + 0.04, fr.width_m - w / 2 - 0.03)))
                box = (u - w / 2, u + w / 2, 0.0, h)
                if _furniture_blocked(layout, wid, box, h, scene=scene, kind=kind):
                    continue
                behind = [scene.specs[p.class_id].depth_m for p in scene.objects
                          if p.wall == wid and _overlap(box, footprint(p, scene.specs))]
                behind += [d.depth_m for d in others if d.wall == wid and _overlap(box, d.box())]
                gap = max(behind, default=0.0) + 0.01
                corners = np.array([fr.to_world(uu, 0.0, dd) for uu in box[:2] for dd in (gap, gap + depth)])
                if not point_in_outline(corners[:, :2], rooms[wall.room].outline).all():
                    continue
                lo, hi = corners.min(axis=0)[:2], corners.max(axis=0)[:2]
                if any(np.all(np.minimum(hi, b[1]) - np.maximum(lo, b[0]) > -0.05) for b in plan_boxes):
                    continue
                if len(stations) and np.any(np.all((stations[:, :2] > lo - 0.6) & (stations[:, :2] < hi + 0.6),
                                                   axis=1)):
                    continue
                d = Distractor(kind, wid, u, h / 2, w, h, depth, gap, int(rng.integers(1 << 30)))
                placed.append(d)
                plan_boxes.append(np.array([lo, hi]))
                break
    return placed


def _furniture_blocked(layout: Layout, wall: str, box, h: float, *, scene: SceneDescription,
                       kind: str) -> bool:
    fr = layout.walls[wall].frame
    if box[0] < 0.02 or box[1] > fr.width_m - 0.02:
        return True
    fw = scene.door_frame_width_m
    for o in layout.openings_on(wall):
        if o.kind == "door" or h > o.v_min - 0.02:
            if _overlap(box, (o.u_min - fw - 0.1, o.u_max + fw + 0.1, 0.0, o.v_max), 0.0):
                return True
    if h > 1.2:  # tall: nothing of the classes behind it
        if any(p.wall == wall and _overlap((box[0], box[1], 0.0, 99.0), footprint(p, scene.specs), MARGIN_M)
               for p in scene.objects):
            return True
    return False


# --------------------------------------------------------------------------- meshes


def distractor_mesh(d: Distractor, layout: Layout) -> ColouredMesh:
    """The distractor built in its local frame and placed on its wall (label -2, its gloss)."""
    rng = np.random.default_rng(d.variant)
    local = _BUILD[d.kind](d, rng)
    fr = layout.walls[d.wall].frame
    rot = np.column_stack([fr.axis_u, fr.axis_v, fr.normal])
    local = local.glossy(GLOSS.get(d.kind, 0.05)) if d.kind in GLOSS else local
    return local.transformed(rot, fr.to_world(d.u, d.v, d.gap_m)).labelled(DISTRACTOR_LABEL)


def _span(x0, x1, y0, y1, *, z0, z1, colour) -> ColouredMesh:
    return M.box((x1 - x0, y1 - y0, z1 - z0), colour, ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2))


def _front(image: np.ndarray, w: float, h: float, z: float) -> ColouredMesh:
    return M.quad((-w / 2, -h / 2, z), (w, 0, 0), (0, h, 0), texture=image)


def _print(w: float, h: float, rng: np.random.Generator, background=None) -> np.ndarray:
    """A random picture: coloured blocks, discs and text lines (no safety colours on purpose)."""
    bg = background if background is not None else tuple(int(c) for c in rng.integers(40, 250, 3))
    p = pic.Painter.new(w, h, bg, px_per_m=600)
    for _ in range(int(rng.integers(3, 9))):
        col = tuple(int(c) for c in rng.integers(0, 256, 3))
        x0, y0 = rng.uniform(0, w * 0.8), rng.uniform(0, h * 0.8)
        if rng.random() < 0.5:
            p.rect(x0, y0, min(w, x0 + rng.uniform(0.03, w / 2)), min(h, y0 + rng.uniform(0.03, h / 2)), col)
        else:
            p.circle((x0, y0), rng.uniform(0.02, min(w, h) / 4), col)
    if rng.random() < 0.6:
        p.text_lines(w * 0.1, h * 0.75, w * 0.9, int(rng.integers(2, 5)), pitch_m=0.02,
                     height_m=0.01, colour=(20, 20, 20),
                     seed=int(rng.integers(1 << 30)))
    return p.img


def _picture(d: Distractor, rng) -> ColouredMesh:
    w, h, t = d.width_m, d.height_m, d.depth_m
    b = float(rng.uniform(0.02, 0.04))
    frame_col = [(30, 30, 30), (150, 110, 70), (190, 190, 195), (235, 235, 230)][int(rng.integers(4))]
    parts = [_span(-w / 2, w / 2, -h / 2, -h / 2 + b, z0=0, z1=t, colour=frame_col),
             _span(-w / 2, w / 2, h / 2 - b, h / 2, z0=0, z1=t, colour=frame_col),
             _span(-w / 2, -w / 2 + b, -h / 2, h / 2, z0=0, z1=t, colour=frame_col),
             _span(w / 2 - b, w / 2, -h / 2, h / 2, z0=0, z1=t, colour=frame_col),
             _span(-w / 2 + b, w / 2 - b, -h / 2 + b, h / 2 - b, z0=0, z1=t - 0.008, colour=(240, 240, 240))]
    parts.append(_front(_print(w - 2 * b, h - 2 * b, rng), w - 2 * b, h - 2 * b, t - 0.008 + 1e-4))
    return M.merge(parts)


def _poster(d: Distractor, rng) -> ColouredMesh:
    return _front(_print(d.width_m, d.height_m, rng), d.width_m, d.height_m, d.depth_m)


def _notice_board(d: Distractor, rng) -> ColouredMesh:
    w, h, t = d.width_m, d.height_m, d.depth_m
    p = pic.Painter.new(w, h, (176, 134, 92), px_per_m=600)
    p.rect(0, 0, w, 0.015, (180, 182, 186))
    p.rect(0, h - 0.015, w, h, (180, 182, 186))
    p.rect(0, 0, 0.015, h, (180, 182, 186))
    p.rect(w - 0.015, 0, w, h, (180, 182, 186))
    for _ in range(int(rng.integers(3, 8))):
        x0, y0 = rng.uniform(0.03, w - 0.25), rng.uniform(0.03, h - 0.3)
        col = [(245, 245, 240), (250, 240, 150), (200, 230, 250), (250, 200, 210)][int(rng.integers(4))]
        p.rect(x0, y0, x0 + 0.21, y0 + 0.297 * rng.uniform(0.5, 1.0), col)
        p.text_lines(x0 + 0.02, y0 + 0.03, x0 + 0.19, 4, pitch_m=0.02, height_m=0.008, colour=(40, 40, 40),
                     seed=int(rng.integers(1 << 30)))
    return M.merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0, z1=t - 0.0005, colour=(176, 134, 92)),
                    _front(p.img, w, h, t)])


def _whiteboard(d: Distractor, rng) -> ColouredMesh:
    w, h, t = d.width_m, d.height_m, d.depth_m
    p = pic.Painter.new(w, h, (246, 247, 247), px_per_m=600)
    for edge in ((0, 0, w, 0.02), (0, h - 0.02, w, h), (0, 0, 0.02, h), (w - 0.02, 0, w, h)):
        p.rect(*edge, (190, 192, 196))
    if rng.random() < 0.7:  # some writing left on it
        p.text_lines(0.1, 0.1, w * 0.6, int(rng.integers(2, 6)), pitch_m=0.06, height_m=0.03,
                     colour=[(30, 60, 160), (20, 20, 20), (180, 30, 30)][int(rng.integers(3))],
                     seed=int(rng.integers(1 << 30)))
    tray = _span(-w / 2 + 0.1, w / 2 - 0.1, -h / 2 - 0.03, -h / 2, z0=0, z1=0.06, colour=(190, 192, 196))
    return M.merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0, z1=t - 0.0005,
                          colour=(246, 247, 247)), _front(p.img, w, h, t), tray])


def _clock(d: Distractor, rng) -> ColouredMesh:
    r, t = d.width_m / 2, d.depth_m
    rim = [(25, 25, 25), (200, 200, 205), (160, 30, 30)][int(rng.integers(3))]
    p = pic.Painter.new(2 * r, 2 * r, rim, px_per_m=1500)
    p.circle((r, r), r * 0.9, (245, 245, 240))
    for k in range(12):
        a = k * math.pi / 6
        p.line(np.array([[r + 0.78 * r * math.sin(a), r - 0.78 * r * math.cos(a)],
                         [r + 0.88 * r * math.sin(a), r - 0.88 * r * math.cos(a)]]), (20, 20, 20), 0.006)
    for length, width, a in ((0.5, 0.008, rng.uniform(0, 6.3)), (0.75, 0.005, rng.uniform(0, 6.3))):
        p.line(np.array([[r, r], [r + length * r * math.sin(a), r - length * r * math.cos(a)]]), (20, 20, 20), width)
    body = M.cylinder(r, t, rim, segments=32, centre=(0, 0, t / 2), axis=2)
    face = M.quad((-r * 0.72, -r * 0.72, t + 1e-4), (1.44 * r, 0, 0), (0, 1.44 * r, 0),
                  texture=p.img[int(0.14 * r * 1500):-int(0.14 * r * 1500) or None,
                                int(0.14 * r * 1500):-int(0.14 * r * 1500) or None])
    return M.merge([body, face])


def _thermostat(d: Distractor, rng) -> ColouredMesh:
    w, h, t = d.width_m, d.height_m, d.depth_m
    col = (238, 238, 234)
    p = pic.Painter.new(w, h, col)
    p.round_rect(w * 0.2, h * 0.2, w * 0.8, h * 0.45, 0.003, colour=(60, 70, 75))  # display
    p.text(f"{rng.integers(18, 24)}.{rng.integers(0, 10)}", w * 0.25, h * 0.4, h * 0.12, (170, 220, 200))
    p.circle((w * 0.5, h * 0.72), min(w, h) * 0.12, (205, 205, 200))
    return M.merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0, z1=t - 0.0005, colour=col),
                    _front(p.img, w, h, t)])


def _room_controller(d: Distractor, rng) -> ColouredMesh:
    w, h, t = d.width_m, d.height_m, d.depth_m
    col = (242, 242, 238)
    p = pic.Painter.new(w, h, col)
    p.circle((w / 2, h / 2), w * 0.32, (215, 215, 210), width_m=0.004)  # a dial ring
    p.circle((w / 2, h * 0.2), 0.002, (40, 160, 60))  # status LED
    dial = M.cylinder(w * 0.3, 0.008, (232, 232, 228), segments=24, centre=(0, 0, t + 0.004), axis=2)
    return M.merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0, z1=t - 0.0005, colour=col),
                    _front(p.img, w, h, t), dial])


def _trunking(d: Distractor, rng) -> ColouredMesh:
    w, h, t = d.width_m, d.height_m, d.depth_m
    col = (236, 236, 232)
    return M.merge([_span(-w / 2, w / 2, -h / 2, h / 2, z0=0, z1=t, colour=col),
                    _span(-w / 2, w / 2, -0.001, 0.001, z0=t, z1=t + 0.001,
                          colour=(215, 215, 210))])  # cover seam


def _coat_hooks(d: Distractor, rng) -> ColouredMesh:
    w, h = d.width_m, d.height_m
    wood = [(150, 110, 70), (210, 190, 150), (40, 40, 40)][int(rng.integers(3))]
    parts = [_span(-w / 2, w / 2, -h / 2, h / 2, z0=0, z1=0.02, colour=wood)]
    n = int(rng.integers(3, 6))
    for k in range(n):
        x = -w / 2 + (k + 0.5) * w / n
        parts.append(_span(x - 0.008, x + 0.008, -0.01, 0.02, z0=0.02, z1=d.depth_m, colour=(170, 170, 175)))
    return M.merge(parts)


def _door_stop(d: Distractor, rng) -> ColouredMesh:
    return M.merge([M.cylinder(0.02, d.depth_m - 0.015, (120, 120, 125), segments=16,
                               centre=(0, 0, (d.depth_m - 0.015) / 2), axis=2),
                    M.cylinder(0.018, 0.015, (35, 35, 35), segments=16,
                               centre=(0, 0, d.depth_m - 0.0075), axis=2)])


def _furniture_colour(rng) -> tuple[int, int, int]:
    return [(235, 233, 226), (160, 120, 80), (120, 122, 126), (200, 180, 140), (60, 62, 66)][int(rng.integers(5))]


def _desk(d: Distractor, rng) -> ColouredMesh:
    w, h, dd = d.width_m, d.height_m, d.depth_m
    top, leg = _furniture_colour(rng), (90, 92, 96)
    y0 = -h / 2
    parts = [_span(-w / 2, w / 2, h / 2 - 0.03, h / 2, z0=0, z1=dd, colour=top)]
    for x in (-w / 2 + 0.03, w / 2 - 0.03):
        for z in (0.03, dd - 0.03):
            parts.append(_span(x - 0.025, x + 0.025, y0, h / 2 - 0.03, z0=z - 0.025, z1=z + 0.025,
                               colour=leg))
    parts.append(_span(-w / 2 + 0.06, w / 2 - 0.06, h / 2 - 0.35, h / 2 - 0.03, z0=0.02, z1=0.035,
                       colour=top))  # modesty panel
    if rng.random() < 0.5:  # a drawer unit under one side
        x = w / 2 - 0.26 if rng.random() < 0.5 else -w / 2 + 0.26
        parts.append(_span(x - 0.2, x + 0.2, y0, y0 + 0.6, z0=0.05, z1=dd - 0.05, colour=top))
    return M.merge(parts)


def _cabinet(d: Distractor, rng) -> ColouredMesh:
    w, h, dd = d.width_m, d.height_m, d.depth_m
    col = _furniture_colour(rng)
    parts = [_span(-w / 2, w / 2, -h / 2, h / 2, z0=0, z1=dd, colour=col),
             _span(-0.002, 0.002, -h / 2 + 0.05, h / 2 - 0.02, z0=dd, z1=dd + 0.002, colour=(70, 70, 70))]
    for x in (-0.04, 0.04):
        parts.append(_span(x - 0.006, x + 0.006, h / 2 - 0.25, h / 2 - 0.1, z0=dd, z1=dd + 0.025,
                           colour=(180, 180, 185)))
    return M.merge(parts)


def _shelf(d: Distractor, rng) -> ColouredMesh:
    w, h, dd = d.width_m, d.height_m, d.depth_m
    col = _furniture_colour(rng)
    t = 0.018
    parts = [_span(-w / 2, -w / 2 + t, -h / 2, h / 2, z0=0, z1=dd, colour=col),
             _span(w / 2 - t, w / 2, -h / 2, h / 2, z0=0, z1=dd, colour=col)]
    n = 5
    for k in range(n):
        y = -h / 2 + k * (h - t) / (n - 1)
        parts.append(_span(-w / 2 + t, w / 2 - t, y, y + t, z0=0, z1=dd, colour=col))
        if k < n - 1 and rng.random() < 0.7:  # books / folders
            x = -w / 2 + t
            while x < w / 2 - t - 0.05:
                bw = float(rng.uniform(0.02, 0.06))
                bh = float(rng.uniform(0.18, min(0.32, (h - t) / (n - 1) - 0.03)))
                parts.append(_span(x, x + bw, y + t, y + t + bh, z0=0.02, z1=dd - 0.03,
                                   colour=tuple(int(c) for c in rng.integers(20, 240, 3))))
                x += bw + (0.0 if rng.random() < 0.8 else float(rng.uniform(0.05, 0.2)))
    return M.merge(parts)


def _chair(d: Distractor, rng) -> ColouredMesh:
    w, h, dd = d.width_m, d.height_m, d.depth_m
    col, metal = _furniture_colour(rng), (60, 60, 64)
    y0 = -h / 2
    seat = y0 + 0.45
    parts = [_span(-w / 2, w / 2, seat - 0.03, seat, z0=0.0, z1=dd, colour=col),
             _span(-w / 2, w / 2, seat + 0.15, h / 2, z0=0.0, z1=0.03,
                   colour=col)]  # back rest towards the wall
    for x in (-w / 2 + 0.02, w / 2 - 0.02):
        for z in (0.02, dd - 0.02):
            parts.append(_span(x - 0.012, x + 0.012, y0, seat - 0.03, z0=z - 0.012, z1=z + 0.012,
                               colour=metal))
        parts.append(_span(x - 0.012, x + 0.012, seat, seat + 0.15, z0=0.005, z1=0.029, colour=metal))
    return M.merge(parts)


def _bin(d: Distractor, rng) -> ColouredMesh:
    r = d.width_m / 2
    col = [(40, 40, 40), (200, 200, 200), (30, 90, 160), (180, 40, 40)][int(rng.integers(4))]
    return M.cylinder(r, d.height_m, col, segments=24, centre=(0, 0, r), axis=1, capped=True)


_BUILD = {"picture": _picture, "poster": _poster, "notice_board": _notice_board, "whiteboard": _whiteboard,
          "clock": _clock, "thermostat": _thermostat, "room_controller": _room_controller,
          "trunking": _trunking, "coat_hooks": _coat_hooks, "door_stop": _door_stop,
          "desk": _desk, "cabinet": _cabinet, "tall_cabinet": _cabinet, "shelf": _shelf, "chair": _chair,
          "bin": _bin}
