"""Synthetic coloured point clouds of rooms and synthetic orthoimages, with their truth.

Used by the segmentation / orthoimage / colour preparation / wall area tests. Rooms are
convex or not, given by the counter-clockwise outline of their free space; every outline
edge is one wall face whose frame follows contract 4 (origin at the lower-left corner seen
from the room = the edge's end vertex, ``axis_u`` = minus the edge direction, ``normal``
into the room). Features are given in that face's (u, v) metres. Everything is
deterministic for a seed and numpy only.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from sbsc_core.types import Orthoimage, PointCloud, Wall, WallFrame

ORIGIN = (1000.0, -2000.0, 50.0)  # world = xyz + ORIGIN (the storeys' scenes)

RGB = tuple[int, int, int]


@dataclass(frozen=True)
class Hole:
    """A door or window: no wall surface there (the scanner looks through)."""

    kind: str
    u0: float
    u1: float
    v0: float
    v1: float


@dataclass(frozen=True)
class Block:
    """A box standing out of the wall by ``depth`` (negative: a recess)."""

    u0: float
    u1: float
    v0: float
    v1: float
    depth: float
    rgb: RGB


@dataclass(frozen=True)
class Patch:
    """A flat coloured rectangle painted on the wall (a sign)."""

    u0: float
    u1: float
    v0: float
    v1: float
    rgb: RGB


@dataclass
class Room:
    outline: Sequence[tuple[float, float]]  # counter-clockwise free space
    features: dict[int, list] = field(default_factory=dict)  # edge index -> Hole / Block / Patch
    rgb: RGB = (205, 200, 190)


def face_frame(a: Sequence[float], b: Sequence[float], height: float, floor_z: float = 0.0) -> WallFrame:
    """Contract-4 frame of the room-side face of the CCW outline edge a -> b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    e = (b - a) / np.linalg.norm(b - a)
    return WallFrame(origin=np.array([b[0], b[1], floor_z]), axis_u=np.array([-e[0], -e[1], 0.0]),
                     axis_v=np.array([0.0, 0.0, 1.0]), normal=np.array([-e[1], e[0], 0.0]),
                     width_m=float(np.linalg.norm(b - a)), height_m=float(height))


def plan_wall(wid: str, a: Sequence[float], b: Sequence[float], height: float, storey: str = "S1") -> Wall:
    """A segmented wall from plan point ``a`` to ``b`` (seen from the room on its left), no points."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    e = (b - a) / np.linalg.norm(b - a)
    frame = WallFrame(np.array([a[0], a[1], 0.0]), np.array([e[0], e[1], 0.0]), np.array([0.0, 0.0, 1.0]),
                      np.array([e[1], -e[0], 0.0]), float(np.linalg.norm(b - a)), height)
    return Wall(wid, frame, np.zeros(0, np.int64), storey)


def _grid(u0: float, u1: float, v0: float, v1: float, step: float, rng: np.random.Generator
          ) -> tuple[np.ndarray, np.ndarray]:
    nu, nv = max(1, int(round((u1 - u0) / step))), max(1, int(round((v1 - v0) / step)))
    uu, vv = np.meshgrid(u0 + (np.arange(nu) + 0.5) * (u1 - u0) / nu, v0 + (np.arange(nv) + 0.5) * (v1 - v0) / nv)
    uu = uu.ravel() + rng.uniform(-0.3, 0.3, uu.size) * (u1 - u0) / nu
    vv = vv.ravel() + rng.uniform(-0.3, 0.3, vv.size) * (v1 - v0) / nv
    return uu, vv


def _inside(u: np.ndarray, v: np.ndarray, f) -> np.ndarray:
    return (u > f.u0) & (u < f.u1) & (v > f.v0) & (v < f.v1)


def _in_polygon(xy: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule, vectorized over points."""
    x, y = xy[:, 0], xy[:, 1]
    inside = np.zeros(len(xy), bool)
    for i in range(len(poly)):
        (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % len(poly)]
        cross = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= cross & (x < xi)
    return inside


def face_points(frame: WallFrame, features: list, spacing: float, rng: np.random.Generator, rgb: RGB,
                see_through_m: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """World points (no noise) and colours of one wall face with its features."""
    u, v = _grid(0.0, frame.width_m, 0.0, frame.height_m, spacing, rng)
    d = np.zeros_like(u)
    col = np.tile(np.asarray(rgb, np.float64), (len(u), 1))
    keep = np.ones(len(u), bool)
    extra_uvd, extra_rgb = [], []
    for f in features:
        m = _inside(u, v, f)
        if isinstance(f, Hole):
            keep &= ~m
            if see_through_m > 0:  # what the scanner sees through the hole, far behind the wall
                eu, ev = u[m], v[m]
                extra_uvd.append(np.column_stack([eu, ev, np.full(len(eu), -see_through_m)]))
                extra_rgb.append(np.tile([90.0, 90.0, 90.0], (len(eu), 1)))
        elif isinstance(f, Block):
            keep &= ~m
            fu, fv = _grid(f.u0, f.u1, f.v0, f.v1, spacing, rng)
            parts = [np.column_stack([fu, fv, np.full(len(fu), f.depth)])]
            dd = np.linspace(0, f.depth, max(2, int(abs(f.depth) / spacing) + 1))
            for a, b, along_u in ((f.u0, f.u1, True), (f.v0, f.v1, False)):
                line = np.arange(a, b, spacing)
                g1, g2 = np.meshgrid(line, dd)
                for edge in ((f.v0, f.v1) if along_u else (f.u0, f.u1)):
                    if along_u:
                        parts.append(np.column_stack([g1.ravel(), np.full(g1.size, edge), g2.ravel()]))
                    else:
                        parts.append(np.column_stack([np.full(g1.size, edge), g1.ravel(), g2.ravel()]))
            p = np.concatenate(parts)
            extra_uvd.append(p)
            extra_rgb.append(np.tile(np.asarray(f.rgb, float), (len(p), 1)))
        elif isinstance(f, Patch):
            col[m] = f.rgb
    uvd = np.column_stack([u, v, d])[keep]
    col = col[keep]
    if extra_uvd:
        uvd = np.concatenate([uvd, *extra_uvd])
        col = np.concatenate([col, *extra_rgb])
    xyz = frame.to_world(uvd[:, 0], uvd[:, 1], uvd[:, 2])
    return xyz, col


def make_scene(rooms: Sequence[Room], height: float = 2.7, floor_z: float = 0.0, spacing: float = 0.02,
               noise_m: float = 0.002, colour_noise: float = 2.0,
               gain: Callable[[np.ndarray], np.ndarray] | None = None,
               specular: Sequence[tuple[Sequence[float], float, float]] = (),
               origin: Sequence[float] = (0.0, 0.0, 0.0), seed: int = 0, see_through_m: float = 1.5,
               floor_rgb: RGB = (130, 120, 110), ceiling_rgb: RGB = (240, 240, 236)) -> tuple[PointCloud, dict]:
    """A point cloud of the rooms (walls, floor, ceiling) and its truth.

    ``gain(xyz) -> (N,)`` multiplies colours (station illumination); ``specular`` is a list
    of (centre xyz, sigma m, amplitude levels) white additive blobs. Through each hole the
    scanner sees a surface ``see_through_m`` behind the wall (0: nothing). The cloud's points are
    stored relative to ``origin`` (world = xyz + origin). Truth: ``{"floor_z", "ceiling_z",
    "walls": [{"room", "edge", **frame}], "openings": [{"wall": index, kind, u/v}]}``.
    """
    rng = np.random.default_rng(seed)
    pts, cols, walls, openings = [], [], [], []
    for ri, room in enumerate(rooms):
        poly = np.asarray(room.outline, float)
        for k in range(len(poly)):
            fr = face_frame(poly[k], poly[(k + 1) % len(poly)], height, floor_z)
            feats = room.features.get(k, [])
            p, c = face_points(fr, feats, spacing, rng, room.rgb, see_through_m)
            nrm = rng.normal(0.0, noise_m, len(p))
            p = p + nrm[:, None] * fr.normal
            pts.append(p)
            cols.append(c)
            walls.append({"room": ri, "edge": k, **fr.to_dict()})
            for f in feats:
                if isinstance(f, Hole):
                    openings.append({"wall": len(walls) - 1, "kind": f.kind, "u_min": f.u0, "u_max": f.u1,
                                     "v_min": f.v0, "v_max": f.v1})
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        gx, gy = _grid(lo[0], hi[0], lo[1], hi[1], spacing, rng)
        xy = np.column_stack([gx, gy])
        xy = xy[_in_polygon(xy, poly)]
        for z, rgb in ((floor_z, floor_rgb), (floor_z + height, ceiling_rgb)):
            zz = z + rng.normal(0.0, noise_m, len(xy))
            pts.append(np.column_stack([xy, zz]))
            cols.append(np.tile(np.asarray(rgb, float), (len(xy), 1)))
    xyz = np.concatenate(pts)
    rgb = np.concatenate(cols)
    if gain is not None:
        rgb = rgb * np.asarray(gain(xyz), float)[:, None]
    for centre, sigma, amp in specular:
        r2 = np.sum((xyz - np.asarray(centre, float)) ** 2, axis=1)
        rgb = rgb + amp * np.exp(-r2 / (2 * sigma**2))[:, None]
    rgb = rgb + rng.normal(0.0, colour_noise, rgb.shape)
    rgb = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    org = np.asarray(origin, float)
    cloud = PointCloud(xyz=(xyz - org).astype(np.float32), rgb=rgb, origin=org)
    truth = {"floor_z": floor_z, "ceiling_z": floor_z + height, "walls": walls, "openings": openings}
    return cloud, truth


def rotated(outline: Sequence[tuple[float, float]], deg: float, shift: Sequence[float] = (0.0, 0.0)
            ) -> list[tuple[float, float]]:
    a = np.radians(deg)
    r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    p = np.asarray(outline, float) @ r.T + np.asarray(shift, float)
    return [(float(x), float(y)) for x, y in p]


# --------------------------------------------------------------------------- orthoimages


def ortho_frame(width_m: float, height_m: float) -> WallFrame:
    """A wall along +x seen from -y (normal -y), origin at the world origin."""
    return WallFrame(origin=np.zeros(3), axis_u=np.array([1.0, 0.0, 0.0]), axis_v=np.array([0.0, 0.0, 1.0]),
                     normal=np.array([0.0, -1.0, 0.0]), width_m=width_m, height_m=height_m)


def make_ortho(width_m: float = 4.0, height_m: float = 2.7, pixel_m: float = 0.005,
               wall_rgb: RGB = (205, 200, 190), features: Sequence = (), noise: float = 2.0,
               depth_noise_m: float = 0.001, gains: Sequence[tuple[float, float, float, float, float]] = (),
               specular: Sequence[tuple[float, float, float, float]] = (),
               nodata: Sequence[tuple[float, float, float, float]] = (), seed: int = 0,
               wall_id: str = "W01") -> Orthoimage:
    """An orthoimage J_CD drawn directly (no points).

    ``features``: Hole (no data; with ``kind`` door/window), Block (relief + colour), Patch.
    ``gains``: (u0, u1, v0, v1, gain) multiplicative colour steps (stations);
    ``specular``: (u, v, sigma_m, amplitude) additive white blobs; ``nodata``: unscanned
    rectangles (u0, u1, v0, v1) that are not openings.
    """
    rng = np.random.default_rng(seed)
    fr = ortho_frame(width_m, height_m)
    h, w = int(np.ceil(height_m / pixel_m - 1e-9)), int(np.ceil(width_m / pixel_m - 1e-9))
    u = (np.arange(w) + 0.5) * pixel_m
    v = height_m - (np.arange(h) + 0.5) * pixel_m
    uu, vv = np.meshgrid(u, v)
    col = np.empty((h, w, 3), float)
    col[:] = wall_rgb
    depth = np.zeros((h, w), float)
    mask = np.ones((h, w), bool)
    for f in features:
        m = _inside(uu, vv, f)
        if isinstance(f, Hole):
            mask &= ~m
        elif isinstance(f, Block):
            depth[m] = f.depth
            col[m] = f.rgb
        elif isinstance(f, Patch):
            col[m] = f.rgb
    for u0, u1, v0, v1 in nodata:
        mask &= ~((uu > u0) & (uu < u1) & (vv > v0) & (vv < v1))
    for u0, u1, v0, v1, g in gains:
        m = (uu > u0) & (uu < u1) & (vv > v0) & (vv < v1)
        col[m] *= g
    for cu, cv, sig, amp in specular:
        col += amp * np.exp(-((uu - cu) ** 2 + (vv - cv) ** 2) / (2 * sig**2))[..., None]
    col += rng.normal(0.0, noise, col.shape)
    depth += rng.normal(0.0, depth_noise_m, depth.shape)
    colour = np.clip(np.rint(col), 0, 255).astype(np.uint8)
    colour[~mask] = 0
    d32 = depth.astype(np.float32)
    d32[~mask] = np.nan
    return Orthoimage(wall_id=wall_id, frame=fr, pixel_m=pixel_m, colour=colour, depth=d32, mask=mask)


def _stack(*clouds: PointCloud) -> PointCloud:
    assert all(np.array_equal(c.origin, clouds[0].origin) for c in clouds)
    return PointCloud(np.concatenate([c.xyz for c in clouds]), np.concatenate([c.rgb for c in clouds]),
                      clouds[0].origin)


def _two_rooms(floor_z: float, heights: tuple[float, float], seed: int) -> list[PointCloud]:
    a = Room([(0, 0), (4, 0), (4, 3.5), (0, 3.5)], {1: [Hole("door", 1.0, 1.9, 0, 2.1)]})
    b = Room([(4.15, 0), (8, 0), (8, 3.5), (4.15, 3.5)], {3: [Hole("door", 1.6, 2.5, 0, 2.1)]})
    return [make_scene([room], height=h, floor_z=floor_z, spacing=0.03, noise_m=0.002, see_through_m=0.0,
                       origin=ORIGIN, seed=seed + i)[0] for i, (room, h) in enumerate(zip((a, b), heights, strict=True))]
