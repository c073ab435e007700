"""Surfaces beyond walls (contract 4's ``surfaces``: ceilings, column faces and pendants) in the review app.

A surface is stored like a wall (``app.models.WallRow`` with a ``kind``) and framed like one:
``origin``, ``axis_u``, ``axis_v``, ``normal``, ``width_m``, ``height_m``. A ceiling's normal
points down into the room and its ``axis_v`` lies in the ceiling plane; a round column is one
surface unrolled around its axis (``radius_m``, ``centre``): ``u`` is the arc length counter-
clockwise from +x, ``v`` the height above the frame's origin.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

SURFACE_KINDS: tuple[str, ...] = ("ceiling", "column", "pendant")
FRAME_FIELDS: tuple[str, ...] = ("id", "kind", "origin", "axis_u", "axis_v", "normal", "width_m",
                                 "height_m", "storey")


def is_round(surface: Mapping[str, Any]) -> bool:
    """Whether a surface is a round column unrolled around its axis."""
    return surface.get("radius_m") is not None and surface.get("centre") is not None


def point_on(surface: Mapping[str, Any], u: float, v: float) -> list[float]:
    """The world point (u, v) of a wall or surface: on its plane, or on the cylinder."""
    o = [float(x) for x in surface["origin"]]
    if is_round(surface):
        r = float(surface["radius_m"])
        cx, cy = (float(c) for c in surface["centre"])
        a = u / r
        return [round(cx + r * math.cos(a), 5), round(cy + r * math.sin(a), 5), round(o[2] + v, 5)]
    return [round(oo + u * a + v * b, 5)
            for oo, a, b in zip(o, surface["axis_u"], surface["axis_v"], strict=True)]


def kind_of(surface: Mapping[str, Any]) -> str:
    """``wall``, ``ceiling``, ``column`` or ``pendant`` (a panel hanging from the ceiling)."""
    return str(surface.get("kind") or "wall")
