"""The paper's simulated Scenarios I and II (section 5.1) and ``sbsc simulate``.

Scenario I is a floor of 22.9 m x 19.4 m with four rooms and a corridor; 116 objects in
Table 1's numbers sit on 24 of its 28 walls, which are painted in neutral colours.
Scenario II is the same floor with the walls repainted close to the objects' colours (the
paper: down to 1.56 % mean RGB difference, for the electrical panel).

The two shipped descriptions ``sbsc_core/data/scenario_I.yaml`` and ``scenario_II.yaml``
are written by :func:`write_scenario_files` from :func:`scenario_description` and kept
under version control; regenerate them with ``python -m sbsc_core.simulate.scenarios``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ..errors import InputError
from ..io.atomic import atomic_output_dir, write_json_atomic
from ..io.ply import write_ply
from ..paths import sample_projects_dir
from .building import Building, ObjectBuilder, build_building, plan_stations
from .catalogue import CATALOGUE, CLASS_ORDER
from .mesh import ColouredMesh
from .scanner import ScannerSettings, WallView, scan_mesh, wall_view
from .scene import RoomSpec, SceneDescription, build_layout, load_scene, parse_scene

Log = Callable[[str], None]


@dataclass
class SimulationSummary:
    out: Path
    scene: str
    points: int
    rays: int
    stations: int
    objects: int
    walls: int
    angular_step_deg: float
    seconds: float
    counts: dict[str, int]


# --------------------------------------------------------------------------- simulate


REALISM_OPTIONS = ("realistic", "clutter", "furniture", "survey_frame")
SURFACE_OPTIONS = ("ceiling_objects", "columns")  # objects beyond walls (surfaces.py)


def simulate_scenario(scenario: str, out: Path, *, seed: int = 0, angular_step_deg: float | None = None,
                      log: Log | None = None, object_builder: ObjectBuilder | None = None,
                      library_builder: ObjectBuilder | None = None, **realism: bool) -> SimulationSummary:
    """Scan the shipped Scenario ``"I"`` or ``"II"`` into ``out`` (see :func:`simulate_scene`)."""
    if scenario not in ("I", "II"):
        raise InputError("--scenario", f"unknown scenario {scenario!r} (I or II)")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise InputError("--seed", f"expected a whole number from 0 to 2**63-1, got {seed!r}")
    path = sample_projects_dir() / f"scenario_{scenario}.yaml"
    return simulate_scene(path, out, seed=seed, angular_step_deg=angular_step_deg, log=log,
                          object_builder=object_builder, library_builder=library_builder, **realism)


def apply_realism(scene: SceneDescription, realistic: bool = False, clutter: bool = False,
                  furniture: bool = False, survey_frame: bool = False) -> SceneDescription:
    """Turn on realism options with their defaults where the description leaves them off.

    ``realistic``: the realistic scanner with published defaults (:class:`ScanEffects`);
    ``clutter``: 0.4 wall items per metre of wall; ``furniture``: 0.15 pieces per metre;
    ``survey_frame``: a UTM-like frame at (412000, 5612000, 100) m turned by 23.5 degrees.
    """
    from .realism import ScanEffects
    from .scene import SurveyFrameSpec
    from .survey import DEFAULT_ROTATION_DEG, UTM_LIKE_OFFSET

    if realistic and scene.effects is None:
        scene.effects = ScanEffects()
    if clutter and not scene.clutter_per_metre:
        scene.clutter_per_metre = 0.4
    if furniture and not scene.furniture_per_metre:
        scene.furniture_per_metre = 0.15
    if survey_frame and scene.survey_frame is None:
        scene.survey_frame = SurveyFrameSpec(UTM_LIKE_OFFSET, DEFAULT_ROTATION_DEG)
    return scene


def simulate_scene(description_path: Path, out: Path, *, seed: int = 0, angular_step_deg: float | None = None,
                   log: Log | None = None, object_builder: ObjectBuilder | None = None,
                   design: bool = True, library_builder: ObjectBuilder | None = None,
                   realistic: bool = False, clutter: bool = False, furniture: bool = False,
                   survey_frame: bool = False, ceiling_objects: bool = False,
                   columns: bool = False, station_index: bool | None = None) -> SimulationSummary:
    """Build the described floor, scan it and write contracts 1, 2, 3 and 5 into ``out``.

    ``out`` receives ``scan.ply`` (float32 xyz, uchar colour; with ``station_index`` a
    ``scan_index`` ushort, each point's station, the stations one after the other, as a
    merging tool keeps it), ``ground_truth.json``,
    ``expected.json``, ``models/`` and, with ``design``, ``as_designed.ifc``: the as-designed
    model with a few objects deliberately moved, removed or added, listed in the ground truth
    under ``design_differences`` (for measuring ``sbsc compare``). Everything is written into a temporary directory
    and moved in at the end, so a failure leaves ``out`` as it was. Deterministic for a seed.

    ``object_builder`` is the design set the objects are built with (default: the standard
    designs; see :mod:`designs`). The model library in ``models/`` is rendered with the same
    designs unless ``library_builder`` names another set (a cross-design test: scene in one
    set, models in another).

    The realism options (``realistic``, ``clutter``, ``furniture``, ``survey_frame``; or the
    description's ``realism``, ``clutter``, ``furniture``, ``survey_frame`` keys) add the
    realistic scanner, wall clutter and furniture (the truth's ``distractors``), and write
    scan and truth in a survey frame; with any of them the truth also records each
    object's ``visible_fraction`` and the stations' ``registration_errors``. All off, the
    output is that of the plain simulator.

    ``ceiling_objects`` and ``columns`` (or the description's keys of the same names) add
    smoke detectors and exit lights on the ceilings and free-standing columns with objects
    on their faces (:mod:`surfaces`); the truth then gives each object's ``surface`` and
    lists ``surfaces`` and ``columns``. Off, nothing changes.

    ``station_index`` None writes the stations when the scanner has a registration error
    (the realistic scanner): then ``sbsc detect`` refines the merged file's registration
    (:mod:`sbsc_core.io.merged_stations`). A scan without registration error is written as
    before, so its detection does not spend the refinement's time on a registration that
    has nothing to refine.

    Parameters
    ----------
    description_path
        A scene description (YAML; ``sbsc_core/data/*.yaml`` are the shipped ones).
    out
        The output folder (made; must not hold another run).
    seed
        Makes the scan, the noise and the design differences (0 <= seed < 2**63).
    angular_step_deg
        The scanner's angular step; None: the description's.
    log
        Called with a line per station.

    Returns
    -------
    SimulationSummary
        What was written: points, objects per class, seconds.
    """
    t0 = time.perf_counter()
    say = log or (lambda msg: None)
    scene = apply_realism(load_scene(description_path), realistic, clutter, furniture, survey_frame)
    scene.ceiling_objects = scene.ceiling_objects or ceiling_objects
    scene.columns = scene.columns or columns
    settings = scene.scanner
    if angular_step_deg is not None:
        try:
            settings = settings.replace(angular_step_deg=float(angular_step_deg))
        except ValueError as exc:
            raise InputError("--step", str(exc)) from None
        scene.scanner = settings
    building = build_building(scene, object_builder, seed=seed)
    say(f"{scene.source}: {len(building.layout.walls)} walls, {len(building.objects)} objects, "
        f"{len(building.distractors)} distractors, "
        + (f"{len(building.columns)} columns, {sum(o.surface != 'wall' for o in building.objects)} objects "
           "on ceilings and columns, " if building.surfaces else "")
        + f"{building.mesh.n_triangles:,} triangles; scanning from "
        f"{len(building.stations)} stations at {settings.angular_step_deg:g} deg"
        + (" with the realistic scanner" if scene.effects else ""))
    from .raycast import MeshRaycaster

    rc = MeshRaycaster(building.mesh, chunk=int(settings.chunk_rays))
    if station_index is None:
        e = scene.effects
        station_index = e is not None and (e.registration_translation_m > 0 or e.registration_rotation_deg > 0)
    scan = scan_mesh(building.mesh, building.stations, settings, seed=seed, log=log, raycaster=rc,
                     effects=scene.effects, keep_station=station_index)
    say(f"{len(scan):,} points from {scan.rays:,} rays; writing {out}")
    truth = building.truth_document()
    if scene.realistic:
        from .visibility import visible_fractions

        for obj, frac in zip(truth["objects"], visible_fractions(building, settings, rc), strict=True):
            obj["visible_fraction"] = round(frac, 4)
        if scan.pose_errors is not None:
            from .realism import pose_error_record

            truth["registration_errors"] = [pose_error_record(k, r, t) for k, (r, t) in enumerate(scan.pose_errors)]
    frame = None
    if scene.survey_frame is not None:
        from .survey import SurveyFrame

        frame = SurveyFrame(scene.survey_frame.offset, scene.survey_frame.rotation_deg)
        truth = frame.truth(truth)
    with atomic_output_dir(out) as tmp:
        if frame is None:
            write_ply(tmp / "scan.ply", scan.xyz, scan.rgb, station=scan.station)
        else:
            write_ply(tmp / "scan.ply", frame.points(scan.xyz), scan.rgb, double=True, station=scan.station)
        n_points, n_rays = len(scan), scan.rays
        del scan
        if design:
            from ..bim.design_writer import write_as_designed_ifc

            res = write_as_designed_ifc(truth, tmp / "as_designed.ifc", seed=seed,
                                        mount_heights={c: spec.mount_height_m for c, spec in CATALOGUE.items()})
            truth["as_designed"] = res["as_designed"]
            truth["design_differences"] = res["design_differences"]
        write_json_atomic(tmp / "ground_truth.json", truth)
        expected = building.expected_document()
        write_json_atomic(tmp / "expected.json", expected)
        from .library import write_model_library

        lib_builder = library_builder or object_builder
        if lib_builder is None:
            write_model_library(tmp / "models", seed=seed)
        else:
            write_model_library(tmp / "models", seed=seed, object_builder=lib_builder)
    seconds = time.perf_counter() - t0
    say(f"done in {seconds:.1f} s")
    return SimulationSummary(Path(out), scene.name, n_points, n_rays, len(building.stations),
                             len(building.objects), len(building.layout.walls), settings.angular_step_deg,
                             seconds, expected["counts"])


# --------------------------------------------------------------------------- the floor

FOOTPRINT_M = (22.9, 19.4)
CEILING_M = 3.0
EXTERIOR_M = 0.25  # exterior wall thickness
STATION_SPACING_M: dict[str, float] = {"R1": 4.0, "R2": 4.0, "R3": 4.0, "R4": 4.0, "C": 3.0}

# Rooms (free space) inside the 22.9 x 19.4 m plate; partitions are 0.15 m thick.
ROOM_OUTLINES: dict[str, list[tuple[float, float]]] = {
    "R1": [(0.25, 10.75), (10.25, 10.75), (10.25, 19.15), (0.25, 19.15)],
    "R2": [(12.55, 10.75), (22.65, 10.75), (22.65, 16.15), (19.45, 16.15), (19.45, 19.15), (12.55, 19.15)],
    "R3": [(0.25, 0.25), (8.35, 0.25), (8.35, 8.45), (0.25, 8.45)],
    "R4": [(8.5, 0.25), (18.35, 0.25), (18.35, 3.4), (22.65, 3.4), (22.65, 8.45), (8.5, 8.45)],
    "C": [(0.25, 8.6), (22.65, 8.6), (22.65, 10.6), (12.4, 10.6), (12.4, 19.15), (10.4, 19.15),
          (10.4, 10.6), (0.25, 10.6)],
}

# Scenario I: neutral paints, a different one per room.
PAINT_I: dict[str, tuple[int, int, int]] = {
    "R1": (226, 214, 188), "R2": (172, 176, 180), "R3": (230, 220, 196), "R4": (178, 176, 168),
    "C": (214, 200, 168),
}

DOOR = (0.9, 2.1)  # interior door width, height
EXIT_DOOR = (1.0, 2.1)
WINDOW = (1.5, 1.3, 0.9)  # width, height, sill

# (wall, u, kind); doors through partitions are given on one face only.
OPENINGS: list[tuple[str, float, str]] = [
    ("C-N1", 5.75, "door"), ("C-W2", 5.4, "door"), ("C-E2", 6.15, "door"), ("C-N3", 4.6, "door"),
    ("C-S", 18.65, "door"), ("C-S", 8.65, "door"), ("R3-E", 6.45, "door"),
    ("C-W1", 1.0, "exit"), ("C-N2", 1.0, "exit"), ("C-E1", 1.0, "exit"),
    ("R1-N", 2.5, "window"), ("R1-N", 7.5, "window"), ("R1-W", 4.2, "window"),
    ("R2-N1", 2.0, "window"), ("R2-N1", 5.0, "window"), ("R2-E1", 2.7, "window"),
    ("R3-S", 2.0, "window"), ("R3-S", 6.0, "window"), ("R3-W", 4.1, "window"),
    ("R4-S1", 2.5, "window"), ("R4-S1", 7.0, "window"), ("R4-E2", 2.5, "window"),
]

# Objects per wall: (class, u) at the class's catalogue height, or (class, u, v).
_SMOKE_V = 2.6
_EXT_V, _EXT_SIGN_V = 1.2, 1.95
_FAS_V, _FAS_SIGN_V = 1.4, 1.75
_EXIT_LIGHT_V = 2.26
OBJECTS: dict[str, list[tuple]] = {
    "R1-N": [("radiator", 2.5), ("radiator", 7.5), ("socket_x1", 0.8), ("socket_x2", 4.5),
             ("socket_x4", 9.3), ("builtin_socket", 5.5), ("smoke_detector", 5.0, _SMOKE_V),
             ("fire_alarm_switch", 5.0, _FAS_V), ("fire_alarm_switch_sign", 5.0, _FAS_SIGN_V)],
    "R1-E": [("switch", 3.85), ("fire_extinguisher", 6.5, _EXT_V), ("extinguisher_sign", 6.5, _EXT_SIGN_V),
             ("socket_x1", 1.0), ("socket_x1", 5.0), ("socket_x4", 7.5)],
    "R1-S": [("switch", 4.95), ("switch", 5.05), ("smoke_detector", 8.0, _SMOKE_V), ("socket_x1", 1.5),
             ("socket_x2", 7.0), ("builtin_socket", 9.0)],
    "R1-W": [("electrical_panel", 1.2), ("socket_x1", 2.0), ("socket_x4", 6.5)],
    "R2-S": [("switch", 6.35), ("fire_extinguisher", 2.0, _EXT_V), ("extinguisher_sign", 2.0, _EXT_SIGN_V),
             ("socket_x1", 1.0), ("socket_x4", 3.5), ("socket_x1", 8.5)],
    "R2-E1": [("socket_x1", 1.0), ("socket_x2", 4.5)],
    "R2-N1": [("radiator", 2.0), ("socket_x4", 3.5), ("builtin_socket", 6.3), ("smoke_detector", 3.5, _SMOKE_V)],
    "R2-W": [("switch", 2.95), ("smoke_detector", 6.0, _SMOKE_V), ("electrical_panel", 7.2),
             ("socket_x1", 1.0), ("socket_x1", 4.5)],
    "R3-N": [("switch", 4.45), ("fire_extinguisher", 6.5, _EXT_V), ("extinguisher_sign", 6.5, _EXT_SIGN_V),
             ("socket_x1", 1.5), ("socket_x4", 6.0)],
    "R3-E": [("switch", 5.75), ("smoke_detector", 3.0, _SMOKE_V), ("socket_x1", 1.5), ("builtin_socket", 4.5)],
    "R3-S": [("radiator", 2.0), ("socket_x1", 4.0), ("socket_x2", 7.5)],
    "R3-W": [("smoke_detector", 6.5, _SMOKE_V), ("socket_x1", 1.5), ("socket_x4", 6.5)],
    "R4-N": [("switch", 6.2), ("switch", 6.3), ("fire_extinguisher", 12.0, _EXT_V),
             ("extinguisher_sign", 12.0, _EXT_SIGN_V), ("smoke_detector", 10.0, _SMOKE_V),
             ("socket_x1", 2.0), ("socket_x4", 9.0), ("socket_x1", 13.0), ("socket_x2", 11.0)],
    "R4-W": [("switch", 2.45), ("electrical_panel", 6.5), ("socket_x1", 4.0), ("builtin_socket", 7.5)],
    "R4-S1": [("radiator", 2.5), ("smoke_detector", 4.7, _SMOKE_V), ("socket_x4", 5.0), ("socket_x1", 9.0)],
    "R4-E2": [("radiator", 2.5), ("fire_alarm_switch", 1.0, _FAS_V),
              ("fire_alarm_switch_sign", 1.0, _FAS_SIGN_V), ("socket_x1", 4.3), ("socket_x2", 0.8)],
    "C-S": [("switch", 9.35), ("switch", 19.35), ("electrical_panel", 12.5),
            ("fire_extinguisher", 3.0, _EXT_V), ("extinguisher_sign", 3.0, _EXT_SIGN_V),
            ("fire_extinguisher", 14.5, _EXT_V), ("extinguisher_sign", 14.5, _EXT_SIGN_V),
            ("smoke_detector", 4.0, _SMOKE_V), ("fire_alarm_switch", 6.0, _FAS_V),
            ("fire_alarm_switch_sign", 6.0, _FAS_SIGN_V), ("socket_x1", 1.0), ("socket_x4", 11.0),
            ("builtin_socket", 21.0)],
    "C-N1": [("switch", 6.45), ("smoke_detector", 2.5, _SMOKE_V), ("fire_extinguisher", 2.0, _EXT_V),
             ("extinguisher_sign", 2.0, _EXT_SIGN_V)],
    "C-N3": [("switch", 5.3), ("fire_extinguisher", 8.5, _EXT_V), ("extinguisher_sign", 8.5, _EXT_SIGN_V),
             ("fire_alarm_switch", 1.0, _FAS_V), ("fire_alarm_switch_sign", 1.0, _FAS_SIGN_V),
             ("socket_x4", 2.5)],
    "C-E2": [("switch", 6.85), ("fire_extinguisher", 2.5, _EXT_V), ("extinguisher_sign", 2.5, _EXT_SIGN_V)],
    "C-W2": [("switch", 6.1), ("fire_alarm_switch", 7.5, _FAS_V), ("fire_alarm_switch_sign", 7.5, _FAS_SIGN_V)],
    "C-W1": [("exit_light", 1.0, _EXIT_LIGHT_V), ("fire_alarm_switch", 1.8, _FAS_V),
             ("fire_alarm_switch_sign", 1.8, _FAS_SIGN_V)],
    "C-N2": [("exit_light", 1.0, _EXIT_LIGHT_V), ("fire_alarm_switch", 1.8, _FAS_V),
             ("fire_alarm_switch_sign", 1.8, _FAS_SIGN_V)],
    "C-E1": [("exit_light", 1.0, _EXIT_LIGHT_V), ("fire_alarm_switch", 1.8, _FAS_V),
             ("fire_alarm_switch_sign", 1.8, _FAS_SIGN_V)],
}


def scenario_description(scenario: str, object_builder: ObjectBuilder | None = None) -> dict:
    """The scene description of Scenario ``"I"`` or ``"II"`` as a plain mapping (deterministic)."""
    if scenario not in ("I", "II"):
        raise ValueError(f"unknown scenario {scenario!r}")
    paints = dict(PAINT_I) if scenario == "I" else scenario_ii_paints(object_builder)
    rooms = [{"id": rid, "outline": [[x, y] for x, y in pts], "paint": list(paints[rid])}
             for rid, pts in ROOM_OUTLINES.items()]
    openings = []
    for wall, u, kind in OPENINGS:
        if kind == "window":
            w, h, sill = WINDOW
            openings.append({"wall": wall, "kind": "window", "u": u, "width_m": w, "height_m": h, "sill_m": sill})
        else:
            w, h = EXIT_DOOR if kind == "exit" else DOOR
            openings.append({"wall": wall, "kind": "door", "u": u, "width_m": w, "height_m": h})
    objects = []
    for wall, items in OBJECTS.items():
        for item in sorted(items, key=lambda it: (it[1], it[2] if len(it) > 2 else CATALOGUE[it[0]].mount_height_m)):
            cls, u = item[0], item[1]
            v = item[2] if len(item) > 2 else CATALOGUE[cls].mount_height_m
            objects.append({"class": cls, "wall": wall, "u": u, "v": v})
    stations = []
    for rid, pts in ROOM_OUTLINES.items():
        room = RoomSpec(rid, tuple(pts), (0, 0, 0))
        for k, (x, y) in enumerate(plan_stations(room, STATION_SPACING_M[rid])):
            # a little deterministic jitter so that stations do not line up exactly
            dx, dy = 0.1 * np.sin(1.7 * k + len(rid)), 0.1 * np.cos(2.3 * k + len(rid))
            stations.append({"room": rid, "xy": [round(float(x + dx), 3), round(float(y + dy), 3)],
                             "height_m": 1.5})
    return {
        "schema": "sbsc.scene/1",
        "name": f"Scenario {scenario}",
        "ceiling_height_m": CEILING_M,
        "exterior_wall_thickness_m": EXTERIOR_M,
        "door_frame_width_m": 0.07,
        "colours": {"floor": [128, 120, 110], "ceiling": [240, 240, 236], "door_frame": [96, 70, 50],
                    "window_frame": [70, 74, 80]},
        "rooms": rooms,
        "openings": openings,
        "objects": objects,
        "stations": stations,
        "scanner": {"angular_step_deg": ScannerSettings().angular_step_deg},
    }


# --------------------------------------------------------------------------- Scenario II paints

# Which object class each room's paint is matched to in Scenario II, and how far the paint
# is from that class's colour: the mean over R, G, B of |paint - object| in 8-bit levels
# (4 levels = 1.57 %, the paper's minimum, reached by the electrical panel).
SCENARIO_II_MATCH: dict[str, tuple[str, int]] = {
    "R1": ("electrical_panel", 4), "R2": ("electrical_panel", 5), "R3": ("socket_x1", 5),
    "R4": ("electrical_panel", 4), "C": ("electrical_panel", 6),
}


def dominant_colour(mesh: ColouredMesh, step_m: float = 0.002) -> np.ndarray:
    """The colour an object mostly shows seen straight on: per-channel median over its front.

    The front view is ray cast orthographically (rays along -z on a ``step_m`` grid over the
    object's footprint), so hidden faces do not count and textures count as drawn.
    """
    from .raycast import MeshRaycaster

    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    xs = np.arange(lo[0] + step_m / 2, hi[0], step_m)
    ys = np.arange(lo[1] + step_m / 2, hi[1], step_m)
    gx, gy = np.meshgrid(xs, ys)
    origins = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, hi[2] + 0.1)])
    dirs = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    hits = MeshRaycaster(mesh).cast(origins, dirs)
    return np.median(hits.rgb[hits.hit].astype(float), axis=0)


def object_colours(object_builder: ObjectBuilder | None = None) -> dict[str, np.ndarray]:
    """The dominant front colour of every class, as built."""
    if object_builder is None:
        from .objects import build_object as object_builder
    return {c: dominant_colour(object_builder(c)) for c in CLASS_ORDER}


def mean_rgb_difference(a, b) -> float:
    """The paper's colour distance: mean over R, G, B of |a - b|, as a fraction of 255."""
    return float(np.mean(np.abs(np.asarray(a, float) - np.asarray(b, float))) / 255.0)


def scenario_ii_paints(object_builder: ObjectBuilder | None = None) -> dict[str, tuple[int, int, int]]:
    """Room paints close to the objects' colours (paper, Scenario II).

    Each room's paint lies exactly ``SCENARIO_II_MATCH`` levels (mean over R, G, B) from its
    reference class and, among such paints, as far as possible from every other class on
    the room's walls, so that the reference class has the smallest contrast.
    """
    colours = object_colours(object_builder)
    classes_in = {rid: sorted({item[0] for wall, items in OBJECTS.items() if wall.split("-")[0] == rid
                               for item in items}) for rid in ROOM_OUTLINES}
    offsets = np.stack(np.meshgrid(*[np.arange(-12, 13)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    paints = {}
    for rid, (ref_cls, levels) in SCENARIO_II_MATCH.items():
        ref = np.rint(colours[ref_cls]).astype(int)
        cand = ref + offsets[np.abs(offsets).sum(axis=1) == 3 * levels]
        cand = cand[np.all((cand >= 0) & (cand <= 255), axis=1)]
        others = [np.rint(colours[c]).astype(int) for c in classes_in[rid] if c != ref_cls]
        worst = np.min([np.abs(cand - o).mean(axis=1) for o in others], axis=0) if others else np.full(len(cand), 99.0)
        ok = worst >= levels  # the reference class keeps the smallest contrast
        cand, worst = (cand[ok], worst[ok]) if ok.any() else (cand, worst)
        tint = np.abs(cand - ref).max(axis=1)  # prefer an even shift (a grey change) to a tint
        order = np.lexsort((cand[:, 2], cand[:, 1], cand[:, 0], -worst, tint))
        paints[rid] = tuple(int(x) for x in cand[order[0]])
    return paints


def colour_contrast(scene: SceneDescription, object_builder: ObjectBuilder | None = None
                    ) -> list[tuple[float, str, str]]:
    """(mean RGB difference, class, wall) for every object of a scene, smallest first."""
    layout = build_layout(scene)
    colours = object_colours(object_builder)
    out = [(mean_rgb_difference(colours[p.class_id], layout.walls[p.wall].paint), p.class_id, p.wall)
           for p in scene.objects]
    return sorted(out)


# --------------------------------------------------------------------------- files


def scenario_yaml(scenario: str, object_builder: ObjectBuilder | None = None) -> str:
    """The text of ``scenario_<X>.yaml``."""
    data = scenario_description(scenario, object_builder)
    parse_scene(data, f"scenario_{scenario}.yaml")  # fail early on a broken generator
    head = (f"# Scenario {scenario} of Adan et al. (2018), section 5.1: a 22.9 m x 19.4 m floor, four rooms\n"
            "# and a corridor, 116 objects on 24 walls (Table 1 counts).\n"
            + ("# Walls in neutral paints.\n" if scenario == "I" else
               "# Walls repainted close to the objects' colours (minimum colour contrast).\n")
            + "# Generated by sbsc_core.simulate.scenarios.write_scenario_files(); do not edit by hand.\n")
    body = ""
    for key, value in data.items():
        if isinstance(value, list):
            body += f"{key}:\n"
            for item in value:
                body += "  - " + yaml.safe_dump(item, default_flow_style=True, sort_keys=False, width=1000).strip() + "\n"
        else:
            body += yaml.safe_dump({key: value}, default_flow_style=None if isinstance(value, dict) else False,
                                   sort_keys=False, width=1000)
    return head + body


def write_scenario_files(directory: Path | None = None, object_builder: ObjectBuilder | None = None) -> list[Path]:
    """(Re)write ``scenario_I.yaml`` and ``scenario_II.yaml``."""
    directory = Path(directory) if directory else sample_projects_dir()
    paths = []
    for sc in ("I", "II"):
        path = directory / f"scenario_{sc}.yaml"
        path.write_text(scenario_yaml(sc, object_builder), encoding="utf-8")
        load_scene(path)
        paths.append(path)
    return paths


def summary_text(building: Building) -> str:
    counts = building.expected_document()["counts"]
    walls_with = len({o.wall for o in building.objects})
    return (f"{len(building.objects)} objects on {walls_with} of {len(building.layout.walls)} walls: "
            + ", ".join(f"{c} {n}" for c, n in counts.items()))


# --------------------------------------------------------------------------- looking at walls


def wall_images(view: WallView, depth_range_m: tuple[float, float] = (-0.01, 0.12)) -> tuple[np.ndarray, np.ndarray]:
    """RGB images of a wall view: colour (no data black) and depth (viridis, no data white)."""
    import cv2

    colour = view.colour.copy()
    d = np.clip((view.depth - depth_range_m[0]) / (depth_range_m[1] - depth_range_m[0]), 0, 1)
    grey = np.nan_to_num(d * 255, nan=0).astype(np.uint8)
    depth = cv2.applyColorMap(grey, cv2.COLORMAP_VIRIDIS)[..., ::-1].copy()
    depth[view.count == 0] = 255
    return colour, depth


def save_wall_images(sim_dir: Path, wall_ids: list[str], out_dir: Path, pixel_m: float = 0.005) -> list[Path]:
    """Write ``wall_<id>_colour.png`` and ``wall_<id>_depth.png`` from a simulated scan."""
    import cv2

    from ..io.scans import read_scan
    from ..types import WallFrame

    sim_dir, out_dir = Path(sim_dir), Path(out_dir)
    truth = json.loads((sim_dir / "ground_truth.json").read_text())
    frames = {w["id"]: WallFrame.from_dict(w) for w in truth["walls"]}
    cloud = read_scan(sim_dir / "scan.ply")
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for wid in wall_ids:
        if wid not in frames:
            raise InputError(sim_dir / "ground_truth.json", f"no wall {wid!r}")
        f = frames[wid]
        local = WallFrame(f.origin - cloud.origin, f.axis_u, f.axis_v, f.normal, f.width_m, f.height_m)
        for kind, img in zip(("colour", "depth"), wall_images(wall_view(cloud.xyz, cloud.rgb, local, pixel_m=pixel_m)),
                             strict=True):
            path = out_dir / f"wall_{wid}_{kind}.png"
            cv2.imwrite(str(path), img[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
            written.append(path)
    return written


if __name__ == "__main__":  # pragma: no cover
    import sys

    if sys.argv[1:2] == ["images"]:  # images SIM_DIR OUT_DIR WALL [WALL ...]
        for p in save_wall_images(Path(sys.argv[2]), sys.argv[4:], Path(sys.argv[3])):
            print(p)
    else:
        for p in write_scenario_files():
            print(p)
