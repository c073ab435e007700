"""Writing an as-designed IFC for the simulator: the ground truth's walls, openings and
objects with a few deliberate differences (moved, removed, added), seeded."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..types import ModelLibrary, Surface, WallFrame
from . import ClassTyping, class_typings
from .design import DEFAULT_MOUNT_HEIGHT_M
from .export import (
    IfcModelBuilder,
    parse_detections_document,
    storey_elevation,
    write_ifc_atomic,
)
from .surfaces import surface_coords, surface_normal


@dataclass
class _Placed:
    class_id: str
    wall: str | None
    u: float
    v: float
    width: float
    height: float
    position: np.ndarray
    normal: np.ndarray | None
    surface: str = "wall"  # kind of surface: wall, ceiling or column
    surface_id: str | None = None  # the ceiling or column face it is on
    rotation_deg: float = 0.0  # in-plane turn seen from the room (objects on ceilings and columns)


def _truth_objects(truth: dict, walls: dict[str, WallFrame], where: str,
                   surfaces: Mapping[str, Surface] | None = None) -> list[_Placed]:
    surfaces = surfaces or {}
    objs = truth.get("objects")
    if not isinstance(objs, list):
        raise InputError(where, "'objects' must be a list")
    out = []
    for i, o in enumerate(objs):
        at = f"{where}: objects[{i}]"
        if not isinstance(o, dict) or not isinstance(o.get("class"), str):
            raise InputError(at, "an object needs a string 'class'")
        try:
            pos = np.asarray(o["position"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            raise InputError(at, "needs 'position' [x, y, z]") from None
        if pos.shape != (3,) or not np.isfinite(pos).all():
            raise InputError(at, "'position' must be 3 finite numbers")
        wid = o.get("wall") if o.get("wall") in walls else None
        sid = o.get("wall") if wid is None and o.get("wall") in surfaces else None
        if wid is not None:
            u, v, _ = walls[wid].to_uvd(pos[None])[0]
        elif sid is not None:
            u, v, _ = surface_coords(surfaces[sid], pos[None])[0]
        else:
            u = v = 0.0
        n = o.get("normal")
        out.append(_Placed(o["class"], wid, float(u), float(v), float(o.get("width_m") or 0.1),
                           float(o.get("height_m") or 0.1), pos,
                           None if n is None else np.asarray(n, dtype=np.float64),
                           surfaces[sid].kind if sid is not None else "wall", sid,
                           float(o.get("rotation_deg") or 0.0) if sid is not None else 0.0))
    return out


def _overlaps(a: tuple[float, float, float, float], b: tuple[float, float, float, float], gap: float) -> bool:
    return not (a[1] + gap <= b[0] or b[1] + gap <= a[0] or a[3] + gap <= b[2] or b[3] + gap <= a[2])


def _rect(u: float, v: float, w: float, h: float) -> tuple[float, float, float, float]:
    return (u - w / 2, u + w / 2, v - h / 2, v + h / 2)


def _surface_point(sf: Surface, u: float, v: float) -> np.ndarray:
    """The point (u, v) of a surface: on its plane, or on the cylinder of a round column."""
    if not sf.round:
        return sf.frame.to_world(u, v)
    a = u / float(sf.radius_m)
    return np.array([sf.centre[0] + sf.radius_m * np.cos(a), sf.centre[1] + sf.radius_m * np.sin(a),
                     sf.frame.origin[2] + v])


SURFACE_MARGIN_M = 0.6  # a moved or added ceiling object keeps this far from its ceiling's edges


ADDED_CEILING_OFFSET_M = (1.5, 3.0)  # an added ceiling object stands this far from a built one of its class


def _surface_differences(built: list[_Placed], surfaces: Mapping[str, Surface], rng: np.random.Generator, *,
                         changes: int, shift_m: tuple[float, float], separation_m: float,
                         size: Any) -> tuple[set[int], dict[int, _Placed], list[_Placed]]:
    """``changes`` removed, moved and added objects per surface kind (ceiling, column).

    A moved ceiling object shifts ``shift_m`` in a random direction in the ceiling's plane, a
    moved column object ``shift_m`` up or down its face. An added object is of a class built
    on that kind of surface: on a ceiling 1.5-3 m from a built one of its class, on a column
    at the middle of a face (round: anywhere around) at its class's median height there.
    Each keeps ``separation_m`` from every other object of its class.
    """
    removed: set[int] = set()
    moved: dict[int, _Placed] = {}
    added: list[_Placed] = []
    occupied: dict[str, list] = {sid: [_rect(o.u, o.v, o.width, o.height) for o in built if o.surface_id == sid]
                                 for sid in surfaces}

    def far_from_class(pos: np.ndarray, cid: str, skip: _Placed | None) -> bool:
        others = [o.position for o in built if o.class_id == cid and o is not skip]
        others += [a.position for a in added if a.class_id == cid]
        others += [m.position for m in moved.values() if m.class_id == cid]
        return all(np.linalg.norm(p - pos) >= separation_m for p in others)

    def fits(sf: Surface, rect: tuple, skip_rect: tuple | None = None) -> bool:
        f = sf.frame
        m = SURFACE_MARGIN_M if sf.kind == "ceiling" else 0.05
        if sf.round:
            if rect[2] < m or rect[3] > f.height_m - m:
                return False
        elif rect[0] < m or rect[1] > f.width_m - m or rect[2] < m or rect[3] > f.height_m - m:
            return False
        return not any(_overlaps(rect, r, 0.05) for r in occupied[sf.id] if r != skip_rect)

    def placed(o_cls: str, sf: Surface, u: float, v: float, *, w: float, h: float,
               turn: float = 0.0) -> _Placed:
        pos = _surface_point(sf, u, v)
        return _Placed(o_cls, None, u, v, w, h, pos, surface_normal(sf, pos), sf.kind, sf.id, turn)

    for kind in ("ceiling", "column"):
        idx = [i for i in (int(k) for k in rng.permutation(len(built))) if built[i].surface == kind]
        kind_surfaces = [sf for sf in surfaces.values() if sf.kind == kind]
        if not idx or not kind_surfaces:
            continue
        isolated = [i for i in idx if far_from_class(built[i].position, built[i].class_id, built[i])]
        removed |= set((isolated + [i for i in idx if i not in isolated])[:changes])
        n_moved = 0
        for i in idx:
            if n_moved >= changes:
                break
            if i in removed:
                continue
            o = built[i]
            sf = surfaces[o.surface_id]
            for _ in range(20):
                dist = float(rng.uniform(*shift_m))
                if kind == "ceiling":
                    a = float(rng.uniform(0, 2 * np.pi))
                    u, v = o.u + dist * np.cos(a), o.v + dist * np.sin(a)
                else:
                    u, v = o.u, o.v + dist * (1 if rng.random() < 0.5 else -1)
                rect = _rect(u, v, o.width, o.height)
                cand = placed(o.class_id, sf, u, v, w=o.width, h=o.height, turn=o.rotation_deg)
                if fits(sf, rect, _rect(o.u, o.v, o.width, o.height)) and far_from_class(cand.position, o.class_id, o):
                    moved[i] = cand
                    occupied[sf.id].append(rect)
                    n_moved += 1
                    break
        classes = sorted({built[i].class_id for i in idx})
        for _ in range(500):
            if sum(a.surface == kind for a in added) >= changes:
                break
            cid = classes[int(rng.integers(len(classes)))]
            same = [o for o in built if o.surface == kind and o.class_id == cid]
            w, h = size(cid, same[0])
            if kind == "ceiling":
                ref = same[int(rng.integers(len(same)))]
                sf = surfaces[ref.surface_id]
                a, dist = float(rng.uniform(0, 2 * np.pi)), float(rng.uniform(*ADDED_CEILING_OFFSET_M))
                u, v = ref.u + dist * np.cos(a), ref.v + dist * np.sin(a)
            else:
                sf = kind_surfaces[int(rng.integers(len(kind_surfaces)))]
                u = float(rng.uniform(0, sf.frame.width_m)) if sf.round else sf.frame.width_m / 2
                v = float(np.median([o.v for o in same]))
            rect = _rect(u, v, w, h)
            cand = placed(cid, sf, u, v, w=w, h=h)
            if fits(sf, rect) and far_from_class(cand.position, cid, None):
                added.append(cand)
                occupied[sf.id].append(rect)
    return removed, moved, added


def write_as_designed_ifc(truth_doc: dict, out: Path, *, seed: int = 0, n_moved: int = 3, n_removed: int = 2,
                          n_added: int = 2, library: ModelLibrary | None = None, schema: str = "IFC4",
                          shift_m: tuple[float, float] = (0.4, 0.8), separation_m: float = 1.2,
                          typings: dict[str, ClassTyping] | None = None,
                          mount_heights: Mapping[str, float] | None = None, surface_changes: int = 1) -> dict:
    """Write an as-designed IFC of a simulated scene with deliberate differences.

    Starting from what is built (the ground truth, contract 5 with ``walls`` and per-object
    ``wall``/``u``/``v``), ``n_removed`` built objects are left out of the design, ``n_moved``
    are designed ``shift_m`` metres away along their wall, and ``n_added`` objects that are
    not built are added. A moved or added designed position keeps ``separation_m`` from every
    other built object of its class, so each difference has one unambiguous reading. An added
    object stands at the median height of its class's built objects, else at its
    ``mount_heights`` entry (the simulator passes its catalogue's), else at
    :data:`DEFAULT_MOUNT_HEIGHT_M`.

    With ceilings and columns in the truth (its ``surfaces``, issue 11) the design holds them
    too (IfcCovering, IfcColumn, :mod:`.export`) with their objects, and ``surface_changes``
    objects are removed, moved and added on each kind of surface
    (:func:`_surface_differences`); the walls' differences are drawn among wall objects only.
    With ``storeys`` in the truth, one IfcBuildingStorey each.

    Parameters
    ----------
    truth_doc
        The ground truth of the simulated scene (contract 5).
    out
        The IFC file to write.
    seed
        Picks which objects differ, and where the added ones go.
    n_moved, n_removed, n_added
        How many wall objects are moved, left out of the design and added.
    library
        The model library; None: the bundled one.
    schema
        ``IFC4``, ``IFC4X3`` or ``IFC2X3``.
    shift_m
        The range of a moved object's shift along its wall, metres.
    separation_m
        The least distance from a moved or added position to a built object of its class.
    typings
        How each class is written in IFC, when already made from the library.
    mount_heights
        Class id -> height of an added object whose class has no built object.
    surface_changes
        How many objects are removed, moved and added on each kind of surface beyond walls.

    Returns
    -------
    dict
        ``{"as_designed": out.name, "design_differences": [...]}``, each difference
        ``{"kind": "moved"|"removed"|"added", "class", "wall", "designed_position",
        "built_position"}`` (null where it does not exist; with surfaces also ``"surface"``:
        wall, ceiling or column, and ``wall`` names the surface), to be stored in the ground truth.
    """
    from .export import add_storeys_and_surfaces

    out = Path(out)
    mount_heights = dict(mount_heights or {})
    where = "ground truth"
    if not isinstance(truth_doc, dict):
        raise InputError(where, "expected a JSON object")
    extra = {k: truth_doc[k] for k in ("surfaces", "storeys") if truth_doc.get(k)}
    parsed = parse_detections_document({"schema": "sbsc.detections/1", "walls": truth_doc.get("walls") or [],
                                        "openings": truth_doc.get("openings") or [], "detections": [], **extra},
                                       where)
    walls = parsed.walls
    surfaces = parsed.surfaces
    built = _truth_objects(truth_doc, walls, where, surfaces)
    typings = typings if typings is not None else class_typings(library)
    rng = np.random.default_rng(seed)

    def size(cid: str, obj: _Placed | None = None) -> tuple[float, float]:
        if cid in typings:
            return typings[cid].width_m, typings[cid].height_m
        return (obj.width, obj.height) if obj else (0.1, 0.1)

    occupied = {wid: [_rect(o.u, o.v, o.width, o.height) for o in built if o.wall == wid] for wid in walls}
    holes = {wid: [(o["u_min"], o["u_max"], o["v_min"], o["v_max"]) for o in parsed.openings if o["wall"] == wid]
             for wid in walls}

    def far_from_class(pos: np.ndarray, cid: str, skip: _Placed | None) -> bool:
        return all(np.linalg.norm(o.position - pos) >= separation_m for o in built
                   if o.class_id == cid and o is not skip)

    def fits(wid: str, rect: tuple[float, float, float, float], skip_rect: tuple | None = None) -> bool:
        f = walls[wid]
        if rect[0] < 0.05 or rect[1] > f.width_m - 0.05 or rect[2] < 0.02 or rect[3] > f.height_m - 0.02:
            return False
        if any(_overlaps(rect, h, 0.10) for h in holes[wid]):
            return False
        return not any(_overlaps(rect, r, 0.05) for r in occupied[wid] if r != skip_rect)

    # the walls' differences among the objects on walls (all of them without surfaces: as before)
    order = [i for i in (int(k) for k in rng.permutation(len(built))) if built[i].surface_id is None]
    # a removed object has no other built object of its class near it, so that its
    # detection cannot pair with a designed neighbour that happens not to be recognized
    isolated = [i for i in order if far_from_class(built[i].position, built[i].class_id, built[i])]
    removed = set((isolated + [i for i in order if i not in isolated])[:n_removed])
    moved: dict[int, _Placed] = {}
    for i in order:
        if i in removed:
            continue
        if len(moved) >= n_moved:
            break
        o = built[i]
        if o.wall is None:
            continue
        w, h = size(o.class_id, o)
        for _ in range(20):
            shift = float(rng.uniform(*shift_m)) * (1 if rng.random() < 0.5 else -1)
            u = o.u + shift
            rect = _rect(u, o.v, w, h)
            pos = walls[o.wall].to_world(u, o.v)
            if fits(o.wall, rect, _rect(o.u, o.v, o.width, o.height)) and far_from_class(pos, o.class_id, o):
                moved[i] = _Placed(o.class_id, o.wall, u, o.v, w, h, pos, walls[o.wall].normal)
                occupied[o.wall].append(rect)
                break
    added: list[_Placed] = []
    on_walls = [o for o in built if o.surface_id is None]
    classes = sorted(typings) or sorted({o.class_id for o in built})
    if surfaces:  # only classes seen on walls are added to walls
        classes = sorted({o.class_id for o in on_walls}) or classes
    attempts = 0
    while len(added) < n_added and attempts < 500 and walls:
        attempts += 1
        cid = classes[int(rng.integers(len(classes)))]
        wid = sorted(walls)[int(rng.integers(len(walls)))]
        w, h = size(cid)
        same = [o.v for o in on_walls if o.class_id == cid]
        v = float(np.median(same)) if same else float(mount_heights.get(cid, DEFAULT_MOUNT_HEIGHT_M))
        f = walls[wid]
        if f.width_m < w + 0.2:
            continue
        u = float(rng.uniform(w / 2 + 0.1, f.width_m - w / 2 - 0.1))
        rect = _rect(u, v, w, h)
        pos = f.to_world(u, v)
        if fits(wid, rect) and far_from_class(pos, cid, None) and all(
                np.linalg.norm(a.position - pos) >= separation_m for a in added if a.class_id == cid):
            added.append(_Placed(cid, wid, u, v, w, h, pos, f.normal))
            occupied[wid].append(rect)
    if surfaces and surface_changes > 0:
        s_removed, s_moved, s_added = _surface_differences(
            built, surfaces, np.random.default_rng([seed, 11]), changes=surface_changes, shift_m=shift_m,
            separation_m=separation_m, size=size)
        removed |= s_removed
        moved.update(s_moved)
        added += s_added

    builder = IfcModelBuilder(schema, project_name="sbsc as-designed model (simulated)", typings=typings,
                              storey_elevation=storey_elevation(walls),
                              description="as-designed model written from a simulated scene, with deliberate differences")
    add_storeys_and_surfaces(builder, parsed)
    designed = [moved.get(i, o) for i, o in enumerate(built) if i not in removed] + added
    for k, o in enumerate(designed):
        typing = builder.typing_of(o.class_id, o.width, o.height)
        builder.add_component(o.class_id, o.position, wall_id=o.wall or o.surface_id, normal=o.normal,
                              name=f"{typing.name} {k + 1:03d}", tag=f"E{k + 1:03d}", rotation_deg=o.rotation_deg)
    write_ifc_atomic(builder.finish(), out)

    def p(x: np.ndarray | None) -> list[float] | None:
        return None if x is None else [round(float(c), 5) for c in x]

    def where_of(o: _Placed) -> dict:
        return {"wall": o.wall or o.surface_id, **({"surface": o.surface} if surfaces else {})}

    diffs = [{"kind": "removed", "class": built[i].class_id, **where_of(built[i]),
              "designed_position": None, "built_position": p(built[i].position)} for i in sorted(removed)]
    diffs += [{"kind": "moved", "class": built[i].class_id, **where_of(built[i]),
               "designed_position": p(m.position), "built_position": p(built[i].position),
               "shift_m": round(float(np.linalg.norm(m.position - built[i].position)), 4)}
              for i, m in sorted(moved.items())]
    diffs += [{"kind": "added", "class": a.class_id, **where_of(a), "designed_position": p(a.position),
               "built_position": None} for a in added]
    return {"as_designed": out.name, "design_differences": diffs}
