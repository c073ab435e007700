"""The scan as the browser gets it: a voxel level of detail of the whole floor, recentred.

A floor scan holds tens of millions of points; the browser gets at most ``max_points``
(2 M by default): the cloud is voxel-downsampled with Open3D (one averaged point per
occupied voxel), the voxel side growing until the count fits. The result is kept beside
the project's files as ``viewer_lod_<key>.npz`` (key: the scan files, their sizes and
modification times, and ``max_points``), so a scene opens again without reading the scan.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import open3d as o3d

from sbsc_core.io.scans import read_scans

LOD_FORMAT = 1  # bump when the cached arrays change meaning
MAX_VOXEL_STEPS = 8


@dataclass
class ScanLod:
    """A downsampled floor: ``xyz`` (float32) relative to the world point ``centre``."""

    xyz: np.ndarray  # (N, 3) float32, world - centre
    rgb: np.ndarray  # (N, 3) uint8
    centre: np.ndarray  # (3,) float64 world coordinates of the scene origin
    voxel_m: float  # side of the voxels (0: not downsampled)
    source_points: int  # points of the scan before downsampling
    overview: ScanLod | None = None  # a coarser level (same centre), shown first

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


def _voxel_down(xyz: np.ndarray, rgb: np.ndarray, voxel_m: float) -> tuple[np.ndarray, np.ndarray]:
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz.astype(np.float64)))
    pcd.colors = o3d.utility.Vector3dVector(rgb.astype(np.float64) / 255.0)
    down = pcd.voxel_down_sample(voxel_m)
    out_xyz = np.asarray(down.points, dtype=np.float32)
    out_rgb = np.clip(np.asarray(down.colors) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return out_xyz, out_rgb


def downsample(xyz: np.ndarray, rgb: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Voxel-downsample (N, 3) points to at most ``max_points``; returns (xyz, rgb, voxel side).

    The first voxel side assumes the points cover about twice the floor's plan area
    (floor, ceiling and walls); each further step grows it by the square root of the
    remaining excess (a surface's voxel count falls with the square of the side) and
    downsamples the previous result, which is already much smaller than the scan.
    """
    n = len(xyz)
    if n <= max_points:
        return xyz.astype(np.float32), rgb.astype(np.uint8), 0.0
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    plan_area = max(float((hi[0] - lo[0]) * (hi[1] - lo[1])), 1.0)
    voxel = max(np.sqrt(2.0 * plan_area / max_points), 1e-3)
    out_xyz, out_rgb = _voxel_down(xyz, rgb, voxel)
    for _ in range(MAX_VOXEL_STEPS):
        if len(out_xyz) <= max_points:
            break
        voxel *= float(np.sqrt(len(out_xyz) / max_points)) * 1.05
        out_xyz, out_rgb = _voxel_down(out_xyz, out_rgb, voxel)
    if len(out_xyz) > max_points:  # pathological clouds: keep an even subset
        keep = np.linspace(0, len(out_xyz) - 1, max_points).astype(np.int64)
        out_xyz, out_rgb = out_xyz[keep], out_rgb[keep]
    return out_xyz, out_rgb, float(voxel)


def lod_cache_key(scans: Sequence[Path], max_points: int, overview_points: int = 0) -> str:
    h = hashlib.sha1(f"lod{LOD_FORMAT}:{max_points}:{overview_points}".encode())
    for p in sorted(Path(s).resolve() for s in scans):
        st = p.stat()
        h.update(f"|{p}:{st.st_size}:{st.st_mtime_ns}".encode())
    return h.hexdigest()[:16]


def _save_npz(path: Path, lod: ScanLod) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".npz", dir=path.parent)
    os.close(fd)
    try:
        ov = lod.overview
        extra = {} if ov is None else {"ov_xyz": ov.xyz, "ov_rgb": ov.rgb,
                                       "ov_voxel_m": np.float64(ov.voxel_m)}
        np.savez(tmp, xyz=lod.xyz, rgb=lod.rgb, centre=lod.centre,
                 voxel_m=np.float64(lod.voxel_m), source_points=np.int64(lod.source_points),
                 **extra)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _load_npz(path: Path) -> ScanLod | None:
    try:
        with np.load(path) as z:
            lod = ScanLod(z["xyz"], z["rgb"], z["centre"], float(z["voxel_m"]),
                          int(z["source_points"]))
            if "ov_xyz" in z:
                lod.overview = ScanLod(z["ov_xyz"], z["ov_rgb"], lod.centre,
                                       float(z["ov_voxel_m"]), lod.source_points)
            return lod
    except (OSError, KeyError, ValueError):
        return None  # unreadable cache: build it again


def scan_lod(scans: Sequence[Path], max_points: int = 2_000_000,
             cache_dir: Path | None = None, overview_points: int = 0) -> ScanLod:
    """The recentred level of detail of a floor's scan files, from the cache when it is there.

    The centre is the middle of the downsampled cloud's bounding box, so that float16
    coordinates in the browser stay precise. With ``overview_points`` the result also holds
    a coarser ``overview`` level, downsampled from the first.
    """
    scans = [Path(s) for s in scans]
    cache = None
    if cache_dir is not None:
        key = lod_cache_key(scans, max_points, overview_points)
        cache = Path(cache_dir) / f"viewer_lod_{key}.npz"
        if cache.exists():
            lod = _load_npz(cache)
            if lod is not None:
                return lod
    cloud = read_scans(scans)
    xyz, rgb, voxel = downsample(cloud.xyz, cloud.rgb, max_points)
    mid = (xyz.min(axis=0).astype(np.float64) + xyz.max(axis=0)) / 2.0
    centre = np.round(cloud.origin + mid, 3)
    rel = (xyz.astype(np.float64) + (cloud.origin - centre)).astype(np.float32)
    lod = ScanLod(rel, rgb, centre, voxel, len(cloud))
    if overview_points:
        o_xyz, o_rgb, o_voxel = downsample(rel, rgb, overview_points)
        lod.overview = ScanLod(o_xyz, o_rgb, centre, max(o_voxel, voxel), len(cloud))
    if cache is not None:
        _save_npz(cache, lod)
    return lod
