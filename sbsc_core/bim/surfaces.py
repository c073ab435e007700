"""Surfaces beyond walls on the BIM side (issue 11): ceilings and column faces.

A detections document (contract 4) may list ``surfaces`` (kind ``ceiling`` or ``column``)
beside its walls; a ground truth (contract 5) lists them too, plus its ``columns``. This
module reads them into :class:`~sbsc_core.types.Surface` and gives what the IFC export,
the as-designed reader and Scan-vs-BIM need:

- :func:`read_surfaces`: the ``surfaces`` of a document by id;
- :func:`column_bodies`: the columns the faces belong to, as bodies from floor to ceiling
  (a rectangle from its faces' frames, a circle from a round face's ``centre``/``radius_m``);
- :func:`surface_coords` / :func:`surface_normal`: (u, v, d) of points on a surface and
  its normal at a point (round faces: on the cylinder, not on the unrolled frame);
- :func:`object_matrix`: the world matrix of an object on a surface (the IFC placement).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError
from ..types import Surface, WallFrame

_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class ColumnBody:
    """A free-standing column as a body: a rectangle or a circle extruded floor to ceiling.

    ``centre`` is the plan centre, ``angle_deg`` the direction of the first side (rect),
    ``size_m`` the sides along ``angle_deg`` and across it (round: the diameter twice).
    """

    id: str
    shape: str  # "rect" | "round"
    centre: tuple[float, float]
    size_m: tuple[float, float]
    angle_deg: float
    floor_z: float
    height_m: float
    faces: tuple[str, ...]
    storey: str | None = None

    def matrix(self) -> np.ndarray:
        """4x4 world matrix: origin at the centre on the floor, X along the first side, Z up."""
        a = math.radians(self.angle_deg)
        m = np.eye(4)
        m[:3, 0] = [math.cos(a), math.sin(a), 0.0]
        m[:3, 1] = [-math.sin(a), math.cos(a), 0.0]
        m[:3, 3] = [self.centre[0], self.centre[1], self.floor_z]
        return m


def read_surfaces(doc: Mapping[str, Any], where: str = "detections") -> dict[str, Surface]:
    """The ``surfaces`` of a contract-4 document (or a contract-5 truth) by id.

    Checks what the BIM side needs beyond the contract: a known ``kind``, a frame that is
    not degenerate (a ceiling's normal vertical, a column face's horizontal) and, for a
    round face, a positive ``radius_m`` with a ``centre``. InputError naming the entry.
    """
    raw = doc.get("surfaces") or []
    if not isinstance(raw, list):
        raise InputError(f"{where}: surfaces", "expected a list")
    out: dict[str, Surface] = {}
    for i, d in enumerate(raw):
        at = f"{where}: surfaces[{i}]"
        if not isinstance(d, dict):
            raise InputError(at, "expected a JSON object")
        try:
            s = Surface.from_dict(d)
        except (KeyError, TypeError, ValueError, IndexError):
            raise InputError(at, "needs id, kind, origin, axis_u, axis_v, normal, width_m and height_m "
                                 "(and a radius_m with a centre [x, y] for a round column)") from None
        f = s.frame
        vectors = np.stack([f.origin, f.axis_u, f.axis_v, f.normal])
        if vectors.shape != (4, 3) or not np.isfinite(vectors).all():
            raise InputError(at, "frame vectors must be 3 finite numbers each")
        if s.kind not in ("ceiling", "column", "pendant"):
            raise InputError(f"{at}.kind", f"unknown surface kind '{s.kind}' (expected ceiling, column or pendant)")
        if s.id in out:
            raise InputError(f"{at}.id", f"duplicate surface id '{s.id}'")
        if s.kind == "ceiling" and abs(f.normal[2]) < 0.9:
            raise InputError(f"{at}.normal", "a ceiling's normal must be vertical")
        if s.kind in ("column", "pendant") and np.linalg.norm(f.normal[:2]) < 0.9:
            raise InputError(f"{at}.normal", f"a {'column face' if s.kind == 'column' else 'pendant'}'s normal must be horizontal")
        if np.linalg.norm(f.axis_u[:2]) < 0.9:
            raise InputError(f"{at}.axis_u", f"a {s.kind}'s axis_u must be horizontal")
        if s.radius_m is not None and not (s.radius_m > 0 and s.centre is not None):
            raise InputError(f"{at}.radius_m", "a round column needs radius_m > 0 and a centre [x, y]")
        out[s.id] = s
    return out


def column_of(surface: Surface) -> str:
    """The column a face belongs to: its ``column``, else its id without a compass suffix."""
    if surface.column:
        return surface.column
    head, _, tail = surface.id.rpartition("-")
    return head if head and tail in ("N", "E", "S", "W") else surface.id


def column_bodies(surfaces: Iterable[Surface]) -> list[ColumnBody]:
    """The columns of the column faces, in order of first appearance.

    A round face gives its circle. The faces of a rectangular column give its rectangle:
    the box around their bottom edges in the frame of the first face (one face alone: a
    square behind it).
    """
    groups: dict[str, list[Surface]] = {}
    for s in surfaces:
        if s.kind == "column":
            groups.setdefault(column_of(s), []).append(s)
    out: list[ColumnBody] = []
    for cid, faces in groups.items():
        floor_z = float(min(s.frame.origin[2] for s in faces))
        height = float(max(s.frame.origin[2] + s.frame.height_m for s in faces)) - floor_z
        storey = next((s.storey for s in faces if s.storey), None)
        ids = tuple(s.id for s in faces)
        round_face = next((s for s in faces if s.round), None)
        if round_face is not None:
            d = 2.0 * float(round_face.radius_m)
            out.append(ColumnBody(cid, "round", tuple(map(float, round_face.centre)), (d, d), 0.0, floor_z,
                                  height, ids, storey))
            continue
        first = faces[0].frame
        x = np.array([first.axis_u[0], first.axis_u[1], 0.0])
        x /= np.linalg.norm(x)
        y = np.cross(_UP, x)
        corners = np.array([p for s in faces for p in (s.frame.origin, s.frame.to_world(s.frame.width_m, 0.0))])
        a, b = corners[:, :2] @ x[:2], corners[:, :2] @ y[:2]
        a0, a1, b0, b1 = a.min(), a.max(), b.min(), b.max()
        if b1 - b0 < 1e-3:  # one face (or two opposite edges seen edge-on): a square behind it
            n = np.array(first.normal[:2]) / np.linalg.norm(first.normal[:2])
            inward = -float(n @ y[:2])
            b0, b1 = (b0 - (a1 - a0), b0) if inward < 0 else (b0, b0 + (a1 - a0))
        centre = (a0 + a1) / 2 * x[:2] + (b0 + b1) / 2 * y[:2]
        angle = math.degrees(math.atan2(x[1], x[0]))
        out.append(ColumnBody(cid, "rect", (float(centre[0]), float(centre[1])), (float(a1 - a0), float(b1 - b0)),
                              angle, floor_z, height, ids, storey))
    return out


def surface_coords(surface: Surface, points: np.ndarray) -> np.ndarray:
    """(N, 3) u, v, d of world points on ``surface`` (d along its normal; round faces: the
    arc length, the height and the distance out of the cylinder)."""
    return surface.drawing_frame().to_uvd(np.asarray(points, dtype=np.float64).reshape(-1, 3))


def surface_normal(surface: Surface, point: np.ndarray) -> np.ndarray:
    """The surface's normal at ``point`` (round faces: radial, outwards)."""
    if not surface.round:
        return np.asarray(surface.frame.normal, dtype=np.float64)
    d = np.array([point[0] - surface.centre[0], point[1] - surface.centre[1], 0.0])
    n = np.linalg.norm(d)
    return d / n if n > 1e-9 else np.asarray(surface.frame.normal, dtype=np.float64)


def tangent_frame(surface: Surface, point: np.ndarray) -> WallFrame:
    """The plane an object at ``point`` sits on: the surface's frame, or for a round face the
    tangent plane there (``axis_u`` counter-clockwise, ``axis_v`` up, origin at u = 0)."""
    if not surface.round:
        return surface.frame
    n = surface_normal(surface, point)
    u_axis = np.cross(_UP, n)
    uvd = surface_coords(surface, np.asarray(point)[None])[0]
    r = float(surface.radius_m)
    on = np.array([surface.centre[0], surface.centre[1], surface.frame.origin[2]]) + r * n
    return WallFrame(on - uvd[0] * u_axis, u_axis, _UP.copy(), n, surface.frame.width_m, surface.frame.height_m)


def drawing_frame(surface: Surface) -> WallFrame:
    """The frame a surface is drawn in like a wall (:meth:`sbsc_core.types.Surface.drawing_frame`)."""
    return surface.drawing_frame()


def object_matrix(surface: Surface, position: np.ndarray) -> np.ndarray:
    """World matrix of an object at ``position`` on ``surface``.

    A ceiling object: X = ``axis_u``, Y = ``axis_v``, Z = ``normal`` (down, into the room), so
    its body stands out along +Z. A column object: framed like an object on a wall, X along
    the face (the tangent on a round one), Z up, Y into the column.
    """
    m = np.eye(4)
    m[:3, 3] = np.asarray(position, dtype=np.float64)
    f = surface.frame
    if surface.kind == "ceiling":
        x = np.asarray(f.axis_u, float) / np.linalg.norm(f.axis_u)
        z = np.asarray(f.normal, float) / np.linalg.norm(f.normal)
        x = x - np.dot(x, z) * z
        x /= np.linalg.norm(x)
        m[:3, 0], m[:3, 1], m[:3, 2] = x, np.cross(z, x), z
        return m
    n = surface_normal(surface, position)
    x = np.cross(_UP, np.array([n[0], n[1], 0.0]))
    x /= np.linalg.norm(x)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, np.cross(_UP, x), _UP
    return m


def ceiling_matrix(surface: Surface) -> np.ndarray:
    """World matrix of a ceiling: origin at its frame's origin, X = ``axis_u``, Z = ``normal``."""
    return object_matrix(surface, surface.frame.origin)
