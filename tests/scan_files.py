"""Helpers shared by several test modules: scan files written byte by byte."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _write_ply_struct(path: Path, rec: np.ndarray, fmt: str, extra_elements: str = "",
                      tail: bytes = b"") -> None:
    """Write any structured array as the vertex element of a PLY (ascii or binary)."""
    names = {"f4": "float", "f8": "double", "u1": "uchar", "u2": "ushort", "i2": "short", "i4": "int", "u4": "uint"}
    props = "".join(f"property {names[rec.dtype[n].str[1:]]} {n}\n" for n in rec.dtype.names)
    header = f"ply\nformat {fmt} 1.0\ncomment test\nelement vertex {len(rec)}\n{props}{extra_elements}end_header\n"
    with open(path, "wb") as fh:
        fh.write(header.encode())
        if fmt == "ascii":
            for r in rec:
                fh.write((" ".join(repr(float(v)) if isinstance(v, np.floating) else str(v) for v in r) + "\n").encode())
        else:
            endian = "<" if fmt == "binary_little_endian" else ">"
            rec.astype(rec.dtype.newbyteorder(endian)).tofile(fh)
        fh.write(tail)
