"""Robustness of ``sbsc detect`` to scans that differ from our simulator's.

    .venv/bin/python benchmarks/bench_robustness.py [--sets standard alt] [--seeds 1 2]
        [--variants baseline noisy ...] [--step 0.1] [--run-dir /tmp/robust] [--redo]

The held-out check uses scenes from another simulator (other object designs, same file
contracts). This benchmark takes the small ``one_room`` scene, simulates it per design set
and seed (the *base* run, kept in ``<run-dir>/base_<set>_s<seed>``) and derives VARIANTS
of the scan that another simulator or a real scanner could produce:

* re-simulated with other scanner / scene settings (noisier, sparser, denser, no
  per-station colour differences, a single station, objects rotated 90 degrees in the
  wall plane, furniture in the room);
* the base scan transformed (rotated about z and moved to UTM-like coordinates, with the
  ground truth moved alike), split into several files, written as E57 (one scan per
  station in the scanner's own frame with its pose) or LAS, recoloured (darker, colour
  cast, linear instead of sRGB, one station darker), thinned (no ceiling, sparse upper
  walls) or misregistered (one station off by a few mm).

Every variant is detected in-process (:func:`sbsc_core.pipeline.detect.detect_to_dir`, the code of
``sbsc detect``) with the base run's model library and ``expected.json`` and evaluated with
:func:`sbsc_core.evaluate.evaluate` (10 cm match radius). Prints one table (a row per
variant and design set, summed over the seeds: TP, FN, FP, mean / max position error of the
TPs, walls and openings found) and per run every miss, false positive and TP more than
``--far-mm`` off (helpers of ``bench_designs.py``). Variants meant to give the same cloud
(``split_*``, ``e57_poses``, ``las``) are also compared with the baseline detections.
Simulations and detections are cached in the run dir (``--redo`` detects again).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_designs import _details  # noqa: E402

UTM = np.array([500_000.0, 4_400_000.0, 650.0])
CLUTTER_COLOURS = {"cabinet": (150, 110, 70), "table": (182, 180, 172), "shelf": (236, 236, 230)}
ROTATED_CLASSES = ("socket_x1", "socket_x2", "socket_x4", "switch", "extinguisher_sign",
                   "fire_alarm_switch_sign", "builtin_socket")


@dataclass
class Variant:
    name: str
    what: str
    kind: str  # "sim": simulated anew; "derive": made from the base scan
    sim: dict = field(default_factory=dict)  # scene yaml overrides / step / builder / clutter
    derive: Callable | None = None
    same_as_baseline: bool = False  # the cloud is the baseline's (other files / formats)


# --------------------------------------------------------------------------- simulation


def _scene_yaml(base_yaml: Path, out: Path, scanner: dict | None = None, stations: list | None = None) -> Path:
    data = yaml.safe_load(base_yaml.read_text())
    if scanner:
        data.setdefault("scanner", {}).update(scanner)
    if stations is not None:
        data["stations"] = stations
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def _rotated_builder(base: Callable, classes: tuple[str, ...]) -> Callable:
    """Objects of ``classes`` turned 90 degrees in the wall plane (local x -> y)."""
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])

    def build(class_id: str):
        mesh = base(class_id)
        return mesh.transformed(rz, np.zeros(3)) if class_id in classes else mesh

    return build


def _clutter_mesh():
    """Furniture of one_room: a cabinet against R1-N, a table mid-room, a tall shelf by R1-E."""
    from sbsc_core.simulate import mesh as M

    parts = [
        M.box((0.8, 0.45, 0.9), CLUTTER_COLOURS["cabinet"], (3.4, 3.0 - 0.01 - 0.225, 0.45)),
        M.box((1.2, 0.7, 0.04), CLUTTER_COLOURS["table"], (2.0, 1.5, 0.73)),
        M.box((0.06, 0.06, 0.71), CLUTTER_COLOURS["table"], (1.45, 1.2, 0.355)),
        M.box((0.06, 0.06, 0.71), CLUTTER_COLOURS["table"], (2.55, 1.8, 0.355)),
        M.box((0.35, 0.5, 2.0), CLUTTER_COLOURS["shelf"], (4.0 - 0.01 - 0.175, 1.5, 1.0)),
    ]
    return M.merge(parts).labelled(-1)


def simulate(scene_path: Path, out: Path, seed: int, step: float | None, builder: Callable,
             lib_builder: Callable | None, clutter: bool = False) -> None:
    """Like ``simulate_scene`` (same building, scan and documents) plus ``stations.npy``
    (the station of every point) and optional furniture; ``models/`` only when
    ``lib_builder`` is given."""
    from sbsc_core.io.atomic import atomic_output_dir, write_json_atomic
    from sbsc_core.io.ply import write_ply
    from sbsc_core.simulate import mesh as M
    from sbsc_core.simulate.building import build_building
    from sbsc_core.simulate.library import write_model_library
    from sbsc_core.simulate.scanner import scan_mesh
    from sbsc_core.simulate.scene import load_scene

    scene = load_scene(scene_path)
    if step is not None:
        scene.scanner = scene.scanner.replace(angular_step_deg=float(step))
    building = build_building(scene, builder)
    mesh = M.merge([building.mesh, _clutter_mesh()]) if clutter else building.mesh
    scan = scan_mesh(mesh, building.stations, scene.scanner, seed=seed, keep_station=True)
    with atomic_output_dir(out) as tmp:
        write_ply(tmp / "scan.ply", scan.xyz, scan.rgb)
        np.save(tmp / "stations.npy", scan.station)
        np.save(tmp / "station_xyz.npy", scan.stations)
        write_json_atomic(tmp / "ground_truth.json", building.truth_document())
        write_json_atomic(tmp / "expected.json", building.expected_document())
        if lib_builder is not None:
            write_model_library(tmp / "models", seed=seed, object_builder=lib_builder)


# --------------------------------------------------------------------------- derived scans


def _load_base(base: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    from sbsc_core.io.scans import read_scan

    cloud = read_scan(base / "scan.ply")
    truth = json.loads((base / "ground_truth.json").read_text())
    return cloud.world(), cloud.rgb.copy(), np.load(base / "stations.npy"), truth


def _rz(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])


def _transform_truth(truth: dict, rot: np.ndarray, t: np.ndarray) -> dict:
    truth = copy.deepcopy(truth)
    for o in truth["objects"]:
        o["position"] = [float(x) for x in rot @ np.asarray(o["position"], float) + t]
        o["normal"] = [float(x) for x in rot @ np.asarray(o["normal"], float)]
    for w in truth.get("walls", []):
        w["origin"] = [float(x) for x in rot @ np.asarray(w["origin"], float) + t]
        for k in ("axis_u", "axis_v", "normal"):
            w[k] = [float(x) for x in rot @ np.asarray(w[k], float)]
    return truth


def _write_truth(out: Path, truth: dict) -> Path:
    p = out / "ground_truth.json"
    p.write_text(json.dumps(truth))
    return p


def _rigid(deg: float, shift: np.ndarray) -> Callable:
    def make(base: Path, out: Path) -> tuple[list[Path], Path]:
        from sbsc_core.io.ply import write_ply

        xyz, rgb, _, truth = _load_base(base)
        rot = _rz(deg)
        write_ply(out / "scan.ply", xyz @ rot.T + shift, rgb, double=True)
        return [out / "scan.ply"], _write_truth(out, _transform_truth(truth, rot, shift))
    return make


def _recolour(fn: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Callable:
    def make(base: Path, out: Path) -> tuple[list[Path], Path]:
        from sbsc_core.io.ply import write_ply

        xyz, rgb, st, _ = _load_base(base)
        new = np.clip(np.rint(fn(rgb.astype(np.float64), st)), 0, 255).astype(np.uint8)
        write_ply(out / "scan.ply", xyz, new)
        return [out / "scan.ply"], base / "ground_truth.json"
    return make


def _subset(keep_fn: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Callable:
    def make(base: Path, out: Path) -> tuple[list[Path], Path]:
        from sbsc_core.io.ply import write_ply

        xyz, rgb, st, _ = _load_base(base)
        keep = keep_fn(xyz, st)
        write_ply(out / "scan.ply", xyz[keep], rgb[keep])
        return [out / "scan.ply"], base / "ground_truth.json"
    return make


def _split_stations(base: Path, out: Path) -> tuple[list[Path], Path]:
    from sbsc_core.io.ply import write_ply

    xyz, rgb, st, _ = _load_base(base)
    files = []
    for k in np.unique(st):
        m = st == k
        files.append(out / f"station_{int(k)}.ply")
        write_ply(files[-1], xyz[m], rgb[m])
    return files, base / "ground_truth.json"


def _split_halves(base: Path, out: Path) -> tuple[list[Path], Path]:
    """Two files cut across the room at x = 2.0 (every wall but R1-E/W spans both)."""
    from sbsc_core.io.ply import write_ply

    xyz, rgb, _, _ = _load_base(base)
    m = xyz[:, 0] < 2.0
    write_ply(out / "west.ply", xyz[m], rgb[m])
    write_ply(out / "east.ply", xyz[~m], rgb[~m])
    return [out / "west.ply", out / "east.ply"], base / "ground_truth.json"


def _e57_poses(base: Path, out: Path) -> tuple[list[Path], Path]:
    """One E57 file, one scan per station in that scanner's frame (turned by some yaw), with pose."""
    import pye57
    from scipy.spatial.transform import Rotation

    xyz, rgb, st, _ = _load_base(base)
    origins = np.load(base / "station_xyz.npy")
    with pye57.E57(str(out / "scan.e57"), mode="w") as e:
        for k in np.unique(st):
            m = st == k
            rot = Rotation.from_euler("z", 37.0 + 71.0 * int(k), degrees=True)
            t = origins[int(k)]
            local = rot.inv().apply(xyz[m] - t)
            q = rot.as_quat()  # x y z w
            e.write_scan_raw({"cartesianX": local[:, 0].copy(), "cartesianY": local[:, 1].copy(),
                              "cartesianZ": local[:, 2].copy(), "colorRed": rgb[m, 0].copy(),
                              "colorGreen": rgb[m, 1].copy(), "colorBlue": rgb[m, 2].copy()},
                             rotation=np.array([q[3], q[0], q[1], q[2]]), translation=np.asarray(t, float))
    return [out / "scan.e57"], base / "ground_truth.json"


def _las(base: Path, out: Path) -> tuple[list[Path], Path]:
    """LAS 1.2 point format 3, 1 mm coordinate scale, 16-bit colour (c * 257)."""
    import laspy

    xyz, rgb, _, _ = _load_base(base)
    las = laspy.create(point_format=3, file_version="1.2")
    las.header.offsets = np.floor(xyz.min(axis=0))
    las.header.scales = [0.001, 0.001, 0.001]
    las.x, las.y, las.z = xyz.T
    rgb16 = rgb.astype(np.uint16) * 257
    las.red, las.green, las.blue = rgb16.T
    las.write(out / "scan.las")
    return [out / "scan.las"], base / "ground_truth.json"


def _misregister(base: Path, out: Path) -> tuple[list[Path], Path]:
    """Station 1 off by (3, -3, 2) mm and 0.03 degrees about z (a typical registration error)."""
    from sbsc_core.io.ply import write_ply

    xyz, rgb, st, _ = _load_base(base)
    origins = np.load(base / "station_xyz.npy")
    m = st == 1
    rot = _rz(0.03)
    xyz[m] = (xyz[m] - origins[1]) @ rot.T + origins[1] + np.array([0.003, -0.003, 0.002])
    write_ply(out / "scan.ply", xyz, rgb)
    return [out / "scan.ply"], base / "ground_truth.json"


def _linear(rgb: np.ndarray, st: np.ndarray) -> np.ndarray:
    return 255.0 * (rgb / 255.0) ** 2.2


def _dark_cast(rgb: np.ndarray, st: np.ndarray) -> np.ndarray:
    return rgb * np.array([0.66, 0.60, 0.48]) + np.array([6.0, 4.0, 0.0])


def _station_exposure(rgb: np.ndarray, st: np.ndarray) -> np.ndarray:
    return np.where((st == 1)[:, None], rgb * 0.7, rgb)


def _no_ceiling(xyz: np.ndarray, st: np.ndarray) -> np.ndarray:
    return xyz[:, 2] < 2.75


def _sparse_upper(xyz: np.ndarray, st: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(7)
    return (xyz[:, 2] < 1.8) | (rng.random(len(xyz)) < 0.3)


VARIANTS: list[Variant] = [
    Variant("baseline", "the base simulation", "derive"),
    Variant("noisy", "range_sigma 5 mm, colour_sigma 6, gain_sigma 0.08", "sim",
            {"scanner": {"range_sigma_m": 0.005, "colour_sigma": 6, "gain_sigma": 0.08}}),
    Variant("sparse_0.2", "angular step 0.2 deg", "sim", {"step": 0.2}),
    Variant("dense_0.05", "angular step 0.05 deg", "sim", {"step": 0.05}),
    Variant("no_gain", "no per-station gain/tint/offset/gradient", "sim",
            {"scanner": {"gain_sigma": 0, "tint_sigma": 0, "offset_sigma": 0, "gradient_amplitude": 0}}),
    Variant("one_station", "a single station mid-room", "sim",
            {"stations": [{"room": "R1", "xy": [2.0, 1.5], "height_m": 1.5}]}),
    Variant("rot_objects", f"{', '.join(ROTATED_CLASSES)} turned 90 deg in the wall plane", "sim",
            {"rotated": ROTATED_CLASSES}),
    Variant("clutter", "cabinet at R1-N, table mid-room, 2 m shelf at R1-E", "sim", {"clutter": True}),
    Variant("utm", "translated by (500000, 4400000, 650), double PLY", "derive", derive=_rigid(0.0, UTM)),
    Variant("rot30", "rotated 30 deg about z", "derive", derive=_rigid(30.0, np.zeros(3))),
    Variant("rot30_utm", "rotated 30 deg and translated to UTM", "derive", derive=_rigid(30.0, UTM)),
    Variant("rot17_utm", "rotated 17 deg and translated to UTM", "derive", derive=_rigid(17.0, UTM)),
    Variant("split_stations", "one PLY per station", "derive", derive=_split_stations, same_as_baseline=True),
    Variant("split_halves", "two PLYs cut at x = 2 m", "derive", derive=_split_halves, same_as_baseline=True),
    Variant("e57_poses", "one E57, a scan per station in its own frame + pose", "derive",
            derive=_e57_poses, same_as_baseline=True),
    Variant("las", "LAS 1.2, 1 mm scale, 16-bit RGB", "derive", derive=_las, same_as_baseline=True),
    Variant("dark_cast", "colours x (0.66, 0.60, 0.48) + (6, 4, 0)", "derive", derive=_recolour(_dark_cast)),
    Variant("linear_rgb", "colours linear instead of sRGB ((c/255)^2.2)", "derive", derive=_recolour(_linear)),
    Variant("station_exposure", "station 1 colours x 0.7", "derive", derive=_recolour(_station_exposure)),
    Variant("no_ceiling", "points above z = 2.75 removed", "derive", derive=_subset(_no_ceiling)),
    Variant("sparse_upper", "70 % of the points above z = 1.8 dropped", "derive", derive=_subset(_sparse_upper)),
    Variant("misregistered", "station 1 off by (3, -3, 2) mm and 0.03 deg", "derive", derive=_misregister),
]
BY_NAME = {v.name: v for v in VARIANTS}


# --------------------------------------------------------------------------- runs


@dataclass
class Run:
    variant: str
    design: str
    seed: int
    table: object | None = None
    det: dict | None = None
    truth: dict | None = None
    walls: int = 0
    openings: int = 0
    error: str | None = None
    seconds: float = 0.0
    vs_baseline: str = ""


def base_dir(run_dir: Path, design: str, seed: int) -> Path:
    return run_dir / f"base_{design}_s{seed}"


def ensure_base(scene: Path, run_dir: Path, design: str, seed: int, step: float) -> Path:
    from sbsc_core.simulate.designs import design_builder

    b = base_dir(run_dir, design, seed)
    if not (b / "scan.ply").is_file():
        t = time.perf_counter()
        builder = design_builder(design)
        simulate(scene, b, seed, step, builder, builder)
        print(f"  simulated base {design} s{seed} in {time.perf_counter() - t:.0f} s", file=sys.stderr, flush=True)
    return b


def prepare(v: Variant, scene: Path, run_dir: Path, design: str, seed: int, step: float
            ) -> tuple[list[Path], Path]:
    """The variant's scan files and ground truth (made once, kept in the run dir)."""
    from sbsc_core.simulate.designs import design_builder

    b = ensure_base(scene, run_dir, design, seed, step)
    if v.name == "baseline":
        return [b / "scan.ply"], b / "ground_truth.json"
    out = run_dir / f"{v.name}_{design}_s{seed}" / "scan"
    done = out / "files.json"
    if done.is_file():
        names = json.loads(done.read_text())
        return [out / n for n in names["scans"]], Path(names["truth"])
    t = time.perf_counter()
    if v.kind == "sim":
        yaml_path = scene
        if "scanner" in v.sim or "stations" in v.sim:
            yaml_path = _scene_yaml(scene, run_dir / "scenes" / f"{scene.stem}_{v.name}.yaml",
                                    v.sim.get("scanner"), v.sim.get("stations"))
        builder = design_builder(design)
        if "rotated" in v.sim:
            builder = _rotated_builder(builder, v.sim["rotated"])
        simulate(yaml_path, out, seed, v.sim.get("step", step), builder, None, clutter=v.sim.get("clutter", False))
        scans, truth = [out / "scan.ply"], out / "ground_truth.json"
    else:
        out.mkdir(parents=True, exist_ok=True)
        scans, truth = v.derive(b, out)
    done.write_text(json.dumps({"scans": [p.name for p in scans], "truth": str(truth)}))
    print(f"  prepared {v.name} {design} s{seed} in {time.perf_counter() - t:.0f} s", file=sys.stderr, flush=True)
    return scans, truth


def run_variant(v: Variant, scene: Path, run_dir: Path, design: str, seed: int, step: float,
                redo: bool) -> Run:
    from sbsc_core.errors import SbscError
    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_truth
    from sbsc_core.pipeline.detect import detect_to_dir

    run = Run(v.name, design, seed)
    b = base_dir(run_dir, design, seed)
    try:
        scans, truth_path = prepare(v, scene, run_dir, design, seed, step)
    except Exception as exc:  # a variant that cannot be made is reported, not fatal
        run.error = f"preparing failed: {type(exc).__name__}: {exc}"
        traceback.print_exc()
        return run
    out = run_dir / f"{v.name}_{design}_s{seed}" / "detect"
    t = time.perf_counter()
    if redo or not (out / "detections.json").is_file():
        try:
            detect_to_dir(scans, b / "models", expected=b / "expected.json", out=out)
        except SbscError as exc:
            run.error = f"detect refused: {exc}"
            return run
        except Exception as exc:
            run.error = f"detect crashed: {type(exc).__name__}: {exc}"
            traceback.print_exc()
            return run
    run.seconds = time.perf_counter() - t
    run.det = json.loads((out / "detections.json").read_text())
    run.truth = json.loads(Path(truth_path).read_text())
    run.table = evaluate(run.det, read_truth(truth_path))
    run.walls = len(run.det["walls"])
    run.openings = len(run.det.get("openings", []))
    return run


def compare_detections(a: dict, b: dict) -> str:
    """How far detections ``b`` are from ``a`` (same classes; largest centre shift)."""
    ca = sorted(d["class"] for d in a["detections"])
    cb = sorted(d["class"] for d in b["detections"])
    if ca != cb:
        return f"DIFFERENT classes: {len(ca)} vs {len(cb)} detections"
    worst = 0.0
    for cls in set(ca):
        pa = np.array([d["position"] for d in a["detections"] if d["class"] == cls])
        pb = np.array([d["position"] for d in b["detections"] if d["class"] == cls])
        dist = np.linalg.norm(pa[:, None] - pb[None], axis=2)
        worst = max(worst, float(dist.min(axis=1).max()))
    return f"same classes, max shift {worst * 1000:.2f} mm"


def _fmt_row(name: str, design: str, runs: list[Run]) -> str:
    errs = [m.distance_m * 1000 for r in runs if r.table for m in r.table.matches]
    inst = sum(r.table.total.instances for r in runs if r.table)
    tp = sum(r.table.total.tp for r in runs if r.table)
    fn = sum(r.table.total.fn for r in runs if r.table)
    fp = sum(r.table.total.fp for r in runs if r.table)
    walls = "/".join(str(r.walls) for r in runs)
    opens = "/".join(str(r.openings) for r in runs)
    mean = f"{np.mean(errs):6.1f}" if errs else f"{'-':>6s}"
    mx = f"{np.max(errs):6.1f}" if errs else f"{'-':>6s}"
    crash = sum(r.error is not None for r in runs)
    return (f"{name:17s} {design:8s} {tp:3d}/{inst:<3d} {fn:3d} {fp:3d} {mean} {mx}  {walls:>7s} {opens:>7s}"
            f"{'  ERRORS ' + str(crash) if crash else ''}")


def main() -> None:
    from sbsc_core.paths import sample_projects_dir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", nargs="+", default=["standard", "alt"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--variants", nargs="+", default=[v.name for v in VARIANTS], choices=list(BY_NAME))
    ap.add_argument("--scene", default="one_room", help="bundled scene name (sbsc_core/data/) or a .yaml path")
    ap.add_argument("--step", type=float, default=None, help="base angular step (default: the scene's)")
    ap.add_argument("--run-dir", default="/tmp/robust")
    ap.add_argument("--far-mm", type=float, default=5.0)
    ap.add_argument("--redo", action="store_true", help="detect again even if detections are cached")
    args = ap.parse_args()

    scene = Path(args.scene) if args.scene.endswith(".yaml") else sample_projects_dir() / f"{args.scene}.yaml"
    run_dir = Path(args.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    names = args.variants if "baseline" in args.variants or not any(
        BY_NAME[n].same_as_baseline for n in args.variants) else ["baseline", *args.variants]
    results: dict[tuple[str, str], list[Run]] = {}
    for name in names:
        v = BY_NAME[name]
        for design in args.sets:
            for seed in args.seeds:
                r = run_variant(v, scene, run_dir, design, seed, args.step, args.redo)
                results.setdefault((name, design), []).append(r)
                tot = r.table.total if r.table else None
                status = r.error or f"TP {tot.tp}/{tot.instances} FP {tot.fp}, {r.walls} walls"
                print(f"[{name} {design} s{seed}] {status} ({r.seconds:.0f} s)", file=sys.stderr, flush=True)

    for (name, design), runs in results.items():
        if BY_NAME[name].same_as_baseline:
            for r, b in zip(runs, results.get(("baseline", design), []), strict=False):
                if r.det and b.det:
                    r.vs_baseline = compare_detections(b.det, r.det)

    head = (f"{'variant':17s} {'designs':8s} {'TP/inst':7s} {'FN':>3s} {'FP':>3s} {'mean':>6s} {'max':>6s}"
            f"  {'walls':>7s} {'opens':>7s}")
    print(f"\n== one_room robustness, seeds {args.seeds}; position error of TPs in mm; walls/openings per run "
          f"(truth: 4 walls, 2 openings)")
    print(head)
    print("-" * len(head))
    for (name, design), runs in results.items():
        print(_fmt_row(name, design, runs))
    print()
    for name in names:
        v = BY_NAME[name]
        print(f"-- {name}: {v.what}")
        for design in args.sets:
            for r in results[(name, design)]:
                if r.error:
                    print(f"  [{design} s{r.seed}] {r.error}")
                    continue
                lines = _details(r.table, r.det, r.truth, args.far_mm)
                extra = f"; vs baseline: {r.vs_baseline}" if r.vs_baseline else ""
                if lines or extra:
                    print(f"  [{design} s{r.seed}]{extra}")
                    for line in lines:
                        print("  " + line)


if __name__ == "__main__":  # detection runs walls in worker processes (spawn)
    main()
