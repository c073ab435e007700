"""Each storey's points out of core, sampled as if the storey had been scanned alone (issue 12).

The first pass of :func:`~sbsc_core.pipeline.detect.detect_scans` keeps one regular sample of the
whole scan (at most ``2 * fit_max_points`` points): with several storeys each storey gets
a fraction of the density it gets when it is scanned alone, and its walls move by
centimetres. Once the storeys are known (their Z ranges, :func:`~sbsc_core.scene.segmentation.storey_bounds`),
:func:`storey_part` streams one part again (or its spill) and appends the points of each
storey's Z range to that storey's file in the scratch folder, keeping every ``step``-th
point over all files, ``step`` being the storey's own (what
:func:`~sbsc_core.imaging.partition.sample_step` gives for its point count). :func:`storey_cloud`
then reads one storey's files back, in the parts' order, so segmentation holds one storey
at a time (at most ``2 * fit_max_points`` points, the bound of the first pass).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..imaging.partition import ScanPart, part_chunks, spilled_chunks
from ..types import PointCloud

__all__ = ["storey_steps", "storey_part", "storey_cloud"]


def storey_steps(shares: Sequence[float], total_points: int, limit: int) -> list[int]:
    """Sample stride of each storey: its point count over the scan (its ``share`` of a regular
    sample of the scan's ``total_points``) over ``limit``, as a scan of its points alone."""
    return [max(1, math.ceil(share * total_points / limit)) for share in shares]


def _paths(scratch: Path, k: int, part: ScanPart) -> tuple[Path, Path]:
    return scratch / f"storey{k}-{part.key}.xyz", scratch / f"storey{k}-{part.key}.rgb"


def storey_part(part: ScanPart, origin: np.ndarray, bounds: Sequence[tuple[float, float]], steps: Sequence[int],
                scratch: str, *, points: int, spilled: bool) -> list[int]:
    """Stream one part again (or its spill) and append to each storey's files its points in
    the storey's Z range ``bounds[k]`` (relative to ``origin``) whose index over all files is a
    multiple of ``steps[k]``. Returns the number of points written per storey."""
    root = Path(scratch)
    chunks = spilled_chunks(root, part, origin, points) if spilled else part_chunks(part, origin)
    written = [0] * len(bounds)
    files = [tuple(open(p, "wb") for p in _paths(root, k, part)) for k in range(len(bounds))]
    try:
        for chunk in chunks:
            g0 = part.first + (chunk.start - part.start)  # global index of the chunk's first point
            z = chunk.xyz[:, 2]
            for k, ((lo, hi), step) in enumerate(zip(bounds, steps, strict=True)):
                idx = np.flatnonzero((z >= lo) & (z < hi))
                if step > 1:
                    idx = idx[(idx + g0) % step == 0]
                if len(idx):
                    chunk.xyz[idx].tofile(files[k][0])
                    chunk.rgb[idx].tofile(files[k][1])
                    written[k] += len(idx)
    finally:
        for pair in files:
            for fh in pair:
                fh.close()
    return written


def storey_cloud(scratch: Path | str, parts: Sequence[ScanPart], k: int, origin: np.ndarray,
                 *, sources: Sequence[str], limit: int) -> PointCloud:
    """Storey ``k``'s points written by :func:`storey_part`, in the parts' order, as one cloud
    (thinned regularly to at most ``limit`` points); its files are deleted."""
    paths = [_paths(Path(scratch), k, part) for part in parts]
    sizes = [p[0].stat().st_size // 12 for p in paths]
    n = sum(sizes)
    keep = max(1, math.ceil(n / limit))
    xyz = np.empty((-(-n // keep), 3), np.float32)
    rgb = np.empty((len(xyz), 3), np.uint8)
    fill = done = 0
    for (pxyz, prgb), m in zip(paths, sizes, strict=True):
        if m:
            a = (-done) % keep  # every keep-th point over the storey's points
            x = np.fromfile(pxyz, np.float32).reshape(m, 3)[a::keep]
            c = np.fromfile(prgb, np.uint8).reshape(m, 3)[a::keep]
            xyz[fill: fill + len(x)] = x
            rgb[fill: fill + len(x)] = c
            fill += len(x)
            done += m
        pxyz.unlink(missing_ok=True)
        prgb.unlink(missing_ok=True)
    return PointCloud(xyz=xyz[:fill], rgb=rgb[:fill], origin=np.asarray(origin, np.float64), sources=tuple(sources))
