"""The stations of a merged scan file, from a per-point station property.

A cloud merged from several scanner stations (CloudCompare's "Merge", a LAS of several
flight lines, a simulator's ``scan.ply``) often keeps which station each point came from
(:data:`~sbsc_core.io.scans.STATION_FIELDS`). Merging writes each station's points one
after the other, so the property is a few long runs of equal values: :func:`station_runs`
reads the property once, block by block, and returns those runs, which
:func:`~sbsc_core.imaging.partition.plan_parts` makes into parts of separate stations (their
registration is then refined as separate files' are, :mod:`sbsc_core.scene.registration`).

A property that is one value, or whose values change too often to be stations (points
interleaved, a per-point class or intensity under a station's name), gives no runs: the
file is one station, as a file without the property.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scan_source import ScanSource

__all__ = ["MAX_STATION_RUNS", "MIN_RUN_POINTS", "StationRun", "station_runs", "station_label"]

MAX_STATION_RUNS = 4096  # more runs than this are not stations (and would make too many parts)
MIN_RUN_POINTS = 1000  # the runs must hold this many points on average (interleaved points are not stations)


@dataclass(frozen=True)
class StationRun:
    """Points ``start:stop`` of a merged file, all of one station (``value`` of the property)."""

    start: int
    stop: int
    value: float | int


def station_runs(src: ScanSource, *, max_runs: int = MAX_STATION_RUNS, min_run_points: int = MIN_RUN_POINTS
                 ) -> list[StationRun] | None:
    """The runs of equal values of ``src``'s station property, or None when they are not stations.

    None when the source has no station property, when the property holds fewer than two
    distinct values, more than ``max_runs`` runs (the reading stops there), runs of
    fewer than ``min_run_points`` points on average, or a NaN value (a point of no known
    station). The property is read once, block by block.
    """
    if src.station_blocks is None or src.count is None:
        return None
    starts: list[int] = []
    values: list = []
    last = None
    at = 0
    for col in src.station_blocks(0, src.count):
        n = len(col)
        if n == 0:
            continue
        col = np.asarray(col)
        change = np.flatnonzero(col[1:] != col[:-1]) + 1
        if last is None or not col[0] == last:
            starts.append(at)
            values.append(col[0].item())
        starts.extend((change + at).tolist())
        values.extend(col[change].tolist())
        if len(starts) > max_runs:
            return None
        last = col[-1]
        at += n
    if at == 0 or len(starts) * min_run_points > at:
        return None
    if any(v != v for v in values) or len(set(values)) < 2:  # NaN, or one station
        return None
    return [StationRun(a, b, v) for a, b, v in zip(starts, [*starts[1:], at], values, strict=True)]


def station_label(value: float | int) -> str:
    """A station's property value as a short name: ``3`` (also for ``3.0``), ``2.5``."""
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)
