"""Coloured triangle meshes for the virtual building.

A triangle is either flat-coloured (``tri_texture == -1``, colour ``tri_colour``) or
textured: ``tri_texture`` indexes ``textures`` (H, W, 3 uint8 images) and ``tri_uv``
holds the texture coordinates of its three corners (u right, v *down*, both 0..1, so a
texture image is drawn as it is seen). ``tri_label`` is -1 for the building and the index
of the placed object otherwise, which lets tests and the scanner tell what a ray hit.
``tri_gloss`` (0 matte .. 1 mirror-like) drives the realistic scanner's specular
highlights and dropouts (:mod:`~sbsc_core.simulate.realism`); it is 0 unless set.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np


@dataclass
class ColouredMesh:
    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int64
    tri_colour: np.ndarray  # (T, 3) uint8
    tri_texture: np.ndarray  # (T,) int32, -1 = flat colour
    tri_uv: np.ndarray  # (T, 3, 2) float32
    textures: list[np.ndarray] = field(default_factory=list)
    tri_label: np.ndarray | None = None  # (T,) int32
    tri_gloss: np.ndarray | None = None  # (T,) float32, 0 = matte

    def __post_init__(self) -> None:
        if self.tri_label is None:
            self.tri_label = np.full(len(self.triangles), -1, dtype=np.int32)
        if self.tri_gloss is None:
            self.tri_gloss = np.zeros(len(self.triangles), dtype=np.float32)

    @property
    def n_triangles(self) -> int:
        return int(len(self.triangles))

    @staticmethod
    def empty() -> ColouredMesh:
        return ColouredMesh(
            np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 3), np.uint8),
            np.zeros(0, np.int32), np.zeros((0, 3, 2), np.float32),
        )

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> ColouredMesh:
        """Apply x' = R x + t to the vertices; everything else is shared."""
        v = self.vertices @ np.asarray(rotation, float).T + np.asarray(translation, float)
        return ColouredMesh(v, self.triangles, self.tri_colour, self.tri_texture, self.tri_uv,
                            self.textures, self.tri_label, self.tri_gloss)

    def labelled(self, label: int) -> ColouredMesh:
        return ColouredMesh(self.vertices, self.triangles, self.tri_colour, self.tri_texture,
                            self.tri_uv, self.textures,
                            np.full(len(self.triangles), label, dtype=np.int32), self.tri_gloss)

    def glossy(self, gloss: float) -> ColouredMesh:
        """The same mesh with every triangle's gloss set to ``gloss`` (0..1)."""
        return ColouredMesh(self.vertices, self.triangles, self.tri_colour, self.tri_texture,
                            self.tri_uv, self.textures, self.tri_label,
                            np.full(len(self.triangles), gloss, dtype=np.float32))


def merge(meshes: Sequence[ColouredMesh]) -> ColouredMesh:
    """Concatenate meshes, re-indexing vertices and textures."""
    meshes = [m for m in meshes if m.n_triangles]
    if not meshes:
        return ColouredMesh.empty()
    verts, tris, cols, texs, uvs, labels, textures, gloss = [], [], [], [], [], [], [], []
    v_off = 0
    for m in meshes:
        verts.append(m.vertices)
        tris.append(m.triangles + v_off)
        v_off += len(m.vertices)
        cols.append(m.tri_colour)
        t = m.tri_texture.copy()
        t[t >= 0] += len(textures)
        texs.append(t)
        textures.extend(m.textures)
        uvs.append(m.tri_uv)
        labels.append(m.tri_label)
        gloss.append(m.tri_gloss)
    return ColouredMesh(
        np.concatenate(verts), np.concatenate(tris), np.concatenate(cols),
        np.concatenate(texs).astype(np.int32), np.concatenate(uvs), textures,
        np.concatenate(labels).astype(np.int32), np.concatenate(gloss).astype(np.float32),
    )


def _flat(vertices: np.ndarray, triangles: np.ndarray, colour: Sequence[int]) -> ColouredMesh:
    n = len(triangles)
    return ColouredMesh(
        np.asarray(vertices, float), np.asarray(triangles, np.int64),
        np.tile(np.asarray(colour, np.uint8), (n, 1)), np.full(n, -1, np.int32),
        np.zeros((n, 3, 2), np.float32),
    )


def box(size: Sequence[float], colour: Sequence[int], centre: Sequence[float] = (0, 0, 0)) -> ColouredMesh:
    """An axis-aligned box of ``size`` (sx, sy, sz) centred at ``centre``, outward faces."""
    sx, sy, sz = (float(s) / 2 for s in size)
    c = np.asarray(centre, float)
    v = np.array([[x, y, z] for z in (-sz, sz) for y in (-sy, sy) for x in (-sx, sx)]) + c
    # vertex index = x + 2*y + 4*z (0/1 each)
    faces = [
        (0, 2, 3, 1), (4, 5, 7, 6),  # z- , z+
        (0, 1, 5, 4), (2, 6, 7, 3),  # y- , y+
        (0, 4, 6, 2), (1, 3, 7, 5),  # x- , x+
    ]
    tris = []
    for a, b, cc, d in faces:
        tris += [(a, b, cc), (a, cc, d)]
    return _flat(v, np.array(tris), colour)


def quad(corner: Sequence[float], edge_u: Sequence[float], edge_v: Sequence[float],
         colour: Sequence[int] = (255, 255, 255), texture: np.ndarray | None = None) -> ColouredMesh:
    """A parallelogram corner + s*edge_u + t*edge_v, s, t in [0, 1].

    Its front (normal = edge_u x edge_v) is the visible side. With ``texture`` the image is
    mapped so that its left edge is at s = 0 and its *top* row at t = 1 (edge_v points up).
    """
    p0 = np.asarray(corner, float)
    eu, ev = np.asarray(edge_u, float), np.asarray(edge_v, float)
    v = np.array([p0, p0 + eu, p0 + eu + ev, p0 + ev])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    m = _flat(v, tris, colour)
    if texture is not None:
        uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)  # image v runs downward
        m.tri_uv = uv[tris].astype(np.float32)
        m.tri_texture = np.zeros(2, np.int32)
        m.textures = [np.ascontiguousarray(texture[..., :3], dtype=np.uint8)]
    return m


def cylinder(radius: float, length: float, colour: Sequence[int], *, segments: int = 24,
             centre: Sequence[float] = (0, 0, 0), axis: int = 2, capped: bool = True) -> ColouredMesh:
    """A closed cylinder along coordinate ``axis`` (0 = x, 1 = y, 2 = z)."""
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([radius * np.cos(ang), radius * np.sin(ang)], axis=1)
    h = length / 2
    bottom = np.column_stack([ring, np.full(segments, -h)])
    top = np.column_stack([ring, np.full(segments, h)])
    v = np.vstack([bottom, top, [[0, 0, -h], [0, 0, h]]])
    tris = []
    for i in range(segments):
        j = (i + 1) % segments
        tris += [(i, j, segments + j), (i, segments + j, segments + i)]
        if capped:
            tris += [(2 * segments, j, i), (2 * segments + 1, segments + i, segments + j)]
    order = {0: [2, 0, 1], 1: [1, 2, 0], 2: [0, 1, 2]}[axis]
    v = v[:, order] + np.asarray(centre, float)
    return _flat(v, np.array(tris), colour)
