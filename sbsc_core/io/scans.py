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
cloud; the detection pipeline streams instead (:mod:`sbsc_core.imaging.partition`).

A file that cannot be used raises :class:`~sbsc_core.errors.InputError` naming the file
and the reason, when it is opened or at the chunk where the problem is met; a caller that
collects chunks then keeps nothing.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..types import PointCloud
from .scan_source import CHUNK_POINTS, ORIGIN_SAMPLE, ScanChunk, ScanSource, _reason, _to_8_bit

"""x, y, z (world coordinates, any float type) and (n, 3) colours (uint8, or uint16 when wide)."""

"""Per-point properties naming a merged file's station (CloudCompare's "Original cloud index", LAS's
point_source_id, ...), in order of preference, as :func:`station_field` compares them."""


ScanReader = Callable[[Path], ScanSource]
PointCount = Callable[[Path], int]
"""A format's upload check: the point count from the header, checked against the file's size
(see :mod:`sbsc_core.io.scan_check`)."""
CrsReader = Callable[[Path], Any]
"""A format's coordinate system, as its file records it (see :mod:`sbsc_core.io.crs`), or None."""
_READERS: dict[str, ScanReader] = {}
_COUNTS: dict[str, PointCount] = {}
_CRS: dict[str, CrsReader] = {}


def register_reader(extension: str, reader: ScanReader, *, count: PointCount | None = None,
                    crs: CrsReader | None = None) -> None:
    """Make ``reader`` the reader of files ending in ``extension``.

    Each format registers itself once, in ``sbsc_core/io/formats.py``; the readers, the
    upload checks and :func:`scan_extensions` all come from this registry.

    Parameters
    ----------
    extension
        The file name's ending, with its dot (``".ply"``); matched without case.
    reader
        Opens a file of the format as a :class:`~sbsc_core.io.scan_source.ScanSource`.
    count
        The upload check: the point count in the file's header. The review app refuses a
        format without one.
    crs
        Reads the coordinate system the files record; None: they record none.
    """
    _READERS[extension.lower()] = reader
    if count is not None:
        _COUNTS[extension.lower()] = count
    if crs is not None:
        _CRS[extension.lower()] = crs


def crs_reader(extension: str) -> CrsReader | None:
    """The reader of the coordinate system files of ``extension`` record, None when they record none."""
    return _CRS.get(extension.lower())


def point_count_check(extension: str) -> PointCount | None:
    """The upload check registered for ``extension``, None when there is none."""
    return _COUNTS.get(extension.lower())


def scan_readers() -> dict[str, ScanReader]:
    """The registered readers by extension.

    Returns
    -------
    dict[str, ScanReader]
        A copy of the registry: extension (``".ply"``) -> reader.
    """
    return dict(_READERS)


def scan_extensions() -> tuple[str, ...]:
    """The scan formats of contract 1: every extension a reader is registered for (``".ply"``, ...).

    The one list of them: the CLI's help, the review app's upload check and its upload page
    take it from here.

    Returns
    -------
    tuple[str, ...]
        The extensions in the order they were registered, lower case, with their dot.
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
    """The point count in the file's header, without reading the points.

    Parameters
    ----------
    path
        A scan file of a registered format.

    Returns
    -------
    int or None
        The header's point count; None for formats whose header has none (text files).
    """
    return open_scan(path).count


def iter_scan(path: Path | str | ScanSource, origin: np.ndarray | None = None, *,
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


def sample_scan(src: ScanSource, origin: np.ndarray, every: int, *, first: int = 0, start: int = 0,
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


# --------------------------------------------------------------------------- PLY


# --------------------------------------------------------------------------- text


# --------------------------------------------------------------------------- LAS / LAZ


# --------------------------------------------------------------------------- E57


# --------------------------------------------------------------------------- PCD


