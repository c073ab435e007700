"""Read coloured scans (contract 1): PLY, E57, LAS/LAZ, PCD and text files, in chunks.

Readers are kept in a registry by extension (as PDAL keeps its readers): each one opens
its file, checks the header and describes it as a :class:`ScanSource` - the point count
where the header has one, and a generator of raw blocks (world coordinates in whatever
float type the file holds, colours as stored). :func:`iter_scan` turns the blocks into
:class:`ScanChunk` s of at most ``chunk_points`` points: float32 coordinates relative to a
float64 ``origin`` and uint8 colours. A block is at most ``BLOCK_POINTS`` points, so the
float64 and parsing temporaries of a chunk in flight stay a few bytes per point of the
chunk, whatever the file's size. :func:`read_scan` / :func:`read_scans` collect the
chunks into one :class:`~sbsc_core.types.PointCloud` for callers that want the whole
cloud; the detection pipeline streams instead (:mod:`sbsc_core.partition`).

A file that cannot be used raises :class:`~sbsc_core.errors.InputError` naming the file
and the reason, when it is opened or at the chunk where the problem is met; a caller that
collects chunks then keeps nothing.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import re
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import PointCloud

CHUNK_POINTS = 1 << 21  # points per chunk handed to the caller
BLOCK_POINTS = 1 << 16  # points a reader converts at once (bounds float64 / parsing temporaries)
ORIGIN_SAMPLE = 100_000  # points of the first block whose median sets the origin

RawBlock = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""x, y, z (world coordinates, any float type) and (n, 3) colours (uint8, or uint16 when wide)."""

STATION_FIELDS: tuple[str, ...] = ("original_cloud_index", "scan_index", "scan_id", "point_source_id", "station")
"""Per-point properties naming a merged file's station (CloudCompare's "Original cloud index", LAS's
point_source_id, ...), in order of preference, as :func:`station_field` compares them."""


@dataclass
class ScanSource:
    """One scan file as its reader describes it.

    ``count`` is the number of points the header announces (E57: before invalid points are
    dropped, so an upper bound), None for text files. ``blocks()`` yields the raw blocks
    from the start of the file each time it is called; a ``seekable`` source (binary PLY and
    PCD: fixed-size records) also takes ``blocks(start, stop)``: the points ``start:stop``
    only, so a file can be split between workers. ``rgb_wide`` says the colours are
    stored in more than 8 bits: they are 8-bit values in wider integers, or use the full
    16-bit range when the first block holds a value above 255 (decided once per file).

    A merged file that keeps which station each point came from (a binary PLY property
    named as in :data:`STATION_FIELDS`, see :func:`station_field`) gives the property's
    name as ``station_field`` and ``station_blocks(start, stop)``: the property's values
    (1-D, any numeric type) for the points ``start:stop``, block by block.
    """

    path: Path
    count: int | None
    blocks: Callable[..., Iterator[RawBlock]]
    rgb_wide: bool = False
    seekable: bool = False
    scans: tuple[int, ...] = ()  # a file of several scans (E57): each one's point count ...
    scan_blocks: Callable[[int], Iterator[RawBlock]] | None = None  # ... and the raw blocks of scan k alone
    station_field: str | None = None  # a merged file's per-point station property (its name in the file) ...
    station_blocks: Callable[..., Iterator[np.ndarray]] | None = None  # ... its values, blocks of points start:stop


@dataclass
class ScanChunk:
    """Consecutive points of one file: float32 ``xyz`` relative to ``origin``, uint8 ``rgb``."""

    xyz: np.ndarray  # (n, 3) float32
    rgb: np.ndarray  # (n, 3) uint8
    origin: np.ndarray  # (3,) float64
    start: int  # index of the first point in the file

    def __len__(self) -> int:
        return len(self.xyz)


ScanReader = Callable[[Path], ScanSource]
PointCount = Callable[[Path], int]
"""A format's upload check: the point count from the header, checked against the file's size
(see :mod:`sbsc_core.io.scan_check`)."""
_READERS: dict[str, ScanReader] = {}
_COUNTS: dict[str, PointCount] = {}


def register_reader(extension: str, reader: ScanReader, *, count: PointCount | None = None) -> None:
    """Make ``reader`` the reader of files ending in ``extension`` (e.g. ``".ply"``), and ``count``
    its upload check (the review app refuses a format without one)."""
    _READERS[extension.lower()] = reader
    if count is not None:
        _COUNTS[extension.lower()] = count


def point_count_check(extension: str) -> PointCount | None:
    """The upload check registered for ``extension``, None when there is none."""
    return _COUNTS.get(extension.lower())


def scan_readers() -> dict[str, ScanReader]:
    """The registered readers by extension."""
    return dict(_READERS)


def scan_extensions() -> tuple[str, ...]:
    """The scan formats of contract 1: every extension a reader is registered for (``".ply"``, ...).

    The one list of them: the CLI's help, the review app's upload check and its upload page
    take it from here.
    """
    return tuple(_READERS)


# --------------------------------------------------------------------------- public API


@contextlib.contextmanager
def _guard(path: Path):
    """Turn a reader's failure into one InputError naming the file."""
    ext = path.suffix.lower()
    try:
        yield
    except InputError:
        raise
    except MemoryError:
        raise InputError(path, "too large to hold in memory") from None
    except Exception as exc:  # laspy, libE57 and numpy raise their own types
        raise InputError(path, f"cannot read {ext[1:].upper()} file ({_reason(exc)})") from None


def open_scan(path: Path | str) -> ScanSource:
    """Open one scan file of any format of contract 1 (chosen by the extension) and read its header.

    Parameters
    ----------
    path
        A file whose extension is one of :func:`scan_extensions`.

    Returns
    -------
    ScanSource
        The header's point count and the raw blocks of the file, not yet read.

    Raises
    ------
    InputError
        When the file cannot be used (unknown format, missing, unreadable header).
    """
    path = Path(path)
    ext = path.suffix.lower()
    reader = _READERS.get(ext)
    if reader is None:
        raise InputError(path, f"unknown scan format '{ext or path.name}' "
                               f"(expected one of {', '.join(scan_extensions())})")
    if not path.exists():
        raise InputError(path, "no such file")
    if not path.is_file():
        raise InputError(path, "not a file")
    if path.stat().st_size == 0:
        raise InputError(path, "empty file")
    with _guard(path):
        return reader(path)


def scan_point_count(path: Path | str) -> int | None:
    """The point count in the file's header (None for text files), without reading the points."""
    return open_scan(path).count


def iter_scan(path: Path | str | ScanSource, origin: np.ndarray | None = None,
              chunk_points: int = CHUNK_POINTS, start: int = 0, stop: int | None = None,
              scan: int | None = None) -> Iterator[ScanChunk]:
    """The points of one scan file as chunks of at most ``chunk_points`` points.

    ``start`` / ``stop`` select a range of points of a ``seekable`` source (see :class:`ScanSource`);
    ``scan`` the points of one scan of a file of several (E57; ``start`` then counts from the scan's first point).

    ``origin`` fixes the recentring origin (several files sharing one); without it the
    origin is the rounded median of the first points of the file (a few stray points do not
    move it).

    Parameters
    ----------
    path
        A scan file, or a source :func:`open_scan` already opened.
    origin
        The recentring origin (float64, 3); None: chosen from the file's first points.
    chunk_points
        At most this many points a chunk.
    start, stop
        Points ``start:stop`` only (a ``seekable`` source).
    scan
        Only the points of scan ``scan`` of a file of several (E57).

    Returns
    -------
    Iterator[ScanChunk]
        float32 ``xyz`` relative to the origin and uint8 ``rgb``, in file order.

    Raises
    ------
    InputError
        Naming the file, at the chunk where a problem is met.
    """
    src = path if isinstance(path, ScanSource) else open_scan(path)
    path = src.path
    origin = None if origin is None else np.asarray(origin, np.float64)
    ranged = start != 0 or stop is not None
    if ranged and not src.seekable:
        raise ValueError(f"{path}: a range of points can only be read from a format of fixed-size records")
    if scan is not None and (src.scan_blocks is None or not 0 <= scan < len(src.scans)):
        raise ValueError(f"{path}: has no scan {scan}")
    blocks = src.scan_blocks(scan) if scan is not None else src.blocks(start, stop) if ranged else src.blocks()
    done = start
    with _guard(path):
        xyz = rgb = None
        fill = 0
        wide: bool | None = None
        for x, y, z, colours in blocks:
            n = len(x)
            if n == 0:
                continue
            if origin is None:
                origin = _median_origin(x, y, z)
            if wide is None:
                wide = bool(src.rgb_wide and colours.size and int(colours.max()) > 255)
            pos = 0
            while pos < n:
                if xyz is None:
                    xyz = np.empty((chunk_points, 3), np.float32)
                    rgb = np.empty((chunk_points, 3), np.uint8)
                k = min(n - pos, chunk_points - fill)
                part = slice(pos, pos + k)
                bad = _recentre(xyz[fill:fill + k], (x[part], y[part], z[part]), origin)
                if bad is not None:
                    raise InputError(path, f"non-finite coordinates (point {done + fill + bad})")
                rgb[fill:fill + k] = _to_8_bit(colours[part], wide)
                fill += k
                pos += k
                if fill == chunk_points:
                    yield ScanChunk(xyz, rgb, origin, done)
                    done += fill
                    xyz = rgb = None
                    fill = 0
        if fill:
            yield ScanChunk(xyz[:fill], rgb[:fill], origin, done)
            done += fill
    if done == start and not ranged and scan is None:
        raise InputError(path, "no points")


def sample_scan(src: ScanSource, origin: np.ndarray, every: int, first: int = 0, start: int = 0,
                stop: int | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """A regular sample of points ``start:stop`` of a ``seekable`` source, and the points read.

    Keeps the points whose index plus ``first - start`` is a multiple of ``every`` (so
    ``first`` is the index of point ``start`` among several files) and converts only those:
    float32 ``xyz`` relative to ``origin`` and uint8 ``rgb``. The other points are not
    checked here (the pass that reads them all is).
    """
    if not src.seekable:
        raise ValueError(f"{src.path}: a sample without reading every point needs a format of fixed-size records")
    origin = np.asarray(origin, np.float64)
    xs, cs = [], []
    pos = start
    wide: bool | None = None
    with _guard(src.path):
        for x, y, z, colours in src.blocks(start, stop):
            n = len(x)
            if wide is None:
                wide = bool(src.rgb_wide and colours.size and int(colours.max()) > 255)
            i0 = (-(first + pos - start)) % every
            out = np.empty((len(range(i0, n, every)), 3), np.float32)
            bad = _recentre(out, (x[i0::every], y[i0::every], z[i0::every]), origin)
            if bad is not None:
                raise InputError(src.path, f"non-finite coordinates (point {pos + i0 + bad * every})")
            xs.append(out)
            cs.append(_to_8_bit(colours[i0::every], wide))
            pos += n
    xyz = np.concatenate(xs) if xs else np.zeros((0, 3), np.float32)
    rgb = np.concatenate(cs) if cs else np.zeros((0, 3), np.uint8)
    return xyz, rgb, pos - start


def read_scan(path: Path | str, origin: np.ndarray | None = None) -> PointCloud:
    """Read one scan file whole (see :func:`iter_scan`).

    Parameters
    ----------
    path
        A scan file of contract 1.
    origin
        The recentring origin; None: chosen from the file's first points.

    Returns
    -------
    PointCloud
        Every point: float32 ``xyz`` relative to ``origin``, uint8 ``rgb``.

    Raises
    ------
    InputError
        When the file cannot be used.
    """
    return read_scans([path], origin)


def read_scans(paths: Sequence[Path | str], origin: np.ndarray | None = None) -> PointCloud:
    """Read several scan files (already registered) into one cloud with one common origin.

    The output arrays are allocated once when every header gives its point count.

    Parameters
    ----------
    paths
        Scan files of one building, in one coordinate frame.
    origin
        The common recentring origin; None: the one chosen for the first file.

    Returns
    -------
    PointCloud
        The points of every file, one after the other; ``sources`` names the files.
    """
    if not paths:
        raise InputError("scans", "no scan files given")
    sources = [open_scan(p) for p in paths]
    counts = [s.count for s in sources]
    known = all(c is not None for c in counts)
    total = sum(counts) if known else 0  # type: ignore[arg-type]
    xyz = np.empty((total, 3), np.float32) if known else None
    rgb = np.empty((total, 3), np.uint8) if known else None
    parts: list[ScanChunk] = []
    n = 0
    for src in sources:
        for chunk in iter_scan(src, origin):
            origin = chunk.origin
            if xyz is not None:
                if n + len(chunk) > total:
                    raise InputError(src.path, "holds more points than its header says")
                xyz[n:n + len(chunk)] = chunk.xyz
                rgb[n:n + len(chunk)] = chunk.rgb
            else:
                parts.append(chunk)
            n += len(chunk)
    if xyz is None:
        xyz = np.concatenate([c.xyz for c in parts]) if len(parts) > 1 else parts[0].xyz
        rgb = np.concatenate([c.rgb for c in parts]) if len(parts) > 1 else parts[0].rgb
        parts.clear()
    elif n < total:  # E57 invalid points dropped: shrink in place
        xyz.resize((n, 3), refcheck=False)
        rgb.resize((n, 3), refcheck=False)
    return PointCloud(xyz=xyz, rgb=rgb, origin=np.asarray(origin, np.float64).copy(),
                      sources=tuple(str(s.path) for s in sources))


def is_scan_file(path: str | os.PathLike[str]) -> bool:
    """True when the file's extension is one of the scan formats of contract 1."""
    return Path(path).suffix.lower() in _READERS


# --------------------------------------------------------------------------- conversions


def _median_origin(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The rounded median of the first points (whole metres; 0 where not finite)."""
    k = min(len(x), ORIGIN_SAMPLE)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: refused later
        med = np.array([np.nanmedian(np.asarray(c[:k], np.float64)) for c in (x, y, z)])
    return np.where(np.isfinite(med), np.round(med), 0.0) + 0.0


def _recentre(out: np.ndarray, columns: tuple[np.ndarray, ...], origin: np.ndarray) -> int | None:
    """``out[:, j] = columns[j] - origin[j]`` in float32; the first non-finite row or None.

    The subtraction runs in float64 through numpy's buffered casting: no float64 copy of
    a column is made.
    """
    with np.errstate(all="ignore"):
        for j, col in enumerate(columns):
            np.subtract(col, origin[j], out=out[:, j], casting="unsafe")
    if np.isfinite(out.reshape(-1)).all():  # one flat pass; the row only when needed
        return None
    return int(np.argmin(np.isfinite(out).all(axis=1)))


def _to_8_bit(rgb: np.ndarray, wide: bool) -> np.ndarray:
    """Colours of a block to uint8: full 16-bit range scaled down when ``wide``, else kept."""
    if rgb.dtype == np.uint8:
        return rgb
    if wide:
        return ((rgb.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    return np.minimum(rgb, 255).astype(np.uint8)


def colours_16_to_8(rgb: np.ndarray) -> np.ndarray:
    """Integer colours that may use 16 bits to 8 bits.

    If any value exceeds 255 the colours use the full 16-bit range and are scaled by
    255/65535; otherwise they are 8-bit values stored in wider integers and kept.
    """
    rgb = np.asarray(rgb)
    return _to_8_bit(rgb, bool(rgb.size and int(rgb.max()) > 255))


def _float_colours_to_8(rgb: np.ndarray) -> np.ndarray:
    """Float colours in 0..1 to uint8 (clipped, rounded)."""
    with np.errstate(invalid="ignore"):
        return np.clip(np.rint(np.nan_to_num(np.asarray(rgb, np.float32)) * 255.0), 0, 255).astype(np.uint8)


def _records(path: Path, dtype: np.dtype, offset: int, n: int, start: int, stop: int | None
             ) -> Iterator[np.ndarray]:
    """Blocks of fixed-size binary records ``start:stop`` of ``n`` read into small buffers
    (not memory-mapped: no file pages stay mapped in the reading process)."""
    with open(path, "rb") as fh:
        for a, b in _blocks_of(n, start, stop):
            fh.seek(offset + a * dtype.itemsize)
            rec = np.fromfile(fh, dtype=dtype, count=b - a)
            if len(rec) < b - a:
                raise InputError(path, f"truncated: {n} points announced, file ends at point {a + len(rec)}")
            yield rec


def _blocks_of(n: int, start: int = 0, stop: int | None = None) -> Iterator[tuple[int, int]]:
    """(a, b) ranges of at most BLOCK_POINTS covering ``start:stop`` of ``n`` points."""
    stop = n if stop is None else min(n, stop)
    for a in range(start, stop, BLOCK_POINTS):
        yield a, min(stop, a + BLOCK_POINTS)


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




def _field_key(name: str) -> str:
    """A property name as :data:`STATION_FIELDS` holds it: lower case, spaces / hyphens as
    underscores, without CloudCompare's ``scalar_`` prefix."""
    key = re.sub(r"[\s\-]+", "_", name.strip().lower())
    return key[len("scalar_"):] if key.startswith("scalar_") else key


def station_field(names: Sequence[str]) -> str | None:
    """The property among ``names`` that gives each point's station (see :data:`STATION_FIELDS`), or None.

    Names are compared case-insensitively after dropping a ``scalar_`` prefix, spaces and
    underscores alike (``scalar_Original_cloud_index``, ``Scan ID``, ``point_source_id``).
    """
    keys = {_field_key(n): n for n in reversed(list(names))}  # the first of equal keys wins
    return next((keys[k] for k in STATION_FIELDS if k in keys), None)


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
        blocks = _ply_ascii_blocks(path, elements, vi, header_len, xyz_names, rgb_names, rgb_kind)
        return ScanSource(path, vertex.count, blocks, wide)
    blocks, records = _ply_binary_blocks(path, fmt, elements, vi, header_len, xyz_names, rgb_names, rgb_kind)
    field = station_field([n for n in dict(vertex.props) if n not in (*xyz_names, *rgb_names)])
    column = None
    if field is not None:
        def column(start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
            for rec in records(start, stop):
                yield rec[field]

    return ScanSource(path, vertex.count, blocks, wide, seekable=True, station_field=field, station_blocks=column)


def _ply_binary_blocks(path, fmt, elements, vi, header_len, xyz_names, rgb_names, rgb_kind
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
        return _records(path, dtype, offset, vertex.count, start, stop)

    def blocks(start: int = 0, stop: int | None = None) -> Iterator[RawBlock]:
        for rec in records(start, stop):
            rgb = np.stack([rec[c] for c in rgb_names], axis=1)
            yield rec[xyz_names[0]], rec[xyz_names[1]], rec[xyz_names[2]], _ply_rgb(path, rgb, rgb_kind)

    return blocks, records


def _ply_ascii_blocks(path, elements, vi, header_len, xyz_names, rgb_names, rgb_kind
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


def _text_blocks(path: Path, lines: Iterator[str], usecols: list[int], delimiter: str | None,
                 first_line: int, limit: int | None, counter: list[int]) -> Iterator[RawBlock]:
    """Up to ``limit`` (or all) of ``lines`` parsed in blocks; ``counter[0]`` counts the lines read."""
    done = 0
    while limit is None or done < limit:
        n = BLOCK_POINTS if limit is None else min(BLOCK_POINTS, limit - done)
        chunk = list(itertools.islice(lines, n))
        if not chunk:
            break
        block = _loadtxt(path, chunk, usecols, first_line + done, delimiter)
        done += len(chunk)
        counter[0] = done
        short = len(chunk) < n
        del chunk
        if block.size:
            yield block[:, 0], block[:, 1], block[:, 2], _text_colours(path, block[:, 3:6])
        if short:
            break


def _read_xyz(path: Path) -> ScanSource:
    """Text ``x y z r g b`` per line (spaces, commas or semicolons; ``#`` comments)."""
    with open(path, encoding="latin-1") as fh:
        first, _ = _next_data_line(fh)
    if first is None:
        raise InputError(path, "no points")
    delimiter, usecols = _text_layout(path, first, False)

    def blocks() -> Iterator[RawBlock]:
        with open(path, encoding="latin-1") as fh:
            first, skipped = _next_data_line(fh)
            yield from _text_blocks(path, itertools.chain([first], fh), usecols, delimiter, skipped, None, [0])

    return ScanSource(path, None, blocks, True)


def _read_pts(path: Path) -> ScanSource:
    """Leica PTS: a point count line, then ``x y z intensity r g b`` lines; blocks may repeat."""
    with open(path, encoding="latin-1") as fh:
        head, _ = _next_data_line(fh)
    if head is None:
        raise InputError(path, "no points")
    tok = head.split()
    if len(tok) != 1 or not tok[0].isdigit():
        raise InputError(path, f"line 1: expected a point count, got '{_snippet(head)}'")

    def blocks() -> Iterator[RawBlock]:
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
                got = [0]
                yield from _text_blocks(path, itertools.chain([first], fh), usecols, delimiter,
                                        line_no + read, count, got)
                if got[0] < count:
                    raise InputError(path, f"truncated: line {line_no} announces {count} points, "
                                           f"file has {got[0]}")
                line_no += read - 1 + got[0]

    return ScanSource(path, None, blocks, True)


# --------------------------------------------------------------------------- LAS / LAZ


def _read_las(path: Path) -> ScanSource:
    import laspy

    try:
        with laspy.open(path) as reader:
            header = reader.header
            dims = set(header.point_format.dimension_names)
            if not {"red", "green", "blue"} <= dims:
                raise InputError(path, f"no colour (LAS point format {header.point_format.id} has no RGB)")
            total = int(header.point_count)
    except laspy.errors.LaspyException as exc:
        raise InputError(path, f"cannot read LAS/LAZ file ({_reason(exc)})") from None
    if total == 0:
        raise InputError(path, "no points")

    def blocks() -> Iterator[RawBlock]:
        got = 0
        try:
            with laspy.open(path) as reader:
                for pts in reader.chunk_iterator(BLOCK_POINTS):
                    got += len(pts)
                    rgb = np.stack([np.asarray(pts.red), np.asarray(pts.green), np.asarray(pts.blue)], axis=1)
                    yield np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z), rgb
        except laspy.errors.LaspyException as exc:
            raise InputError(path, f"cannot read LAS/LAZ file ({_reason(exc)})") from None
        if got < total:
            raise InputError(path, f"truncated: header says {total} points, file has {got}")

    return ScanSource(path, total, blocks, True)


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


def _read_e57(path: Path) -> ScanSource:
    import pye57

    try:
        e57 = pye57.E57(str(path))
    except Exception as exc:  # libe57 raises its own exception types
        raise InputError(path, f"not a readable E57 file ({_reason(exc)})") from None
    try:
        n_scans = e57.scan_count
        if n_scans == 0:
            raise InputError(path, "no points (no scans in the file)")
        counts = tuple(int(e57.get_header(i).point_count) for i in range(n_scans))
    finally:
        e57.close()
    total = sum(counts)
    if total == 0:
        raise InputError(path, "no points")

    def blocks() -> Iterator[RawBlock]:
        for i in range(len(counts)):
            yield from scan_blocks(i)

    def scan_blocks(i: int) -> Iterator[RawBlock]:
        from pye57 import libe57

        e57 = pye57.E57(str(path))
        try:
            h = e57.get_header(i)
            if h.point_count:
                yield from _e57_scan_blocks(path, e57, i, h, libe57)
        finally:
            e57.close()

    return ScanSource(path, total, blocks, False, scans=counts, scan_blocks=scan_blocks)


def _e57_scan_blocks(path: Path, e57, index: int, h, libe57) -> Iterator[RawBlock]:
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

    cap = int(min(BLOCK_POINTS, h.point_count))
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
            yield world[:, 0], world[:, 1], world[:, 2], rgb
    finally:
        reader.close()


# --------------------------------------------------------------------------- PCD

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
        for rec in _records(path, dtype, pos, n, start, stop):
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

