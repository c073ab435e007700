"""Read coloured scans (contract 1): PLY, E57, LAS/LAZ, PCD and text files.

Every reader streams its file in chunks into one :class:`~sbsc_core.types.PointCloud`:
float32 coordinates relative to a float64 ``origin`` and uint8 colours, so that a big
scan never sits in memory as more than one chunk of float64. A file that cannot be
used raises :class:`~sbsc_core.errors.InputError` naming the file and the reason; the
reader then returns nothing, so no half-read cloud is kept.
"""

from __future__ import annotations

import itertools
import os
import re
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import PointCloud

SCAN_EXTENSIONS: tuple[str, ...] = (".ply", ".e57", ".las", ".laz", ".pcd", ".xyz", ".pts", ".txt")
CHUNK_POINTS = 1 << 21  # points converted per step (bounds the float64 working set)
_ORIGIN_SAMPLE = 100_000  # points of the first chunk whose mean sets the origin
_READ_THREADS = 4  # at most this many threads convert chunks of a binary PLY


# --------------------------------------------------------------------------- collector


class _Collector:
    """Turns chunks of world coordinates and colours into one compact cloud.

    ``capacity`` (an upper bound of the point count) lets the output arrays be
    allocated once; without it chunks are kept and joined at the end. ``origin``
    fixes the recentring origin (several files sharing one); otherwise it is the
    rounded mean of the first chunk. Colours are kept as given (uint8, or uint16
    until :meth:`finish` decides whether they use 16 bits).
    """

    def __init__(self, path: Path, capacity: int | None = None, origin: np.ndarray | None = None,
                 rgb_dtype: type = np.uint8) -> None:
        self.path = path
        self.origin = None if origin is None else np.asarray(origin, np.float64)
        self.rgb_dtype = rgb_dtype
        self.count = 0
        self._xyz: np.ndarray | None = None
        self._rgb: np.ndarray | None = None
        self._chunks: list[tuple[np.ndarray, np.ndarray]] = []
        if capacity is not None:
            self._xyz = np.empty((capacity, 3), np.float32)
            self._rgb = np.empty((capacity, 3), rgb_dtype)

    def set_origin(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> None:
        """Fix the origin, unless given, as the rounded mean of the first points of these columns."""
        if self.origin is None:
            k = min(len(x), _ORIGIN_SAMPLE)
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: refused later
                mean = np.array([np.nanmean(np.asarray(c[:k], np.float64)) for c in (x, y, z)])
            self.origin = np.where(np.isfinite(mean), np.round(mean), 0.0) + 0.0

    def add(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, rgb: np.ndarray) -> None:
        """Append points given as three coordinate columns (any float type) and (n, 3) colours."""
        n = len(x)
        if n == 0:
            return
        self.set_origin(x, y, z)
        if self._xyz is not None:
            if self.count + n > len(self._xyz):
                raise InputError(self.path, "holds more points than its header says")
            bad = self.put(self.count, x, y, z, rgb)
        else:
            out = np.empty((n, 3), np.float32)
            self._chunks.append((out, np.asarray(rgb, self.rgb_dtype)))
            bad = _recentre(out, (x, y, z), self.origin)
        if bad is not None:
            raise InputError(self.path, f"non-finite coordinates (point {self.count + bad})")
        self.count += n

    def put(self, start: int, x: np.ndarray, y: np.ndarray, z: np.ndarray, rgb: np.ndarray) -> int | None:
        """Write points at ``start`` of the preallocated arrays (the origin must be set).

        Chunks that do not overlap may be put from several threads at once; ``count`` is
        then set by the caller. Returns the chunk's first non-finite point, or None.
        """
        n = len(x)
        self._rgb[start:start + n] = rgb
        return _recentre(self._xyz[start:start + n], (x, y, z), self.origin)

    def finish(self) -> PointCloud:
        if self.count == 0:
            raise InputError(self.path, "no points")
        if self._xyz is not None:
            xyz, rgb = self._xyz, self._rgb
            if self.count < len(xyz):  # shrink in place (E57 invalid points dropped)
                xyz.resize((self.count, 3), refcheck=False)
                rgb.resize((self.count, 3), refcheck=False)
        elif len(self._chunks) == 1:
            xyz, rgb = self._chunks[0]
        else:
            xyz = np.concatenate([c[0] for c in self._chunks])
            rgb = np.concatenate([c[1] for c in self._chunks])
        self._chunks = []
        if rgb.dtype != np.uint8:
            rgb = colours_16_to_8(rgb)
        return PointCloud(xyz=xyz, rgb=np.ascontiguousarray(rgb, np.uint8),
                          origin=self.origin.copy(), sources=(str(self.path),))


def _recentre(out: np.ndarray, columns: tuple[np.ndarray, ...], origin: np.ndarray) -> int | None:
    """``out[:, j] = columns[j] - origin[j]`` in float32; the first non-finite row or None."""
    with np.errstate(all="ignore"):
        for j, col in enumerate(columns):
            np.subtract(col, origin[j], out=out[:, j], casting="unsafe")
    finite = np.isfinite(out).all(axis=1)
    return None if finite.all() else int(np.argmin(finite))


def colours_16_to_8(rgb: np.ndarray) -> np.ndarray:
    """Integer colours that may use 16 bits to 8 bits.

    If any value exceeds 255 the colours use the full 16-bit range and are scaled by
    255/65535; otherwise they are 8-bit values stored in wider integers and kept.
    """
    rgb = np.asarray(rgb)
    if rgb.size and int(rgb.max()) > 255:
        return ((rgb.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    return rgb.astype(np.uint8)


def _float_colours_to_8(rgb: np.ndarray) -> np.ndarray:
    """Float colours in 0..1 to uint8 (clipped, rounded)."""
    with np.errstate(invalid="ignore"):
        return np.clip(np.rint(np.nan_to_num(np.asarray(rgb, np.float32)) * 255.0), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------- public API


def read_scan(path: Path | str, origin: np.ndarray | None = None) -> PointCloud:
    """Read one scan file of any format of contract 1 (chosen by the extension).

    ``origin`` forces the recentring origin (used by :func:`read_scans`).
    Raises :class:`InputError` when the file cannot be used.
    """
    path = Path(path)
    ext = path.suffix.lower()
    reader = _READERS.get(ext)
    if reader is None:
        raise InputError(path, f"unknown scan format '{ext or path.name}' "
                               f"(expected one of {', '.join(SCAN_EXTENSIONS)})")
    if not path.exists():
        raise InputError(path, "no such file")
    if not path.is_file():
        raise InputError(path, "not a file")
    if path.stat().st_size == 0:
        raise InputError(path, "empty file")
    try:
        return reader(path, origin)
    except InputError:
        raise
    except MemoryError:
        raise InputError(path, "too large to hold in memory") from None
    except (OSError, ValueError, RuntimeError) as exc:
        raise InputError(path, f"cannot read {ext[1:].upper()} file ({_reason(exc)})") from None


def read_scans(paths: Sequence[Path | str]) -> PointCloud:
    """Read several scan files (already registered) into one cloud with one common origin.

    The origin is the one chosen for the first file.
    """
    if not paths:
        raise InputError("scans", "no scan files given")
    clouds: list[PointCloud] = []
    origin = None
    for p in paths:
        cloud = read_scan(p, origin)
        origin = cloud.origin
        clouds.append(cloud)
    if len(clouds) == 1:
        return clouds[0]
    xyz = np.concatenate([c.xyz for c in clouds])
    rgb = np.concatenate([c.rgb for c in clouds])
    sources = tuple(s for c in clouds for s in c.sources)
    clouds.clear()
    return PointCloud(xyz=xyz, rgb=rgb, origin=origin, sources=sources)


# --------------------------------------------------------------------------- PLY

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


def _read_ply(path: Path, origin: np.ndarray | None) -> PointCloud:
    with open(path, "rb") as fh:
        fmt, elements, header_len = _parse_ply_header(path, fh)
    vi = next((i for i, e in enumerate(elements) if e.name == "vertex"), None)
    if vi is None:
        raise InputError(path, "PLY file has no vertex element")
    vertex = elements[vi]
    if vertex.count == 0:
        raise InputError(path, "no points")
    xyz_names, rgb_names = _ply_columns(path, vertex)
    kinds = dict(vertex.props)
    rgb_kind = kinds[rgb_names[0]]
    wide = rgb_kind not in ("u1",) and rgb_kind[0] != "f"
    col = _Collector(path, capacity=vertex.count, origin=origin, rgb_dtype=np.uint16 if wide else np.uint8)
    if fmt == "ascii":
        _read_ply_ascii(path, elements, vi, header_len, xyz_names, rgb_names, rgb_kind, col)
    else:
        _read_ply_binary(path, fmt, elements, vi, header_len, xyz_names, rgb_names, rgb_kind, col)
    return col.finish()


def _read_ply_binary(path, fmt, elements, vi, header_len, xyz_names, rgb_names, rgb_kind, col) -> None:
    endian = "<" if fmt == "binary_little_endian" else ">"
    offset = header_len
    for e in elements[:vi]:
        if e.has_list:
            raise InputError(path, f"PLY element '{e.name}' with list properties before the vertices")
        offset += e.count * sum(np.dtype(t).itemsize for _, t in e.props)
    vertex = elements[vi]
    if vertex.has_list:
        raise InputError(path, "PLY vertex element with list properties is not supported")
    dtype = np.dtype([(n, endian + t) for n, t in vertex.props])
    need = offset + vertex.count * dtype.itemsize
    size = path.stat().st_size
    if size < need:
        raise InputError(path, f"truncated: {vertex.count} vertices need {need} bytes, file has {size}")
    data = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=(vertex.count,))

    def convert(start: int) -> int | None:
        chunk = data[start:start + CHUNK_POINTS]
        rgb = np.stack([chunk[c] for c in rgb_names], axis=1)
        bad = col.put(start, chunk[xyz_names[0]], chunk[xyz_names[1]], chunk[xyz_names[2]],
                      _ply_rgb(path, rgb, rgb_kind))
        return None if bad is None else start + bad

    first = data[:CHUNK_POINTS]
    col.set_origin(first[xyz_names[0]], first[xyz_names[1]], first[xyz_names[2]])
    # numpy releases the GIL on these conversions: chunks go through a few threads at once
    with ThreadPoolExecutor(max_workers=min(_READ_THREADS, os.cpu_count() or 1)) as pool:
        bad = [b for b in pool.map(convert, range(0, vertex.count, CHUNK_POINTS)) if b is not None]
    if bad:
        raise InputError(path, f"non-finite coordinates (point {min(bad)})")
    col.count = vertex.count


def _read_ply_ascii(path, elements, vi, header_len, xyz_names, rgb_names, rgb_kind, col) -> None:
    vertex = elements[vi]
    if vertex.has_list:
        raise InputError(path, "PLY vertex element with list properties is not supported")
    names = [p[0] for p in vertex.props]
    usecols = [names.index(n) for n in (*xyz_names, *rgb_names)]
    with open(path, encoding="latin-1", newline=None) as fh:
        fh.seek(header_len)
        skip = sum(e.count for e in elements[:vi])
        for _ in itertools.islice(fh, skip):
            pass
        remaining = vertex.count
        first_line = 1 + skip
        while remaining > 0:
            n = min(remaining, CHUNK_POINTS)
            block = _loadtxt(path, itertools.islice(fh, n), usecols, first_line)
            if len(block) < n:
                raise InputError(path, f"truncated: header says {vertex.count} vertices, "
                                       f"file has {vertex.count - remaining + len(block)}")
            col.add(block[:, 0], block[:, 1], block[:, 2], _ply_rgb(path, block[:, 3:6], rgb_kind))
            remaining -= n
            first_line += n


# --------------------------------------------------------------------------- text


def _loadtxt(path: Path, lines, usecols, first_line: int, delimiter: str | None = None) -> np.ndarray:
    """Parse numeric text lines (numpy's C parser); errors name the file."""
    try:
        return np.loadtxt(lines, dtype=np.float64, usecols=usecols, ndmin=2, delimiter=delimiter,
                          comments="#")  # one marker keeps the C fast path
    except ValueError as exc:
        msg = str(exc).splitlines()[0] if str(exc) else "not numbers"
        raise InputError(path, f"bad numbers near line {first_line} ({msg})") from None


def _text_colours(path: Path, rgb: np.ndarray) -> np.ndarray:
    """Colours parsed from text: integers 0..255 (or 0..65535), or floats in 0..1."""
    if rgb.size == 0:
        return rgb.astype(np.uint16)
    if not np.isfinite(rgb).all() or rgb.min() < 0:
        raise InputError(path, "colours must be non-negative numbers")
    if rgb.max() <= 1.0 and np.any(rgb != np.round(rgb)):
        return _float_colours_to_8(rgb).astype(np.uint16)
    if rgb.max() > 65535:
        raise InputError(path, "colour values above 65535")
    return np.rint(rgb).astype(np.uint16)


def _snippet(text: str, limit: int = 30) -> str:
    """A short printable excerpt of a line for an error message."""
    clean = "".join(ch if ch.isprintable() and ord(ch) < 128 else "?" for ch in text.strip())
    return clean if len(clean) <= limit else clean[:limit] + "..."


def _reason(exc: BaseException, limit: int = 120) -> str:
    """A third-party exception as a short one-line reason."""
    text = " ".join(str(exc).split("****")[0].split()) or type(exc).__name__
    return text if len(text) <= limit else text[:limit] + "..."


def _next_data_line(fh) -> tuple[str | None, int]:
    """The next line that holds data (skipping blank and comment lines) and the lines read."""
    read = 0
    while True:
        line = fh.readline()
        if not line:
            return None, read
        read += 1
        s = line.strip()
        if s and not s.startswith(("#", "//")):
            return line, read


def _text_layout(path: Path, sample: str, pts: bool) -> tuple[str | None, list[int]]:
    """Delimiter and the columns x y z r g b of a text scan, from one data line."""
    delimiter = "," if "," in sample else (";" if ";" in sample else None)
    tokens = sample.split(delimiter)
    try:
        [float(t) for t in tokens]
    except ValueError:
        raise InputError(path, f"not a text point file (first data line is '{_snippet(sample)}')") from None
    ncols = len(tokens)
    if pts:  # x y z intensity r g b
        if ncols < 7:
            raise InputError(path, f"no colour ({ncols} columns; expected x y z intensity r g b)")
        return delimiter, [0, 1, 2, 4, 5, 6]
    if ncols < 6:
        raise InputError(path, f"no colour ({ncols} columns; expected x y z r g b)")
    # x y z r g b, or x y z intensity r g b as many tools write
    return delimiter, [0, 1, 2, 3, 4, 5] if ncols == 6 else [0, 1, 2, ncols - 3, ncols - 2, ncols - 1]


def _read_text_block(path: Path, lines: Iterator[str], usecols: list[int], delimiter: str | None,
                     col: _Collector, first_line: int, limit: int | None) -> int:
    """Parse up to ``limit`` (or all) of ``lines`` into ``col`` in chunks; returns lines read."""
    done = 0
    while limit is None or done < limit:
        n = CHUNK_POINTS if limit is None else min(CHUNK_POINTS, limit - done)
        chunk = list(itertools.islice(lines, n))
        if not chunk:
            break
        block = _loadtxt(path, chunk, usecols, first_line + done, delimiter)
        if block.size:
            col.add(block[:, 0], block[:, 1], block[:, 2], _text_colours(path, block[:, 3:6]))
        done += len(chunk)
        if len(chunk) < n:
            break
    return done


def _read_xyz(path: Path, origin: np.ndarray | None) -> PointCloud:
    """Text ``x y z r g b`` per line (spaces, commas or semicolons; ``#`` comments)."""
    col = _Collector(path, origin=origin, rgb_dtype=np.uint16)
    with open(path, encoding="latin-1") as fh:
        first, skipped = _next_data_line(fh)
        if first is None:
            raise InputError(path, "no points")
        delimiter, usecols = _text_layout(path, first, False)
        _read_text_block(path, itertools.chain([first], fh), usecols, delimiter,
                         col, skipped, None)
    return col.finish()


def _read_pts(path: Path, origin: np.ndarray | None) -> PointCloud:
    """Leica PTS: a point count line, then ``x y z intensity r g b`` lines; blocks may repeat."""
    col = _Collector(path, origin=origin, rgb_dtype=np.uint16)
    line_no = 0
    with open(path, encoding="latin-1") as fh:
        while True:
            head, read = _next_data_line(fh)
            line_no += read
            if head is None:
                break
            tok = head.split()
            if len(tok) != 1 or not tok[0].isdigit():
                raise InputError(path, f"line {line_no}: expected a point count, got '{_snippet(head)}'")
            count = int(tok[0])
            if count == 0:
                continue
            first, read = _next_data_line(fh)
            if first is None:
                raise InputError(path, f"truncated: line {line_no} announces {count} points, file has 0")
            delimiter, usecols = _text_layout(path, first, True)
            got = _read_text_block(path, itertools.chain([first], fh), usecols,
                                   delimiter, col, line_no + read, count)
            if got < count:
                raise InputError(path, f"truncated: line {line_no} announces {count} points, file has {got}")
            line_no += read - 1 + got
    return col.finish()


# --------------------------------------------------------------------------- LAS / LAZ


def _read_las(path: Path, origin: np.ndarray | None) -> PointCloud:
    import laspy

    try:
        with laspy.open(path) as reader:
            header = reader.header
            dims = set(header.point_format.dimension_names)
            if not {"red", "green", "blue"} <= dims:
                raise InputError(path, f"no colour (LAS point format {header.point_format.id} has no RGB)")
            total = int(header.point_count)
            if total == 0:
                raise InputError(path, "no points")
            if origin is None:
                origin = np.round((np.asarray(header.mins) + np.asarray(header.maxs)) / 2.0)
            col = _Collector(path, capacity=total, origin=origin, rgb_dtype=np.uint16)
            for pts in reader.chunk_iterator(CHUNK_POINTS):
                rgb = np.stack([np.asarray(pts.red), np.asarray(pts.green), np.asarray(pts.blue)], axis=1)
                col.add(np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z), rgb)
    except InputError:
        raise
    except laspy.errors.LaspyException as exc:
        raise InputError(path, f"cannot read LAS/LAZ file ({_reason(exc)})") from None
    if col.count < total:
        raise InputError(path, f"truncated: header says {total} points, file has {col.count}")
    return col.finish()


# --------------------------------------------------------------------------- E57


def _e57_colour_limits(header, proto, name: str) -> tuple[float, float]:
    """(min, max) of a colour channel: the scan's colorLimits, else the field's own range."""
    from pye57 import libe57
    from pye57.utils import get_node

    channel = name[len("color"):]  # Red / Green / Blue
    node = header.node
    if node.isDefined("colorLimits"):
        limits = node["colorLimits"]
        lo_key, hi_key = f"color{channel}Minimum", f"color{channel}Maximum"
        if limits.isDefined(lo_key) and limits.isDefined(hi_key):
            lo, hi = float(limits[lo_key].value()), float(limits[hi_key].value())
            if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
                return lo, hi
    field = get_node(proto, name)
    if isinstance(field, libe57.IntegerNode | libe57.ScaledIntegerNode):
        lo, hi = float(field.minimum()), float(field.maximum())
        if isinstance(field, libe57.ScaledIntegerNode):
            lo, hi = lo * field.scale() + field.offset(), hi * field.scale() + field.offset()
        if hi > lo:
            return lo, hi
    return 0.0, 1.0 if isinstance(field, libe57.FloatNode) else 255.0


def _read_e57(path: Path, origin: np.ndarray | None) -> PointCloud:
    import pye57
    from pye57 import libe57

    try:
        e57 = pye57.E57(str(path))
    except Exception as exc:  # libe57 raises its own exception types
        raise InputError(path, f"not a readable E57 file ({_reason(exc)})") from None
    try:
        n_scans = e57.scan_count
        if n_scans == 0:
            raise InputError(path, "no points (no scans in the file)")
        headers = [e57.get_header(i) for i in range(n_scans)]
        total = sum(int(h.point_count) for h in headers)
        if total == 0:
            raise InputError(path, "no points")
        col = _Collector(path, capacity=total, origin=origin)
        for i, h in enumerate(headers):
            if h.point_count:
                _read_e57_scan(path, e57, i, h, col, libe57)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(path, f"cannot read E57 file ({_reason(exc)})") from None
    finally:
        e57.close()
    return col.finish()


def _read_e57_scan(path: Path, e57, index: int, h, col: _Collector, libe57) -> None:
    fields = set(h.point_fields)
    colours = ("colorRed", "colorGreen", "colorBlue")
    if not set(colours) <= fields:
        raise InputError(path, f"no colour (scan {index} has no colorRed/Green/Blue)")
    if {"cartesianX", "cartesianY", "cartesianZ"} <= fields:
        coords, invalid = ("cartesianX", "cartesianY", "cartesianZ"), "cartesianInvalidState"
    elif {"sphericalRange", "sphericalAzimuth", "sphericalElevation"} <= fields:
        coords, invalid = ("sphericalRange", "sphericalAzimuth", "sphericalElevation"), "sphericalInvalidState"
    else:
        raise InputError(path, f"scan {index} has neither cartesian nor spherical coordinates")
    proto = libe57.StructureNode(h.node["points"].prototype())
    limits = [_e57_colour_limits(h, proto, c) for c in colours]
    rotation = h.rotation_matrix if h.has_pose() else np.eye(3)
    translation = np.asarray(h.translation, np.float64) if h.has_pose() else np.zeros(3)

    cap = int(min(CHUNK_POINTS, h.point_count))
    arrays: dict[str, np.ndarray] = {}
    buffers = libe57.VectorSourceDestBuffer()
    wanted = [*coords, *colours] + ([invalid] if invalid in fields else [])
    for name in wanted:
        arr = np.empty(cap, np.int8 if name == invalid else np.float64)
        arrays[name] = arr
        buffers.append(libe57.SourceDestBuffer(e57.image_file, name, arr, cap, True, True))
    reader = h.points.reader(buffers)
    try:
        while True:
            n = reader.read()
            if n == 0:
                break
            keep = slice(0, n) if invalid not in arrays else np.flatnonzero(arrays[invalid][:n] == 0)
            a, b, c = (arrays[k][keep] for k in coords)
            if invalid == "sphericalInvalidState":
                a, b, c = a * np.cos(c) * np.cos(b), a * np.cos(c) * np.sin(b), a * np.sin(c)
            local = np.stack([a, b, c], axis=1)
            del a, b, c
            world = local @ rotation.T + translation
            rgb = np.empty((len(world), 3), np.uint8)
            for j, (name, (lo, hi)) in enumerate(zip(colours, limits, strict=True)):
                v = (arrays[name][keep] - lo) * (255.0 / (hi - lo))
                rgb[:, j] = np.clip(np.rint(v), 0, 255)
            col.add(world[:, 0], world[:, 1], world[:, 2], rgb)
    finally:
        reader.close()


# --------------------------------------------------------------------------- PCD


def _read_pcd(path: Path, origin: np.ndarray | None) -> PointCloud:
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
    col = _Collector(path, capacity=len(pts), origin=origin)
    for s in range(0, len(pts), CHUNK_POINTS):
        p = pts[s:s + CHUNK_POINTS]
        col.add(p[:, 0], p[:, 1], p[:, 2], _float_colours_to_8(cols[s:s + CHUNK_POINTS]))
    del pcd, pts, cols
    return col.finish()


_READERS: dict[str, Callable[[Path, np.ndarray | None], PointCloud]] = {
    ".ply": _read_ply,
    ".e57": _read_e57,
    ".las": _read_las,
    ".laz": _read_las,
    ".pcd": _read_pcd,
    ".xyz": _read_xyz,
    ".txt": _read_xyz,
    ".pts": _read_pts,
}


def is_scan_file(path: str | os.PathLike[str]) -> bool:
    """True when the file's extension is one of the scan formats of contract 1."""
    return Path(path).suffix.lower() in SCAN_EXTENSIONS
