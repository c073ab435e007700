"""The LAS / LAZ scan reader (laspy, lazrs)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from .scan_source import BLOCK_POINTS, RawBlock, ScanSource, _reason


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
