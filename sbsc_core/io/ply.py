"""A small binary PLY writer for coloured points (``x y z`` float32/float64, ``red green blue`` uchar)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def write_ply(path: str | os.PathLike[str], xyz: np.ndarray, rgb: np.ndarray, *, double: bool = False) -> None:
    """Write points and 8-bit colours as binary little-endian PLY, atomically."""
    xyz = np.asarray(xyz)
    rgb = np.asarray(rgb, np.uint8)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or rgb.shape != xyz.shape:
        raise ValueError("xyz and rgb must both be (N, 3)")
    ft = "f8" if double else "f4"
    rec = np.empty(len(xyz), dtype=[("x", "<" + ft), ("y", "<" + ft), ("z", "<" + ft),
                                    ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    rec["red"], rec["green"], rec["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    t = "double" if double else "float"
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by sbsc\n"
        f"element vertex {len(xyz)}\nproperty {t} x\nproperty {t} y\nproperty {t} z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        rec.tofile(fh)
    os.replace(tmp, path)
