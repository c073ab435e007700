"""The PCD scan reader: ascii, binary and binary_compressed."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from .scan_source import (
    BLOCK_POINTS,
    RawBlock,
    ScanSource,
    _blocks_of,
    _float_colours_to_8,
    _records,
)
from .scan_text import _loadtxt

_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8",
              ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8"}


def _read_pcd(path: Path) -> ScanSource:
    """PCD (ascii, binary or binary_compressed) with x y z and a packed rgb / rgba field.

    ascii and binary are parsed here block by block (Open3D would read the whole file as
    float64 first, about 50 bytes a point). binary_compressed stores each field of all
    points as one LZF-compressed column, so no block can be decoded alone: that layout is
    read by Open3D whole.
    """
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    header: dict[str, list[str]] = {}
    pos = 0
    for raw in head.split(b"\n"):
        pos += len(raw) + 1
        line = raw.decode("ascii", errors="replace").strip()
        if not line or line.startswith("#"):
            continue
        tok = line.split()
        header[tok[0].upper()] = tok[1:]
        if tok[0].upper() == "DATA":
            break
    else:
        raise InputError(path, "not a PCD file (no DATA line)")
    fields = header.get("FIELDS", [])
    sizes, types = header.get("SIZE", []), header.get("TYPE", [])
    counts = header.get("COUNT", ["1"] * len(fields))
    try:
        n = int(header.get("POINTS", header.get("WIDTH", ["0"]))[0])
        spec = [(f, _PCD_TYPES[(t.upper(), int(s))], int(c))
                for f, s, t, c in zip(fields, sizes, types, counts, strict=True)]
    except (KeyError, ValueError, IndexError):
        raise InputError(path, "not a PCD file (bad FIELDS/SIZE/TYPE/COUNT header)") from None
    names = [f for f, _, _ in spec]
    if not {"x", "y", "z"} <= set(names):
        raise InputError(path, "not a PCD file (no x y z fields)")
    colour = next((c for c in ("rgb", "rgba") if c in names), None)
    if colour is None:
        raise InputError(path, "no colour (PCD has no rgb/rgba field)")
    if n <= 0:
        raise InputError(path, "no points")
    data = header["DATA"][0].lower() if header["DATA"] else ""
    if data == "binary_compressed":
        return _pcd_open3d(path, n)
    if data == "ascii":
        first = {}
        k = 0
        for f, _, c in spec:
            first[f] = k
            k += c
        usecols = [first["x"], first["y"], first["z"], first[colour]]

        def blocks() -> Iterator[RawBlock]:
            with open(path, encoding="latin-1") as fh:
                fh.seek(pos)
                done = 0
                while done < n:
                    m = min(BLOCK_POINTS, n - done)
                    block = _loadtxt(path, itertools.islice(fh, m), usecols, done + 1)
                    if len(block) < m:
                        raise InputError(path, f"truncated: header says {n} points, file has {done + len(block)}")
                    yield block[:, 0], block[:, 1], block[:, 2], _pcd_rgb(block[:, 3])
                    done += m

        return ScanSource(path, n, blocks, False)
    if data != "binary":
        raise InputError(path, f"unknown PCD DATA '{data}'")
    dtype = np.dtype([(f, "<" + t) if c == 1 else (f, "<" + t, (c,)) for f, t, c in spec])
    need = pos + n * dtype.itemsize
    size = path.stat().st_size
    if size < need:
        raise InputError(path, f"truncated: {n} points need {need} bytes, file has {size}")

    def blocks(start: int = 0, stop: int | None = None) -> Iterator[RawBlock]:
        for rec in _records(path, dtype, pos, n, start=start, stop=stop):
            yield rec["x"], rec["y"], rec["z"], _pcd_rgb(rec[colour])

    return ScanSource(path, n, blocks, False, seekable=True)


def _pcd_rgb(packed: np.ndarray) -> np.ndarray:
    """PCL's packed colour (float or integer field holding 0x00RRGGBB bits) to (n, 3) uint8."""
    a = np.asarray(packed)
    if a.dtype == np.float64:  # parsed from text: the integer or the float whose bits hold the colour
        if np.all(a == np.round(a)) and (a >= 0).all() and (a < 2**32).all():
            bits = a.astype(np.uint32)
        else:
            bits = a.astype(np.float32).view(np.uint32)
    elif a.dtype.kind == "f":
        bits = np.ascontiguousarray(a, np.float32).view(np.uint32)
    else:
        bits = a.astype(np.uint32)
    out = np.empty((len(bits), 3), np.uint8)
    out[:, 0] = (bits >> 16) & 255
    out[:, 1] = (bits >> 8) & 255
    out[:, 2] = bits & 255
    return out


def _pcd_open3d(path: Path, n: int) -> ScanSource:
    def blocks() -> Iterator[RawBlock]:
        import open3d as o3d

        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            pcd = o3d.io.read_point_cloud(str(path), format="pcd", remove_nan_points=False,
                                          remove_infinite_points=False)
        if not pcd.has_points():
            raise InputError(path, "no points (or not a readable PCD file)")
        if not pcd.has_colors():
            raise InputError(path, "no colour (PCD has no rgb/rgba field)")
        pts = np.asarray(pcd.points)
        cols = np.asarray(pcd.colors)
        for a, b in _blocks_of(len(pts)):
            yield pts[a:b, 0], pts[a:b, 1], pts[a:b, 2], _float_colours_to_8(cols[a:b])

    return ScanSource(path, n, blocks, False)
