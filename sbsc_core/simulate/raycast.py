"""Ray casting against a coloured mesh with ``open3d.t.geometry.RaycastingScene``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from .mesh import ColouredMesh


@dataclass
class RayHits:
    t: np.ndarray  # (N,) float32 distance along the ray, inf = miss
    triangle: np.ndarray  # (N,) int64, -1 = miss
    rgb: np.ndarray  # (N, 3) uint8 surface colour (0 on a miss)
    label: np.ndarray  # (N,) int32 tri_label of the hit (-1 building or miss)
    normal: np.ndarray  # (N, 3) float32 unit normal of the hit triangle

    @property
    def hit(self) -> np.ndarray:
        return self.triangle >= 0


class MeshRaycaster:
    """Casts rays against a :class:`ColouredMesh` and returns distances and surface colours."""

    def __init__(self, mesh: ColouredMesh, chunk: int = 2_000_000) -> None:
        self.mesh = mesh
        self.chunk = int(chunk)
        self._scene = o3d.t.geometry.RaycastingScene()
        tmesh = o3d.t.geometry.TriangleMesh()
        tmesh.vertex.positions = o3d.core.Tensor(mesh.vertices.astype(np.float32))
        tmesh.triangle.indices = o3d.core.Tensor(mesh.triangles.astype(np.int32))
        self._scene.add_triangles(tmesh)

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        origins = np.asarray(origins, np.float32)
        directions = np.asarray(directions, np.float32)
        n = len(directions)
        if origins.shape == (3,):
            origins = np.broadcast_to(origins, (n, 3))
        t = np.empty(n, np.float32)
        tri = np.empty(n, np.int64)
        buv = np.empty((n, 2), np.float32)
        nrm = np.empty((n, 3), np.float32)
        for s in range(0, n, self.chunk):
            e = min(n, s + self.chunk)
            rays = np.concatenate([origins[s:e], directions[s:e]], axis=1)
            ans = self._scene.cast_rays(o3d.core.Tensor(np.ascontiguousarray(rays)))
            t[s:e] = ans["t_hit"].numpy()
            ids = ans["primitive_ids"].numpy().astype(np.int64)
            ids[ids == o3d.t.geometry.RaycastingScene.INVALID_ID] = -1
            ids[~np.isfinite(t[s:e])] = -1
            tri[s:e] = ids
            buv[s:e] = ans["primitive_uvs"].numpy()
            nrm[s:e] = ans["primitive_normals"].numpy()
        rgb = self.shade(tri, buv)
        label = np.full(n, -1, np.int32)
        hit = tri >= 0
        label[hit] = self.mesh.tri_label[tri[hit]]
        return RayHits(t, tri, rgb, label, nrm)

    def shade(self, tri: np.ndarray, bary_uv: np.ndarray) -> np.ndarray:
        """Surface colour at hits given triangle ids and open3d's barycentric (u, v)."""
        m = self.mesh
        rgb = np.zeros((len(tri), 3), np.uint8)
        hit = tri >= 0
        rgb[hit] = m.tri_colour[tri[hit]]
        tex_of = np.full(len(tri), -1, np.int32)
        tex_of[hit] = m.tri_texture[tri[hit]]
        for k, image in enumerate(m.textures):
            sel = np.nonzero(tex_of == k)[0]
            if not len(sel):
                continue
            uvs = m.tri_uv[tri[sel]]  # (n, 3, 2)
            b1, b2 = bary_uv[sel, 0:1], bary_uv[sel, 1:2]
            uv = (1 - b1 - b2) * uvs[:, 0] + b1 * uvs[:, 1] + b2 * uvs[:, 2]
            h, w = image.shape[:2]
            x = np.clip((uv[:, 0] * w).astype(np.int64), 0, w - 1)
            y = np.clip((uv[:, 1] * h).astype(np.int64), 0, h - 1)
            rgb[sel] = image[y, x, :3]
        return rgb
