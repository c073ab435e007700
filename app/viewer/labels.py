"""What the 3D scene writes and in which colours: status and RoI colours, wall and spot
labels, times, class names."""

from __future__ import annotations

import logging
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from sbsc_core.types import WallFrame

from ..surfaces import is_round, kind_of

log = logging.getLogger(__name__)


STATUS_RGB: dict[str, tuple[int, int, int]] = {
    "pending": (230, 30, 30),  # the paper's red spots
    "accepted": (40, 190, 70),
    "rejected": (120, 120, 120),
}


DEPTH_ROI_RGB = (0, 255, 255)  # cyan, figure 21 a


COLOUR_ROI_RGB = (255, 0, 255)  # magenta, figure 21 a


WALL_RGB = (255, 210, 0)


OPENING_RGB = (255, 130, 0)


SELECTION_RGB = (255, 240, 0)


COLUMN_RGB = (190, 190, 196)


CEILING_RGB = (120, 200, 255)


IMAGE_MODES: tuple[str, ...] = ("colour", "depth", "off")


SCAN_LEVELS: tuple[str, ...] = ("overview", "full", "off")


def _fmt(x: Any, nd: int = 2) -> str:
    return "–" if x is None else f"{float(x):.{nd}f}"


def wall_label(wid: str, f: WallFrame, storey: str | None = None) -> str:
    """A wall's name in the scene: its id and width, and its storey when the id does not carry it."""
    named = f" ({storey})" if storey and not wid.startswith(f"{storey}-") else ""
    return f"{wid}{named}  {f.width_m:.2f} m"


def readable_time(iso: Any) -> str:
    """An ISO time as people read it: ``2026-11-28 12:34 UTC`` (unchanged when not ISO)."""
    import datetime as _dt

    try:
        t = _dt.datetime.fromisoformat(str(iso).replace("Z", "+00:00"))
    except ValueError:
        return str(iso)
    if t.tzinfo is not None:
        t = t.astimezone(_dt.UTC)
    return t.strftime("%Y-%m-%d %H:%M") + (" UTC" if t.tzinfo is not None else "")


def label_positions(frames: dict[str, WallFrame], gap_m: float) -> dict[str, float]:
    """Where along each wall (u, metres) its name goes: the middle, except for walls whose
    middles are closer than ``gap_m`` in plan (the two faces of a partition, walls meeting
    at a corner): each of such a group of n goes to (k + 1) / (n + 1) of its own width, in
    the order of the ids and measured the same way round on walls facing each other, so that
    seen from above the names stand apart (raising them would not separate them in a view
    from above)."""
    ids = list(frames)
    mids = {w: frames[w].to_world(frames[w].width_m / 2.0, frames[w].height_m)[:2] for w in ids}
    group = {w: w for w in ids}

    def root(w: str) -> str:
        while group[w] != w:
            w = group[w]
        return w

    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            if np.hypot(*(mids[a] - mids[b])) < gap_m:
                group[root(b)] = root(a)
    members: dict[str, list[str]] = {}
    for w in ids:
        members.setdefault(root(w), []).append(w)
    out = {}
    for ws in members.values():
        ref = frames[min(ws)].axis_u
        for k, w in enumerate(sorted(ws)):
            share = (k + 1) / (len(ws) + 1)
            if float(np.dot(frames[w].axis_u, ref)) < -0.5:  # the other face of a partition runs the other way
                share = 1.0 - share
            out[w] = frames[w].width_m * share
    return out


def spread_labels(points: dict[str, np.ndarray], gap_m: float, step_m: float) -> dict[str, np.ndarray]:
    """Label anchors lifted so that no two closer than ``gap_m`` in plan share a height:
    each one, in order, rises by ``step_m`` until no label placed before it is within
    ``gap_m`` in plan and ``step_m`` in height (short walls at a corner stack their names)."""
    placed: dict[str, np.ndarray] = {}
    for key, p in points.items():
        q = np.asarray(p, float).copy()
        while any(np.hypot(*(q[:2] - o[:2])) < gap_m and abs(q[2] - o[2]) < step_m * 0.99
                  for o in placed.values()):
            q[2] += step_m
        placed[key] = q
    return placed


def spot_label(det: dict, names: dict[str, str] | None = None) -> str:
    """An object's label: the library's name of its class (``names``, from model.json) and its score."""
    name = (names or {}).get(det["class"], det["class"])
    if det.get("confidence") is not None:
        return f"{name} {_fmt(det['confidence'])}"
    return f"{name} α {_fmt(det.get('alpha'))}"


def class_names(models_dir: Path | None) -> dict[str, str]:
    """Class id -> display name from the library's model.json files ({} when unreadable)."""
    if models_dir is None:
        return {}
    from sbsc_core.errors import SbscError
    from sbsc_core.io.models import read_library_metadata

    try:
        return {cid: str(m.get("name") or cid) for cid, m in read_library_metadata(models_dir).items()}
    except (SbscError, OSError, ValueError):
        return {}


def class_choices(ids: Iterable[str], names: dict[str, str]) -> dict[str, str]:
    """A class dropdown's options: the library's display name -> class id, in the order of ``ids``.

    A name that two classes share, or that is another class's id, gets its id in brackets,
    so every option names one class.
    """
    ids = list(ids)
    shown = [names.get(cid, cid) for cid in ids]
    taken = set(ids)
    out: dict[str, str] = {}
    for cid, label in zip(ids, shown, strict=True):
        if shown.count(label) > 1 or (label != cid and label in taken):
            label = f"{label} ({cid})"
        out[label] = cid
    return out


def surface_text(wid: str | None, sf: dict | None) -> str:
    """Where an object is, in words: on a wall, a ceiling seen from below, a column's face."""
    if sf is None or kind_of(sf) == "wall":
        return f"wall {wid}"
    if kind_of(sf) == "ceiling":
        return f"ceiling {wid} (seen from below)"
    col = sf.get("column") or wid
    if is_round(sf):
        return f"round column {col} (unrolled)"
    return f"column {col}, face {wid}"
