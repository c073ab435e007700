"""Stations of one synthetic room seen with small registration errors (shared by the registration tests)."""

from __future__ import annotations

import numpy as np


def _room(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` points on the inside of a 6 x 4 x 3 m room with a 0.6 x 0.4 x 0.1 m box on one wall."""
    faces = rng.integers(0, 7, n)
    a, b = rng.random(n), rng.random(n)
    p = np.empty((n, 3))
    for f, (fix, val, u, su, v, sv) in enumerate([
            (2, 0.0, 0, 6.0, 1, 4.0), (2, 3.0, 0, 6.0, 1, 4.0),  # floor, ceiling
            (0, 0.0, 1, 4.0, 2, 3.0), (0, 6.0, 1, 4.0, 2, 3.0),  # walls x = 0, 6
            (1, 0.0, 0, 6.0, 2, 3.0), (1, 4.0, 0, 6.0, 2, 3.0),  # walls y = 0, 4
            (1, 0.1, 0, 0.6, 2, 0.4)]):  # the front of a box on the wall y = 0
        m = faces == f
        p[m, fix] = val
        p[m, u] = a[m] * su + (2.0 if f == 6 else 0.0)
        p[m, v] = b[m] * sv + (1.0 if f == 6 else 0.0)
    return p


def _motion(rng: np.random.Generator, shift_m: float, turn_deg: float) -> np.ndarray:
    """A small rigid motion (4x4) about a point in the room."""
    w = np.radians(turn_deg) * rng.normal(size=3)
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    R = np.eye(3) + k + k @ k / 2  # close enough to a rotation for these angles; orthonormalised below
    u, _, vt = np.linalg.svd(R)
    T = np.eye(4)
    T[:3, :3] = u @ vt
    T[:3, 3] = rng.normal(0, shift_m, 3) + np.array([3.0, 2.0, 1.5]) - T[:3, :3] @ np.array([3.0, 2.0, 1.5])
    return T


def _stations(seed: int, n: int, errors: list[np.ndarray]) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for E in errors:
        p = _room(rng, n) + rng.normal(0, 0.001, (n, 3))  # 1 mm range noise
        out.append((p @ E[:3, :3].T + E[:3, 3]).astype(np.float32))
    return out


def _disagreement_mm(poses: list[np.ndarray], errors: list[np.ndarray]) -> float:
    """Largest difference over the room's corners between what the stations now say."""
    corners = np.array([[x, y, z] for x in (0, 6) for y in (0, 4) for z in (0, 3)], float)
    where = [corners @ (P @ E)[:3, :3].T + (P @ E)[:3, 3] for P, E in zip(poses, errors, strict=True)]
    return max(float(np.max(np.linalg.norm(w - where[0], axis=1))) for w in where) * 1000
