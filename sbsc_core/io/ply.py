"""A small binary PLY writer for coloured points (``x y z`` float32/float64, ``red green blue`` uchar,
optionally a ``scan_index`` ushort: the station of each point)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def write_ply(path: str | os.PathLike[str], xyz: np.ndarray, rgb: np.ndarray, *, double: bool = False,
              station: np.ndarray | None = None) -> None:
    """Write points and 8-bit colours as binary little-endian PLY, atomically.

    ``station`` (N,) gives each point's scanner station, written as a ``scan_index``
    ushort property (as merging tools keep it; :mod:`sbsc_core.io.scans` reads it back).
    """
    xyz = np.asarray(xyz)
    rgb = np.asarray(rgb, np.uint8)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or rgb.shape != xyz.shape:
        raise ValueError("xyz and rgb must both be (N, 3)")
    if station is not None:
        station = np.asarray(station)
        if station.shape != (len(xyz),):
            raise ValueError("station must be (N,)")
        if len(station) and (station.min() < 0 or station.max() > 65535):
            raise ValueError("station values must be in 0..65535")
    ft = "f8" if double else "f4"
    fields = [("x", "<" + ft), ("y", "<" + ft), ("z", "<" + ft), ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if station is not None:
        fields.append(("scan_index", "<u2"))
    rec = np.empty(len(xyz), dtype=fields)
    rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    rec["red"], rec["green"], rec["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    if station is not None:
        rec["scan_index"] = station
    t = "double" if double else "float"
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by sbsc\n"
        f"element vertex {len(xyz)}\nproperty {t} x\nproperty {t} y\nproperty {t} z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        + ("property ushort scan_index\n" if station is not None else "")
        + "end_header\n"
    )
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        rec.tofile(fh)
    os.replace(tmp, path)
