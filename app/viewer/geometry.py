"""The 3D scene's geometry: wall and surface planes, rays hitting them, column meshes,
the scan's tiles."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import viser.transforms as vtf

from sbsc_core.types import WallFrame

from ..surfaces import is_round, kind_of


def rect_segments(frame: WallFrame, u0: float, u1: float, v0: float, v1: float,
                  d: float = 0.0) -> np.ndarray:
    """The four sides of a (u, v) rectangle on a wall as (4, 2, 3) world segments."""
    c = frame.to_world(np.array([u0, u1, u1, u0]), np.array([v0, v0, v1, v1]), d)
    return np.stack([c, np.roll(c, -1, axis=0)], axis=1)


def plane_wxyz(frame: WallFrame) -> np.ndarray:
    """Orientation of a viser image on a wall: image x along u, image rows downwards.

    viser draws an image in its node's x-y plane with the top row towards -y (the OpenCV
    camera convention), so the node's axes are (axis_u, -axis_v, -normal).
    """
    rot = np.stack([frame.axis_u, -frame.axis_v, -frame.normal], axis=1)
    return vtf.SO3.from_matrix(rot).wxyz


@dataclass
class ScanTile:
    """Scan points of one ``tile_m`` square: float16 offsets from ``position``."""

    points: np.ndarray  # (n, 3) float16
    colors: np.ndarray  # (n, 3) uint8
    position: np.ndarray  # (3,) float64, scene coordinates
    point_size: float


def make_tiles(p: np.ndarray, c: np.ndarray, size: float, tile_m: float) -> list[ScanTile]:
    """Split points into square tiles in plan, each centred on its bounding box."""
    if len(p) == 0:
        return []
    lo = p[:, :2].min(axis=0)
    key = np.floor((p[:, :2] - lo) / tile_m).astype(np.int64)
    tile_id = key[:, 0] * 1_000_003 + key[:, 1]
    order = np.argsort(tile_id, kind="stable")
    bounds = np.flatnonzero(np.diff(tile_id[order])) + 1
    tiles = []
    for idx in np.split(order, bounds):
        tp = p[idx].astype(np.float64)
        mid = (tp.min(axis=0) + tp.max(axis=0)) / 2.0
        tiles.append(ScanTile((tp - mid).astype(np.float16), c[idx], mid, size))
    return tiles


def wall_hit(frames: dict[str, WallFrame], origin: np.ndarray, direction: np.ndarray
             ) -> tuple[str, float, float] | None:
    """The first wall (id, u, v) a ray meets from its room side, or None."""
    best = None
    d = np.asarray(direction, float)
    for wid, f in frames.items():
        den = float(np.dot(d, f.normal))
        if den >= -1e-9:  # parallel, or seen from behind
            continue
        t = float(np.dot(f.origin - origin, f.normal)) / den
        if t <= 0 or (best is not None and t >= best[0]):
            continue
        p = origin + t * d - f.origin
        u, v = float(np.dot(p, f.axis_u)), float(np.dot(p, f.axis_v))
        if 0.0 <= u <= f.width_m and 0.0 <= v <= f.height_m:
            best = (t, wid, u, v)
    return None if best is None else best[1:]


def _ray_cylinder(centre: np.ndarray, r: float, z0: float, z1: float, origin: np.ndarray,
                  direction: np.ndarray) -> tuple[float, float, float] | None:
    """Where a ray first meets a vertical cylinder from outside: (t, u, v), u the arc length
    counter-clockwise from +x, v the height above ``z0``; None when it misses."""
    ox, oy = origin[0] - centre[0], origin[1] - centre[1]
    dx, dy = direction[0], direction[1]
    a = dx * dx + dy * dy
    if a < 1e-12:
        return None
    b = 2.0 * (ox * dx + oy * dy)
    c = ox * ox + oy * oy - r * r
    disc = b * b - 4 * a * c
    if c <= 0 or disc < 0:  # the ray starts inside, or misses
        return None
    t = (-b - np.sqrt(disc)) / (2 * a)
    if t <= 0:
        return None
    p = origin + t * direction
    if not z0 <= p[2] <= z1:
        return None
    ang = float(np.arctan2(p[1] - centre[1], p[0] - centre[0])) % (2 * np.pi)
    return float(t), ang * r, float(p[2] - z0)


def surface_hit(frames: dict[str, WallFrame], rounds: dict[str, dict], origin: np.ndarray,
                direction: np.ndarray) -> tuple[str, float, float] | None:
    """The first wall or surface (id, u, v) a ray meets from its room side, or None.

    ``frames`` are planar (walls, ceilings seen from below, a rectangular column's faces);
    ``rounds`` the round columns' surfaces (contract 4: ``radius_m``, ``centre``).
    """
    d = np.asarray(direction, float)
    o = np.asarray(origin, float)
    best: tuple[float, str, float, float] | None = None
    hit = wall_hit(frames, o, d)
    if hit is not None:
        f = frames[hit[0]]
        t = float(np.dot(f.to_world(hit[1], hit[2]) - o, d) / max(float(np.dot(d, d)), 1e-12))
        best = (t, *hit)
    for sid, sf in rounds.items():
        z0 = float(sf["origin"][2])
        got = _ray_cylinder(np.asarray(sf["centre"], float), float(sf["radius_m"]), z0,
                            z0 + float(sf["height_m"]), o, d)
        if got is not None and (best is None or got[0] < best[0]):
            best = (got[0], sid, got[1], got[2])
    return None if best is None else best[1:]


def cylinder_mesh(centre: Any, r: float, z0: float, z1: float, segments: int = 32
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A closed vertical cylinder as (vertices, triangles), faces outwards."""
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.column_stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a)])
    return prism_mesh(ring, z0, z1)


def prism_mesh(ring: np.ndarray, z0: float, z1: float) -> tuple[np.ndarray, np.ndarray]:
    """A vertical prism over a convex plan polygon (counter-clockwise) as (vertices, triangles)."""
    n = len(ring)
    v = np.concatenate([np.column_stack([ring, np.full(n, z0)]), np.column_stack([ring, np.full(n, z1)]),
                        [[*ring.mean(axis=0), z0], [*ring.mean(axis=0), z1]]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i],  # side
                  [2 * n, j, i], [2 * n + 1, n + i, n + j]]  # bottom, top
    return v.astype(np.float32), np.asarray(faces, np.uint32)


def column_meshes(surfaces: list[dict], inset_m: float = 0.003) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each column of contract 4's ``surfaces`` (kind ``column``) as a mesh: a round one as its
    cylinder, a rectangular one as the box its faces span (``inset_m`` inside them)."""
    faces: dict[str, list[dict]] = {}
    for sf in surfaces:
        if kind_of(sf) == "column":
            cid = str(sf.get("column") or sf["id"].rsplit("-", 1)[0])
            faces.setdefault(cid, []).append(sf)
    out = {}
    for cid, fs in faces.items():
        z0 = min(float(f["origin"][2]) for f in fs)
        z1 = max(float(f["origin"][2]) + float(f["height_m"]) for f in fs)
        rnd = next((f for f in fs if is_round(f)), None)
        if rnd is not None:
            out[cid] = cylinder_mesh(rnd["centre"], float(rnd["radius_m"]) - inset_m, z0, z1)
            continue
        pts = np.concatenate([[np.asarray(f["origin"], float)[:2],
                               (np.asarray(f["origin"], float) + float(f["width_m"]) * np.asarray(f["axis_u"], float))[:2]]
                              for f in fs])
        mid = pts.mean(axis=0)
        ang = np.arctan2(pts[:, 1] - mid[1], pts[:, 0] - mid[0])
        ring = pts[np.argsort(ang)]
        keep = np.concatenate([[True], np.linalg.norm(np.diff(ring, axis=0), axis=1) > 1e-3])
        ring = ring[keep]
        if len(ring) > 1 and np.linalg.norm(ring[0] - ring[-1]) <= 1e-3:
            ring = ring[:-1]
        if len(ring) < 3:
            continue
        ring = mid + (ring - mid) * (1.0 - inset_m / max(float(np.linalg.norm(ring - mid, axis=1).min()), 1e-3))
        out[cid] = prism_mesh(ring, z0, z1)
    return out


def wrapped_cylinder(img: np.ndarray, sf: dict, pixel_m: float, offset_m: float, segments: int = 64) -> Any:
    """A round column's unrolled orthoimage wrapped back round it: a textured ``trimesh.Trimesh``
    (seen from outside only), in world coordinates. The image's column c is at the arc length
    ``(c + 0.5) * pixel_m`` counter-clockwise from +x, its rows from the top (contract 4)."""
    import trimesh
    from PIL import Image

    r = float(sf["radius_m"]) + offset_m
    cx, cy = (float(c) for c in sf["centre"])
    z0 = float(sf["origin"][2])
    circ = 2 * np.pi * float(sf["radius_m"])
    w_m, h_m = img.shape[1] * pixel_m, img.shape[0] * pixel_m
    top = z0 + float(sf["height_m"])
    a = np.linspace(0.0, 2 * np.pi, segments + 1)
    ring = np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)])
    n = segments + 1
    verts = np.concatenate([np.column_stack([ring, np.full(n, top - h_m)]), np.column_stack([ring, np.full(n, top)])])
    u = (a / (2 * np.pi)) * circ / w_m  # the image may be longer than the circumference (its seam repeated)
    uv = np.concatenate([np.column_stack([u, np.zeros(n)]), np.column_stack([u, np.ones(n)])])
    faces = []
    for k in range(segments):
        faces += [[k, k + 1, n + k + 1], [k, n + k + 1, n + k]]  # outwards
    material = trimesh.visual.material.PBRMaterial(  # matte, not metallic (glTF's default is metallic)
        baseColorTexture=Image.fromarray(np.ascontiguousarray(img)), metallicFactor=0.0, roughnessFactor=1.0)
    visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    return trimesh.Trimesh(verts, np.asarray(faces), visual=visual, process=False)
