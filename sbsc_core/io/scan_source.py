"""What a scan reader gives: a :class:`ScanSource` of raw blocks, the :class:`ScanChunk` s
made of them, and the block and colour helpers every reader shares."""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

CHUNK_POINTS = 1 << 21  # points per chunk handed to the caller


BLOCK_POINTS = 1 << 16  # points a reader converts at once (bounds float64 / parsing temporaries)


ORIGIN_SAMPLE = 100_000  # points of the first block whose median sets the origin


RawBlock = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


STATION_FIELDS: tuple[str, ...] = ("original_cloud_index", "scan_index", "scan_id", "point_source_id", "station")


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


def _records(path: Path, dtype: np.dtype, offset: int, n: int, *, start: int, stop: int | None
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


def _snippet(text: str, limit: int = 30) -> str:
    """A short printable excerpt of a line for an error message."""
    clean = "".join(ch if ch.isprintable() and ord(ch) < 128 else "?" for ch in text.strip())
    return clean if len(clean) <= limit else clean[:limit] + "..."


def _reason(exc: BaseException, limit: int = 120) -> str:
    """A third-party exception as a short one-line reason."""
    text = " ".join(str(exc).split("****")[0].split()) or type(exc).__name__
    return text if len(text) <= limit else text[:limit] + "..."
