"""The E57 scan reader (pye57): one or several scans a file, cartesian or spherical."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from .scan_source import BLOCK_POINTS, RawBlock, ScanSource, _reason


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
