"""The PLY scan reader: ascii and binary, any vertex properties, a merged file's stations."""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from .scan_source import (
    BLOCK_POINTS,
    RawBlock,
    ScanSource,
    _float_colours_to_8,
    _records,
    station_field,
)
from .scan_text import _loadtxt

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


_COLOUR_NAMES = (("red", "green", "blue"), ("r", "g", "b"), ("diffuse_red", "diffuse_green", "diffuse_blue"))


_MAX_HEADER = 1 << 16


class _PlyElement:
    def __init__(self, name: str, count: int) -> None:
        self.name = name
        self.count = count
        self.props: list[tuple[str, str]] = []  # (name, numpy type)
        self.has_list = False


def _parse_ply_header(path: Path, fh) -> tuple[str, list[_PlyElement], int]:
    head = fh.read(_MAX_HEADER)
    if not head.startswith(b"ply"):
        raise InputError(path, "not a PLY file (no 'ply' magic)")
    m = re.search(rb"end_header[ \t]*\r?\n", head)
    if m is None:
        raise InputError(path, "not a PLY file (no end_header)")
    lines = head[:m.start()].decode("ascii", errors="replace").splitlines()
    fmt = None
    elements: list[_PlyElement] = []
    for line in lines[1:]:
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format" and len(tok) >= 2:
            fmt = tok[1]
        elif tok[0] == "element" and len(tok) == 3:
            try:
                count = int(tok[2])
            except ValueError:
                raise InputError(path, f"bad PLY header line '{line}'") from None
            if count < 0:
                raise InputError(path, f"bad PLY header line '{line}'")
            elements.append(_PlyElement(tok[1], count))
        elif tok[0] == "property" and elements:
            if len(tok) == 5 and tok[1] == "list":
                elements[-1].has_list = True
                elements[-1].props.append((tok[4], "list"))
            elif len(tok) == 3 and tok[1] in _PLY_TYPES:
                elements[-1].props.append((tok[2], _PLY_TYPES[tok[1]]))
            else:
                raise InputError(path, f"bad PLY header line '{line}'")
        else:
            raise InputError(path, f"bad PLY header line '{line}'")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise InputError(path, f"unknown PLY format '{fmt}'")
    return fmt, elements, m.end()


def _ply_columns(path: Path, vertex: _PlyElement) -> tuple[list[str], list[str]]:
    names = [p[0] for p in vertex.props]
    for axis in "xyz":
        if axis not in names:
            raise InputError(path, f"PLY vertex has no '{axis}' property")
    for triple in _COLOUR_NAMES:
        if all(c in names for c in triple):
            return ["x", "y", "z"], list(triple)
    raise InputError(path, "no colour (PLY vertex has no red/green/blue properties)")


def _ply_rgb(path: Path, rgb: np.ndarray, kind: str) -> np.ndarray:
    """PLY colour columns of numpy type ``kind`` to uint8 or uint16 (16-bit decided later)."""
    if kind == "u1":
        return rgb.astype(np.uint8, copy=False)
    if kind[0] == "f":
        return _float_colours_to_8(rgb)
    if kind in ("u2", "u4", "i2", "i4"):
        return np.clip(rgb, 0, 65535).astype(np.uint16)
    raise InputError(path, f"unsupported PLY colour type '{kind}'")


def _read_ply(path: Path) -> ScanSource:
    with open(path, "rb") as fh:
        fmt, elements, header_len = _parse_ply_header(path, fh)
    vi = next((i for i, e in enumerate(elements) if e.name == "vertex"), None)
    if vi is None:
        raise InputError(path, "PLY file has no vertex element")
    vertex = elements[vi]
    if vertex.count == 0:
        raise InputError(path, "no points")
    if vertex.has_list:
        raise InputError(path, "PLY vertex element with list properties is not supported")
    xyz_names, rgb_names = _ply_columns(path, vertex)
    rgb_kind = dict(vertex.props)[rgb_names[0]]
    if rgb_kind not in ("u1", "u2", "u4", "i2", "i4") and rgb_kind[0] != "f":
        raise InputError(path, f"unsupported PLY colour type '{rgb_kind}'")
    wide = rgb_kind != "u1" and rgb_kind[0] != "f"
    if fmt == "ascii":
        blocks = _ply_ascii_blocks(path, elements, vi=vi, header_len=header_len,
                                   xyz_names=xyz_names, rgb_names=rgb_names, rgb_kind=rgb_kind)
        return ScanSource(path, vertex.count, blocks, wide)
    blocks, records = _ply_binary_blocks(path, fmt, elements, vi=vi, header_len=header_len, xyz_names=xyz_names, rgb_names=rgb_names, rgb_kind=rgb_kind)
    field = station_field([n for n in dict(vertex.props) if n not in (*xyz_names, *rgb_names)])
    column = None
    if field is not None:
        def column(start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
            for rec in records(start, stop):
                yield rec[field]

    return ScanSource(path, vertex.count, blocks, wide, seekable=True, station_field=field, station_blocks=column)


def _ply_binary_blocks(path, fmt, elements, *, vi, header_len, xyz_names, rgb_names, rgb_kind
                       ) -> tuple[Callable[..., Iterator[RawBlock]], Callable[..., Iterator[np.ndarray]]]:
    endian = "<" if fmt == "binary_little_endian" else ">"
    offset = header_len
    for e in elements[:vi]:
        if e.has_list:
            raise InputError(path, f"PLY element '{e.name}' with list properties before the vertices")
        offset += e.count * sum(np.dtype(t).itemsize for _, t in e.props)
    vertex = elements[vi]
    dtype = np.dtype([(n, endian + t) for n, t in vertex.props])
    need = offset + vertex.count * dtype.itemsize
    size = path.stat().st_size
    if size < need:
        raise InputError(path, f"truncated: {vertex.count} vertices need {need} bytes, file has {size}")

    def records(start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        return _records(path, dtype, offset, vertex.count, start=start, stop=stop)

    def blocks(start: int = 0, stop: int | None = None) -> Iterator[RawBlock]:
        for rec in records(start, stop):
            rgb = np.stack([rec[c] for c in rgb_names], axis=1)
            yield rec[xyz_names[0]], rec[xyz_names[1]], rec[xyz_names[2]], _ply_rgb(path, rgb, rgb_kind)

    return blocks, records


def _ply_ascii_blocks(path, elements, *, vi, header_len, xyz_names, rgb_names, rgb_kind
                      ) -> Callable[[], Iterator[RawBlock]]:
    vertex = elements[vi]
    names = [p[0] for p in vertex.props]
    usecols = [names.index(n) for n in (*xyz_names, *rgb_names)]

    def blocks() -> Iterator[RawBlock]:
        with open(path, encoding="latin-1", newline=None) as fh:
            fh.seek(header_len)
            skip = sum(e.count for e in elements[:vi])
            for _ in itertools.islice(fh, skip):
                pass
            remaining = vertex.count
            first_line = 1 + skip
            while remaining > 0:
                n = min(remaining, BLOCK_POINTS)
                block = _loadtxt(path, itertools.islice(fh, n), usecols, first_line)
                if len(block) < n:
                    raise InputError(path, f"truncated: header says {vertex.count} vertices, "
                                           f"file has {vertex.count - remaining + len(block)}")
                yield block[:, 0], block[:, 1], block[:, 2], _ply_rgb(path, block[:, 3:6], rgb_kind)
                remaining -= n
                first_line += n

    return blocks
