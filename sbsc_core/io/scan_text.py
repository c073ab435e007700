"""The text scan readers: XYZ / TXT (x y z r g b per line) and PTS (a count line, then x y z
intensity r g b)."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from .scan_source import BLOCK_POINTS, RawBlock, ScanSource, _float_colours_to_8, _snippet


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


def _text_blocks(path: Path, lines: Iterator[str], usecols: list[int], *, delimiter: str | None,
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
            yield from _text_blocks(path, itertools.chain([first], fh), usecols,
                                    delimiter=delimiter, first_line=skipped, limit=None, counter=[0])

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
                yield from _text_blocks(path, itertools.chain([first], fh), usecols, delimiter=delimiter,
                                        first_line=line_no + read, limit=count, counter=got)
                if got[0] < count:
                    raise InputError(path, f"truncated: line {line_no} announces {count} points, "
                                           f"file has {got[0]}")
                line_no += read - 1 + got[0]

    return ScanSource(path, None, blocks, True)
