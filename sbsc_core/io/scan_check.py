"""The upload check of a scan: its header and a bounded sample, never the whole cloud.

The point count comes from the header where the format has one (PLY, PTS, LAS, PCD,
E57) and is checked against the file's size: a binary PLY whose header claims 10 points
while the file holds 1,000 is refused, and so is one that claims more than it holds.
Text formats are counted line by line (streamed, constant memory). The first
:data:`SAMPLE_POINTS` points are then written to a small file of the same format and read
with the library's own reader (:func:`sbsc_core.io.scans.read_scan`), which decides about
colour, numbers and finite coordinates exactly as a job will.

Memory is bounded by the sample, whatever the file's size; the server runs this in a
child process (:func:`app.storage.check_scan`) so that a reader crash cannot take it down.
"""

from __future__ import annotations

import re
import struct
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError

SAMPLE_POINTS = 20_000
CHUNK = 1 << 20
_EMPTY_LINE = re.compile(rb"\n(?=\n)")


class ScanRefused(Exception):
    """The scan cannot be used: a one-line reason (without any server path)."""


def count_points(path: Path) -> int:
    """The number of points of the scan at ``path`` from its header / lines (the format's check
    in the reader registry, :mod:`sbsc_core.io.formats`); raise ScanRefused."""
    from .scans import point_count_check

    suffix = path.suffix.lower().split(".")[-1]
    check = point_count_check(f".{suffix}")
    if check is None:
        raise ScanRefused(f"unsupported file type '.{suffix}'")
    if path.stat().st_size == 0:
        raise ScanRefused("empty file")
    try:
        n = check(path)
    except InputError as exc:
        raise ScanRefused(exc.reason) from None
    if n <= 0:
        raise ScanRefused("no points")
    return n


def _sample_read(path: Path, suffix: str, data: bytes) -> None:
    """Read ``data`` (a small file of the same format) with the library's reader."""
    from .scans import read_scan

    with tempfile.TemporaryDirectory(prefix="sbsc-sample-") as tmp:
        sample = Path(tmp) / f"sample{suffix}"
        sample.write_bytes(data)
        try:
            read_scan(sample)
        except InputError as exc:
            raise ScanRefused(exc.reason.replace(str(sample), path.name)) from None


def _lines(fh, start: int = 0) -> Iterator[bytes]:  # noqa: ANN001
    fh.seek(start)
    yield from fh


def _data_line(line: bytes) -> bool:
    s = line.strip()
    return bool(s) and not s.startswith(b"#")


# --------------------------------------------------------------------------- PLY


def ply_points(path: Path) -> int:
    import numpy as np

    from .scan_ply import _parse_ply_header, _ply_columns

    size = path.stat().st_size
    with open(path, "rb") as fh:
        fmt, elements, header_len = _parse_ply_header(path, fh)
        vi = next((i for i, e in enumerate(elements) if e.name == "vertex"), None)
        if vi is None:
            raise ScanRefused("PLY file has no vertex element")
        vertex = elements[vi]
        if vertex.count == 0:
            raise ScanRefused("no points")
        _ply_columns(path, vertex)
        if vertex.has_list:
            raise ScanRefused("PLY vertex element with list properties is not supported")
        fh.seek(0)
        header = fh.read(header_len)
        head_lines = header.decode("ascii", "replace").splitlines(keepends=True)
        keep = min(vertex.count, SAMPLE_POINTS)

        def sample_header() -> bytes:
            """The header with only the vertex element, of ``keep`` vertices."""
            out, skip = [], False
            for line in head_lines:
                tok = line.split()
                if tok[:1] == ["element"]:
                    skip = tok[1] != "vertex"
                    if not skip:
                        line = f"element vertex {keep}\n"
                if not skip:
                    out.append(line)
            return "".join(out).encode("ascii")

        if fmt == "ascii":
            before = sum(e.count for e in elements[:vi])
            total = sum(e.count for e in elements)
            n_lines, rows = 0, []
            for line in _lines(fh, header_len):
                if not line.strip():
                    continue
                if before <= n_lines < before + keep:
                    rows.append(line)
                n_lines += 1
                if n_lines > total:
                    raise ScanRefused(f"the header says {vertex.count:,} points but the file holds more lines "
                                      "than its elements")
            if n_lines < total:
                raise ScanRefused(f"truncated: the header says {vertex.count:,} points, "
                                  f"the file holds {max(0, n_lines - before):,}")
            _sample_read(path, ".ply", sample_header() + b"".join(rows))
            return vertex.count
        offset, tail_fixed = header_len, True
        for e in elements[:vi]:
            if e.has_list:
                raise ScanRefused(f"PLY element '{e.name}' with list properties before the vertices")
            offset += e.count * sum(np.dtype(t).itemsize for _, t in e.props)
        record = sum(np.dtype(t).itemsize for _, t in vertex.props)
        end = offset + vertex.count * record
        for e in elements[vi + 1:]:
            if e.has_list:
                tail_fixed = False
            else:
                end += e.count * sum(np.dtype(t).itemsize for _, t in e.props)
        if size < end:
            raise ScanRefused(f"truncated: the header says {vertex.count:,} points ({end:,} bytes), "
                              f"the file has {size:,} bytes")
        if tail_fixed and size > end:
            more = (size - end) // max(record, 1)
            raise ScanRefused(f"the header says {vertex.count:,} points but the file holds {size - end:,} "
                              f"more bytes (about {more:,} more points)")
        fh.seek(offset)
        body = fh.read(keep * record)
        _sample_read(path, ".ply", sample_header() + body)
    return vertex.count


# --------------------------------------------------------------------------- text


def text_points(path: Path) -> int:
    """Data lines of an ``x y z r g b`` file, counted in 1 MiB blocks at C speed: newlines,
    minus empty lines and ``#`` comment lines (a line of blanks only counts as data here;
    the reader of a job skips it)."""
    rows: list[bytes] = []
    with open(path, "rb") as fh:
        for line in fh:
            if _data_line(line):
                rows.append(line if line.endswith(b"\n") else line + b"\n")
                if len(rows) >= SAMPLE_POINTS:
                    break
        if not rows:
            raise ScanRefused("no points")
        fh.seek(0)
        n, prev = 0, b"\n"  # a virtual newline before the first byte
        while block := fh.read(CHUNK):
            text = prev + block.replace(b"\r", b"")
            if len(text) == 1:
                continue
            # line starts in this block follow the newlines of text[:-1]; the ones that start
            # with a newline (empty line) or '#' (comment) are no points
            body = text[:-1]
            n += body.count(b"\n") - len(_EMPTY_LINE.findall(text)) - text.count(b"\n#")
            prev = text[-1:]
    _sample_read(path, path.suffix.lower(), b"".join(rows))
    return n


def _count_text_lines_slow(path: Path) -> int:  # the definition the fast count follows (tests)
    with open(path, "rb") as fh:
        return sum(1 for line in fh if line.replace(b"\r", b"") not in (b"\n", b"")
                   and not line.startswith(b"#"))


def pts_points(path: Path) -> int:
    total, rows, announced, got = 0, [], None, 0
    with open(path, "rb") as fh:
        for line in _lines(fh):
            if not _data_line(line):
                continue
            if announced is None or got == announced:
                if announced is not None:
                    total += got
                tok = line.split()
                if len(tok) != 1 or not tok[0].isdigit() or len(tok[0]) > 15:
                    if announced is None:
                        raise ScanRefused(f"expected a point count on the first line, got '{line[:40].decode('latin-1').strip()}'")
                    raise ScanRefused(f"holds more points than its count line announces ({announced:,})")
                announced, got = int(tok[0]), 0
                continue
            if len(rows) < SAMPLE_POINTS and total == 0:
                rows.append(line if line.endswith(b"\n") else line + b"\n")
            got += 1
    if announced is None:
        raise ScanRefused("no points")
    if got < announced:
        raise ScanRefused(f"truncated: a count line announces {announced:,} points, the file has {got:,}")
    total += got
    if rows:
        _sample_read(path, ".pts", f"{len(rows)}\n".encode() + b"".join(rows))
    return total


# --------------------------------------------------------------------------- LAS / LAZ


def las_points(path: Path) -> int:
    import laspy

    size = path.stat().st_size
    try:
        with laspy.open(path) as reader:
            h = reader.header
            dims = set(h.point_format.dimension_names)
            if not {"red", "green", "blue"} <= dims:
                raise ScanRefused(f"no colour (LAS point format {h.point_format.id} has no RGB)")
            n = int(h.point_count)
            if n <= 0:
                raise ScanRefused("no points")
            if path.suffix.lower() == ".las":
                end = int(h.offset_to_point_data) + n * int(h.point_format.size)
                if size < end:
                    raise ScanRefused(f"truncated: the header says {n:,} points ({end:,} bytes), "
                                      f"the file has {size:,} bytes")
                evlrs = int(getattr(h, "number_of_evlrs", 0) or 0)
                if not evlrs and size - end >= int(h.point_format.size) * 2:
                    raise ScanRefused(f"the header says {n:,} points but the file holds "
                                      f"{(size - end) // int(h.point_format.size):,} more records")
            pts = reader.read_points(min(n, SAMPLE_POINTS))
            import numpy as np

            xyz = np.stack([np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z)], axis=1)
            if len(xyz) == 0:
                raise ScanRefused("truncated: no point records")
            if not np.isfinite(xyz).all():
                raise ScanRefused("non-finite coordinates")
            return n
    except ScanRefused:
        raise
    except Exception as exc:  # noqa: BLE001 - laspy raises many kinds on a broken file
        raise ScanRefused(f"cannot read LAS/LAZ file ({type(exc).__name__}: {str(exc)[:120]})") from None


# --------------------------------------------------------------------------- PCD


_PCD_HEAD = re.compile(rb"^DATA[ \t]+(\S+)[ \t]*\r?\n", re.M)


def pcd_points(path: Path) -> int:
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
        m = _PCD_HEAD.search(head)
        if m is None:
            raise ScanRefused("not a PCD file (no DATA line in the header)")
        header_len = m.end()
        fields: dict[str, list[str]] = {}
        for line in head[:m.start()].decode("ascii", "replace").splitlines():
            tok = line.split()
            if tok and not tok[0].startswith("#"):
                fields[tok[0].upper()] = tok[1:]
        data = m.group(1).decode("ascii", "replace")
        try:
            names = fields["FIELDS"]
            sizes = [int(x) for x in fields.get("SIZE", [])]
            counts = [int(x) for x in fields.get("COUNT", ["1"] * len(names))]
            n = int(fields["POINTS"][0])
        except (KeyError, IndexError, ValueError):
            raise ScanRefused("bad PCD header (FIELDS, SIZE, COUNT or POINTS)") from None
        if n <= 0:
            raise ScanRefused("no points")
        if not ({"x", "y", "z"} <= set(names)):
            raise ScanRefused("PCD has no x, y, z fields")
        if not ({"rgb"} & set(names) or {"rgba"} & set(names)):
            raise ScanRefused("no colour (PCD has no rgb/rgba field)")
        if len(sizes) != len(names) or len(counts) != len(names):
            raise ScanRefused("bad PCD header (FIELDS, SIZE and COUNT differ in length)")
        record = sum(s * c for s, c in zip(sizes, counts, strict=True))
        keep = min(n, SAMPLE_POINTS)
        new_head = re.sub(rb"(?m)^(POINTS|WIDTH)[ \t]+\d+", lambda mm: mm.group(1) + b" %d" % keep,
                          head[:m.start()])
        new_head = re.sub(rb"(?m)^HEIGHT[ \t]+\d+", b"HEIGHT 1", new_head)
        if data == "binary":
            end = header_len + n * record
            if size != end:
                raise ScanRefused(f"the header says {n:,} points ({end:,} bytes), the file has {size:,} bytes")
            fh.seek(header_len)
            _sample_read(path, ".pcd", new_head + m.group(0) + fh.read(keep * record))
        elif data == "ascii":
            rows, got = [], 0
            for line in _lines(fh, header_len):
                if line.strip():
                    if got < keep:
                        rows.append(line)
                    got += 1
            if got != n:
                raise ScanRefused(f"the header says {n:,} points, the file holds {got:,} lines")
            _sample_read(path, ".pcd", new_head + m.group(0) + b"".join(rows))
        elif data == "binary_compressed":
            fh.seek(header_len)
            sizes_raw = fh.read(8)
            if len(sizes_raw) < 8:
                raise ScanRefused("truncated PCD (no compressed block)")
            compressed, uncompressed = struct.unpack("<II", sizes_raw)
            if uncompressed != n * record:
                raise ScanRefused(f"the header says {n:,} points but the compressed block holds "
                                  f"{uncompressed:,} bytes ({n * record:,} expected)")
            if header_len + 8 + compressed > size:
                raise ScanRefused("truncated PCD (the compressed block is cut)")
        else:
            raise ScanRefused(f"unknown PCD DATA kind '{data}'")
    return n


# --------------------------------------------------------------------------- E57


def e57_points(path: Path) -> int:
    try:
        import pye57
    except ImportError:
        raise ScanRefused("E57 support (pye57) is not installed") from None
    size = path.stat().st_size
    try:
        e57 = pye57.E57(str(path))
    except Exception as exc:  # noqa: BLE001 - libE57 raises its own kinds on broken files
        raise ScanRefused(f"cannot read E57 file ({type(exc).__name__})") from None
    try:
        total = 0
        for i in range(e57.scan_count):
            h = e57.get_header(i)
            fields = set(h.point_fields)
            if not ({"cartesianX", "cartesianY", "cartesianZ"} <= fields
                    or {"sphericalRange", "sphericalAzimuth", "sphericalElevation"} <= fields):
                raise ScanRefused(f"scan {i} has neither cartesian nor spherical coordinates")
            if not {"colorRed", "colorGreen", "colorBlue"} <= fields:
                raise ScanRefused(f"no colour (scan {i} has no colorRed/Green/Blue)")
            total += int(h.point_count)
    except ScanRefused:
        raise
    except Exception as exc:  # noqa: BLE001
        raise ScanRefused(f"cannot read E57 file ({type(exc).__name__})") from None
    finally:
        close = getattr(e57, "close", None)
        if close:
            close()
    if total <= 0:
        raise ScanRefused("no points")
    if total > size:  # even bit-packed, a point takes more than one byte of the file
        raise ScanRefused(f"the headers claim {total:,} points in a file of {size:,} bytes")
    return total
