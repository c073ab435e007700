"""A simulated building: several floors stacked, one scan file per station (``sbsc simulate
--scenario building``).

Each storey is a floor in the style of Scenario I (neutral paints) or II (paints close to
the objects' colours), alternating bottom up, or the small one-room scene for tests. The
storeys vary: storey heights and slab thicknesses change from one to the next, and in
every second storey of the Scenario floors one room (``LOW_ROOM``) has a lower ceiling
than the others. A storey's floor stands on the slab above the storey below.

The slabs close every storey (no stairwell), so a station only sees its own storey and
each storey is ray cast on its own mesh. Every station is scanned and written on its own
(PLY, E57 or LAS), so the simulator's memory is one storey's mesh plus one station's
points, whatever the size of the building; ``angular_step_deg`` sets the density (0.1
degrees gives about 100 M points per Scenario floor).

The output folder holds ``stations/S<k>_<nnn>.<ext>`` (world coordinates),
``ground_truth.json`` (contract 5; objects and walls carry their ``storey``, wall ids are
prefixed with it, plus a top-level ``storeys`` list), ``expected.json`` (the building's counts
and each storey's, contract 3) and ``models/``.

The realism options of the one-floor simulator apply to every storey: ``realistic`` (the
realistic scanner per station, each station with its own registration error), ``clutter``
and ``furniture`` (laid out per storey, from ``(seed, storey number)``, so storeys differ;
the truth's ``distractors`` carry their ``storey``) and ``survey_frame`` (every station file
and the truth at UTM-like coordinates, see :mod:`survey`). With any of them the truth also
gives each object's ``visible_fraction`` and, with the realistic scanner, the stations'
``registration_errors``. All off, the output is that of the plain building.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_output_dir, write_json_atomic
from ..io.ply import write_ply
from ..paths import sample_projects_dir
from ..types import WallFrame
from . import mesh as M
from .building import (
    Building,
    ObjectBuilder,
    PlacedObject,
    _casing,
    _reveal,
    _rotation,
    add_distractors,
    add_surface_objects,
    sized_for,
    station_positions,
    wall_face_mesh,
)
from .catalogue import CLASS_ORDER
from .mesh import ColouredMesh
from .raycast import MeshRaycaster
from .realism import CLASS_GLOSS, pose_error_record, station_pose_error
from .scanner import ScannerSettings, scan_station
from .scene import SceneDescription, load_scene, outline_cells, parse_scene, validate_scene
from .survey import SurveyFrame

Log = Callable[[str], None]

FORMATS = ("ply", "e57", "las")
SCENES = ("scenario", "one_room")
MAX_STOREYS = 20
# per storey, cycling bottom up: floor-to-ceiling height (Scenario floors / one room) and slab thickness
STOREY_HEIGHTS_M: dict[str, tuple[float, ...]] = {"scenario": (3.0, 3.1, 3.2, 3.05),
                                                  "one_room": (2.8, 2.65, 2.9, 2.75)}
SLAB_M = (0.25, 0.30, 0.22, 0.35)
LOW_ROOM = ("R3", 0.3)  # in storeys S2, S4, ... of the Scenario floors this room's ceiling is lower by this


@dataclass(frozen=True)
class StoreyPlan:
    """One storey of the building: its floor description and where it stands."""

    id: str  # "S1", ...
    scene: SceneDescription  # the floor, built at z = 0 and lifted by ``floor_z``
    floor_z: float
    room_ceilings: dict[str, float]  # rooms whose ceiling is lower than the storey's
    number: int = 1  # 1 for S1, ...: with the seed, the key of the storey's clutter and furniture

    @property
    def height_m(self) -> float:
        return self.scene.ceiling_height_m


@dataclass
class BuildingSummary:
    out: Path
    storeys: int
    stations: int
    points: int
    objects: int
    walls: int
    angular_step_deg: float
    seconds: float
    files: list[Path]


def plan_building(storeys: int, scene: str = "scenario", object_builder: ObjectBuilder | None = None,
                  angular_step_deg: float | None = None, *, ceiling_objects: bool = False,
                  columns: bool = False, realistic: bool = False, clutter: bool = False,
                  furniture: bool = False, survey_frame: bool = False) -> list[StoreyPlan]:
    """The storeys of a ``storeys``-storey building of ``scene`` floors (see the module docstring).

    ``ceiling_objects`` and ``columns`` turn on the floors' objects beyond walls (:mod:`surfaces`);
    ``realistic``, ``clutter``, ``furniture`` and ``survey_frame`` the realism options of every
    floor with their defaults (:func:`~sbsc_core.simulate.scenarios.apply_realism`).
    """
    from .scenarios import apply_realism

    if not 1 <= storeys <= MAX_STOREYS:
        raise InputError("--storeys", f"must be 1..{MAX_STOREYS}, got {storeys}")
    if scene not in SCENES:
        raise InputError("--scene", f"unknown scene {scene!r} ({' or '.join(SCENES)})")
    plans = []
    z = 0.0
    ii_paints = None
    for k in range(storeys):
        height = STOREY_HEIGHTS_M[scene][k % len(STOREY_HEIGHTS_M[scene])]
        if scene == "one_room":
            floor = dataclasses.replace(load_scene(sample_projects_dir() / "one_room.yaml"), ceiling_height_m=height)
            low: dict[str, float] = {}
        else:
            from .scenarios import scenario_description, scenario_ii_paints

            variant = "I" if k % 2 == 0 else "II"
            data = scenario_description("I", object_builder)
            if variant == "II":
                ii_paints = ii_paints or scenario_ii_paints(object_builder)
                for room in data["rooms"]:
                    room["paint"] = list(ii_paints[room["id"]])
            data["name"] = f"storey S{k + 1} (Scenario {variant})"
            data["ceiling_height_m"] = height
            floor = parse_scene(data, f"storey S{k + 1}")
            low = {LOW_ROOM[0]: round(height - LOW_ROOM[1], 3)} if k % 2 == 1 else {}
        if angular_step_deg is not None:
            try:
                floor.scanner = floor.scanner.replace(angular_step_deg=float(angular_step_deg))
            except ValueError as exc:
                raise InputError("--step", str(exc)) from None
        floor.ceiling_objects = floor.ceiling_objects or ceiling_objects
        floor.columns = floor.columns or columns
        apply_realism(floor, realistic, clutter, furniture, survey_frame)
        plans.append(StoreyPlan(f"S{k + 1}", floor, round(z, 4), low, k + 1))
        z += height + SLAB_M[k % len(SLAB_M)]
    return plans


def build_storey(plan: StoreyPlan, object_builder: ObjectBuilder | None = None, *, seed: int = 0) -> Building:
    """Mesh, objects and stations of one storey, in world coordinates (lifted by its floor level).

    Rooms in ``plan.room_ceilings`` get walls up to their own ceiling and a ceiling of their
    own there; the storey's ceiling stays above it, out of sight. With the floor's clutter or
    furniture options, the distractors are laid out for ``(seed, plan.number)``.
    """
    if object_builder is None:
        from .objects import build_object as object_builder
    scene = sized_for(plan.scene, object_builder)
    layout = validate_scene(scene)
    for wid, wall in list(layout.walls.items()):
        if wall.room in plan.room_ceilings:
            frame = dataclasses.replace(wall.frame, height_m=plan.room_ceilings[wall.room])
            layout.walls[wid] = dataclasses.replace(wall, frame=frame)
    parts: list[ColouredMesh] = [_slabs(scene, plan.room_ceilings)]
    for wall in layout.walls.values():
        parts.append(wall_face_mesh(wall, layout.openings_on(wall.id)))
    first = {}
    for o in layout.openings:
        first.setdefault(o.spec_index, o)
        parts.append(_casing(layout.walls[o.wall].frame, o, scene))
    for o in first.values():
        parts.append(_reveal(layout.walls[o.wall].frame, o, scene))
    objects = []
    for p in scene.objects:
        wall = layout.walls[p.wall]
        spec = scene.specs[p.class_id]
        if p.v + spec.height_m / 2 > wall.frame.height_m:
            raise InputError(scene.source, f"object {p.class_id} on {p.wall} is above its room's ceiling")
        local = object_builder(p.class_id).glossy(CLASS_GLOSS.get(p.class_id, 0.0))  # gloss: realistic scanner only
        parts.append(local.transformed(_rotation(wall.frame), wall.frame.to_world(p.u, p.v)).labelled(p.index))
        objects.append(PlacedObject(p.index, p.class_id, p.wall, p.u, p.v, wall.frame.to_world(p.u, p.v),
                                    wall.frame.normal.copy(), spec.width_m, spec.height_m))
    stations = station_positions(scene)
    surfaces, columns = add_surface_objects(scene, layout, stations, object_builder, parts=parts, objects=objects,
                                            ceilings=plan.room_ceilings)
    distractors = add_distractors(scene, layout, stations, (seed, plan.number), parts)
    lift = np.array([0.0, 0.0, plan.floor_z])
    mesh = M.merge(parts).transformed(np.eye(3), lift)
    for o in objects:
        o.position = o.position + lift
        if o.frame is not None:
            o.frame = _lifted(o.frame, plan.floor_z)
    for wid, wall in list(layout.walls.items()):
        layout.walls[wid] = dataclasses.replace(wall, frame=_lifted(wall.frame, plan.floor_z))
    surfaces = [dataclasses.replace(sf, frame=_lifted(sf.frame, plan.floor_z)) for sf in surfaces]
    return Building(scene, layout, mesh, objects, stations + lift, distractors, surfaces=surfaces, columns=columns)


def _lifted(f: WallFrame, dz: float) -> WallFrame:
    return dataclasses.replace(f, origin=f.origin + np.array([0.0, 0.0, dz]))


def _slabs(scene: SceneDescription, room_ceilings: dict[str, float]) -> ColouredMesh:
    """Floor and ceiling over the floor plate, and the lower ceilings of some rooms."""
    pts = np.concatenate([np.asarray(r.outline, float) for r in scene.rooms])
    t = scene.exterior_wall_thickness_m
    x0, y0 = pts.min(axis=0) - t
    x1, y1 = pts.max(axis=0) + t
    h = scene.ceiling_height_m
    parts = [M.quad((x0, y0, 0.0), (x1 - x0, 0, 0), (0, y1 - y0, 0), scene.colours["floor"]),
             M.quad((x0, y0, h), (0, y1 - y0, 0), (x1 - x0, 0, 0), scene.colours["ceiling"])]
    for room in scene.rooms:
        if room.id in room_ceilings:
            hr = room_ceilings[room.id]
            for cx0, cy0, cx1, cy1 in outline_cells(room.outline):
                parts.append(M.quad((cx0, cy0, hr), (0, cy1 - cy0, 0), (cx1 - cx0, 0, 0), scene.colours["ceiling"]))
    return M.merge(parts)


# --------------------------------------------------------------------------- writing


def write_station(path: Path, xyz: np.ndarray, rgb: np.ndarray, origin: np.ndarray, *, fmt: str,
                  frame: SurveyFrame | None = None) -> None:
    """One station's points (world coordinates) as PLY, E57 (scanner frame + pose) or LAS 1.2.

    With a survey ``frame`` the points are written in it: PLY in double precision, LAS with
    its offset at the station (0.5 mm steps, as without), E57 in the scanner's own frame
    with the frame's turn and the station's survey position as its pose.
    """
    if fmt == "ply":
        if frame is None:
            write_ply(path, xyz, rgb)
        else:
            write_ply(path, frame.points(xyz), rgb, double=True)
    elif fmt == "las":
        import laspy

        if frame is not None:
            xyz, origin = frame.points(xyz), frame.points(np.asarray(origin, float).reshape(1, 3))[0]
        las = laspy.create(point_format=3, file_version="1.2")
        las.header.offsets = np.floor(np.asarray(origin, float))
        las.header.scales = [0.0005, 0.0005, 0.0005]
        las.x, las.y, las.z = (np.asarray(xyz, np.float64)).T
        rgb16 = rgb.astype(np.uint16) * np.uint16(257)
        las.red, las.green, las.blue = rgb16.T
        las.write(path)
    elif fmt == "e57":
        import pye57

        local = np.asarray(xyz, np.float64) - np.asarray(origin, np.float64)
        rotation, translation = np.array([1.0, 0.0, 0.0, 0.0]), np.asarray(origin, float)
        if frame is not None:  # pose: the frame's turn about z (w, x, y, z) and the station in the frame
            half = np.radians(frame.rotation_deg) / 2
            rotation = np.array([np.cos(half), 0.0, 0.0, np.sin(half)])
            translation = frame.points(translation.reshape(1, 3))[0]
        with pye57.E57(str(path), mode="w") as e:
            e.write_scan_raw({"cartesianX": local[:, 0].copy(), "cartesianY": local[:, 1].copy(),
                              "cartesianZ": local[:, 2].copy(), "colorRed": rgb[:, 0].copy(),
                              "colorGreen": rgb[:, 1].copy(), "colorBlue": rgb[:, 2].copy()},
                             rotation=rotation, translation=translation)
    else:
        raise InputError("--format", f"unknown format {fmt!r} ({', '.join(FORMATS)})")


def simulate_building(out: Path, storeys: int = 2, *, scene: str = "scenario", fmt: str = "ply", seed: int = 0,
                      angular_step_deg: float | None = None, log: Log | None = None,
                      object_builder: ObjectBuilder | None = None, ceiling_objects: bool = False,
                      columns: bool = False, realistic: bool = False, clutter: bool = False,
                      furniture: bool = False, survey_frame: bool = False) -> BuildingSummary:
    """Build, scan and write a ``storeys``-storey building into ``out`` (see the module docstring).

    Everything is written into a temporary folder beside ``out`` and moved in at the end.
    Deterministic for a seed; station ``k`` (counted over the whole building) draws its
    noise from ``[seed, k]``. ``ceiling_objects`` and ``columns``: see :mod:`surfaces`; the
    truth then gives each object's ``surface`` and lists ``surfaces`` and ``columns`` (ids
    prefixed by the storey, like the walls'). Off, nothing changes.

    ``realistic``, ``clutter``, ``furniture`` and ``survey_frame``: see the module docstring
    and :func:`~sbsc_core.simulate.scenarios.simulate_scene`. Station ``k``'s registration
    error is drawn from ``[seed, k]`` like its noise; ``registration_errors`` name each
    station's index in ``stations``, its storey and its file.
    """
    t0 = time.perf_counter()
    say = log or (lambda msg: None)
    if fmt not in FORMATS:
        raise InputError("--format", f"unknown format {fmt!r} ({', '.join(FORMATS)})")
    plans = plan_building(storeys, scene, object_builder, angular_step_deg, ceiling_objects=ceiling_objects,
                          columns=columns, realistic=realistic, clutter=clutter, furniture=furniture,
                          survey_frame=survey_frame)
    effects = plans[0].scene.effects
    realism = plans[0].scene.realistic
    spec = plans[0].scene.survey_frame
    frame = SurveyFrame(spec.offset, spec.rotation_deg) if spec is not None else None
    truth_distractors: list[dict] = []
    registration: list[dict] = []
    truth_surfaces: list[dict] = []
    truth_columns: list[dict] = []
    ext = {"ply": ".ply", "e57": ".e57", "las": ".las"}[fmt]
    truth_objects: list[dict] = []
    truth_walls: list[dict] = []
    truth_openings: list[dict] = []
    stations_all: list[list[float]] = []
    counts = dict.fromkeys(CLASS_ORDER, 0)
    files: list[Path] = []
    n_points = n_station = 0
    settings: ScannerSettings = plans[0].scene.scanner
    with atomic_output_dir(out) as tmp:
        (tmp / "stations").mkdir()
        for plan in plans:
            b = build_storey(plan, object_builder, seed=seed)
            settings = plan.scene.scanner
            say(f"{plan.id}: floor z = {plan.floor_z:.2f} m, {plan.height_m:.2f} m high"
                + (f", lower ceilings {plan.room_ceilings}" if plan.room_ceilings else "")
                + f"; {len(b.layout.walls)} walls, {len(b.objects)} objects, "
                + (f"{len(b.distractors)} distractors, " if b.distractors else "")
                + f"{len(b.stations)} stations at {settings.angular_step_deg:g} deg"
                + (" with the realistic scanner" if effects else ""))
            rc = MeshRaycaster(b.mesh, chunk=int(settings.chunk_rays))
            for k, origin in enumerate(b.stations):
                xyz, rgb, _, _ = scan_station(rc, origin, settings, seed, n_station, effects=effects)
                path = tmp / "stations" / f"{plan.id}_{k + 1:03d}{ext}"
                write_station(path, xyz, rgb, origin, fmt=fmt, frame=frame)
                if effects is not None:
                    registration.append(_registration_error(seed, n_station, effects, plan.id, path.name))
                files.append(out / "stations" / path.name)
                n_points += len(xyz)
                n_station += 1
                say(f"{plan.id} station {k + 1}/{len(b.stations)}: {len(xyz):,} points")
                del xyz, rgb
            fractions = [None] * len(b.objects)
            if realism:
                from .visibility import visible_fractions

                fractions = [round(f, 4) for f in visible_fractions(b, settings, rc)]
            del rc
            for o, frac in zip(b.objects, fractions, strict=True):
                counts[o.class_id] = counts.get(o.class_id, 0) + 1
                truth_objects.append({**o.to_truth(), "wall": f"{plan.id}-{o.wall}", "storey": plan.id,
                                      **({"surface": o.surface} if ceiling_objects or columns else {}),
                                      **({"visible_fraction": frac} if frac is not None else {})})
            truth_distractors += [{**d.to_truth(b.layout), "wall": f"{plan.id}-{d.wall}", "storey": plan.id}
                                  for d in b.distractors]
            for sf in b.surfaces:
                d = sf.to_dict(digits=6)
                truth_surfaces.append({**d, "id": f"{plan.id}-{sf.id}", "storey": plan.id,
                                       **({"column": f"{plan.id}-{sf.column}"} if sf.column else {})})
            for c in b.columns:
                d = c.to_truth()
                truth_columns.append({**d, "id": f"{plan.id}-{c.id}", "storey": plan.id,
                                      "floor_z": plan.floor_z, "faces": [f"{plan.id}-{f}" for f in c.faces]})
            truth_walls += [{"id": f"{plan.id}-{w.id}", "room": w.room, "storey": plan.id, **w.frame.to_dict()}
                            for w in b.layout.walls.values()]
            truth_openings += [{**o.to_dict(), "wall": f"{plan.id}-{o.wall}"} for o in b.layout.openings]
            stations_all += [[round(float(x), 4) for x in s] for s in b.stations]
        storeys_doc = [{"id": p.id, "floor_z": p.floor_z, "ceiling_z": round(p.floor_z + p.height_m, 4),
                        "room_ceilings": {r: round(p.floor_z + h, 4) for r, h in p.room_ceilings.items()},
                        "scene": p.scene.name} for p in plans]
        truth = {
            "schema": "sbsc.truth/1", "scene": f"building of {storeys} {scene} storeys",
            "storeys": storeys_doc, "objects": truth_objects, "walls": truth_walls,
            "openings": truth_openings, "stations": stations_all,
            **({"surfaces": truth_surfaces, "columns": truth_columns} if ceiling_objects or columns else {}),
            **({"distractors": truth_distractors} if clutter or furniture or truth_distractors else {}),
            **({"registration_errors": registration} if effects is not None else {})}
        if frame is not None:
            truth = frame.truth(truth)
        write_json_atomic(tmp / "ground_truth.json", truth)
        per_storey: dict[str, dict[str, int]] = {p.id: {} for p in plans}  # contract 3's optional storeys
        for o in truth_objects:
            per_storey[o["storey"]][o["class"]] = per_storey[o["storey"]].get(o["class"], 0) + 1
        write_json_atomic(tmp / "expected.json", {"schema": "sbsc.expected/1",
                                                  "counts": {c: n for c, n in counts.items() if n},
                                                  "storeys": per_storey})
        from .library import write_model_library

        if object_builder is None:
            write_model_library(tmp / "models", seed=seed)
        else:
            write_model_library(tmp / "models", seed=seed, object_builder=object_builder)
    seconds = time.perf_counter() - t0
    say(f"{n_points:,} points from {n_station} stations in {seconds:.1f} s")
    return BuildingSummary(Path(out), storeys, n_station, n_points, len(truth_objects), len(truth_walls),
                           settings.angular_step_deg, seconds, files)


def _registration_error(seed: int, station: int, effects, storey: str, name: str) -> dict:
    """The truth's record of station ``station``'s registration error (as the scanner drew it)."""
    record = pose_error_record(station, *station_pose_error(seed, station, effects))
    return {"station": station, "storey": storey, "file": f"stations/{name}",
            "translation_m": record["translation_m"], "rotation_deg": record["rotation_deg"]}
