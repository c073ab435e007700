"""Recognition across design sets: the same small scene built with different object designs.

    .venv/bin/python benchmarks/bench_designs.py [--seeds 1 2 3] [--sets standard alt cross]
        [--scene one_room] [--step 0.12] [--run-dir runs/bench_designs]

For every design set and seed the scene is simulated (``sbsc_core.simulate``; kept in the
run dir and reused on a second run), detected with ``sbsc detect`` and evaluated against its
ground truth. Sets:

* ``standard``: scene and model library with the standard designs (:mod:`objects`);
* ``alt``: scene and library with the alternative designs (:mod:`objects_alt`);
* ``cross``: scene in the alternative designs, library in the standard ones (the models
  do not show the products on the wall: how far recognition carries over to other designs).

Prints per set a per-class table summed over the seeds (instances, TP, FN, FP, mean and
largest position error of the TPs in mm) and, per run, every miss, false positive and TP
placed more than ``--far-mm`` off, with the nearest object / detection of any class (a
miss next to a detection of another class is a mislabelling).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SETS: dict[str, tuple[str, str]] = {  # name: (scene designs, library designs)
    "standard": ("standard", "standard"),
    "alt": ("alt", "alt"),
    "cross": ("alt", "standard"),
}


@dataclass
class ClassSum:
    instances: int = 0
    tp: int = 0
    fn: int = 0
    fp: int = 0
    errors_mm: list[float] = field(default_factory=list)


def run_one(scene_path: Path, set_name: str, seed: int, step: float, run_dir: Path) -> tuple[object, dict, dict, float, float]:
    from sbsc_core.cli import main
    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_detections, read_truth
    from sbsc_core.simulate.designs import design_builder
    from sbsc_core.simulate.scenarios import simulate_scene

    scene_designs, library_designs = SETS[set_name]
    out = run_dir / f"{scene_path.stem}_{set_name}_s{seed}"
    t0 = time.perf_counter()
    if not (out / "scan" / "scan.ply").is_file():
        simulate_scene(scene_path, out / "scan", seed=seed, angular_step_deg=step,
                       object_builder=design_builder(scene_designs),
                       library_builder=design_builder(library_designs), design=False)
    t1 = time.perf_counter()
    rc = main(["-q", "detect", str(out / "scan" / "scan.ply"), "--models", str(out / "scan" / "models"),
               "--expected", str(out / "scan" / "expected.json"), "--out", str(out / "detect")])
    if rc != 0:
        raise SystemExit(f"detect failed on {out}")
    t2 = time.perf_counter()
    doc = read_detections(out / "detect" / "detections.json")
    table = evaluate(doc, read_truth(out / "scan" / "ground_truth.json"))
    raw_det = json.loads((out / "detect" / "detections.json").read_text())
    raw_truth = json.loads((out / "scan" / "ground_truth.json").read_text())
    return table, raw_det, raw_truth, t1 - t0, t2 - t1


def _details(table, det: dict, truth: dict, far_mm: float) -> list[str]:
    """Lines for misses, false positives and far TPs of one run."""
    objs = truth["objects"]
    dets = det["detections"]
    t_xyz = np.array([o["position"] for o in objs], float)
    d_xyz = np.array([d["position"] for d in dets], float) if dets else np.zeros((0, 3))
    matched_truth = {m.truth_index for m in table.matches}
    matched_det = {m.detection_id for m in table.matches}
    lines = []
    for i, o in enumerate(objs):
        if i in matched_truth:
            continue
        near = ""
        if len(d_xyz):
            k = int(np.argmin(np.linalg.norm(d_xyz - t_xyz[i], axis=1)))
            dist = float(np.linalg.norm(d_xyz[k] - t_xyz[i]))
            near = f"; nearest detection {dets[k]['class']} {dets[k]['id']} at {dist * 1000:.0f} mm"
        lines.append(f"  MISS {o['class']} on {o['wall']} u={o['u']:.3f} v={o['v']:.3f}{near}")
    for d, p in zip(dets, d_xyz, strict=True):
        if d["id"] in matched_det:
            continue
        k = int(np.argmin(np.linalg.norm(t_xyz - p, axis=1)))
        dist = float(np.linalg.norm(t_xyz[k] - p))
        lines.append(f"  FP   {d['class']} {d['id']} on {d.get('wall', '?')} alpha={d.get('alpha', '?')}; "
                     f"nearest object {objs[k]['class']} at {dist * 1000:.0f} mm")
    for m in table.matches:
        if m.distance_m * 1000 > far_mm:
            lines.append(f"  FAR  {m.class_id} {m.detection_id}: {m.distance_m * 1000:.1f} mm "
                         f"(h {m.horizontal_m * 1000:.1f}, v {m.vertical_m * 1000:.1f}) alpha={m.alpha}")
    return lines


def format_sums(title: str, sums: dict[str, ClassSum], order: list[str]) -> str:
    head = f"{'class':24s} {'inst':>4s} {'TP':>3s} {'FN':>3s} {'FP':>3s} {'err mean':>8s} {'err max':>7s}"
    lines = [title, head, "-" * len(head)]
    total = ClassSum()
    for c in order:
        s = sums.get(c, ClassSum())
        total.instances += s.instances
        total.tp += s.tp
        total.fn += s.fn
        total.fp += s.fp
        total.errors_mm += s.errors_mm
        lines.append(_row(c, s))
    lines.append("-" * len(head))
    lines.append(_row("TOTAL", total))
    return "\n".join(lines)


def _row(name: str, s: ClassSum) -> str:
    mean = f"{np.mean(s.errors_mm):8.1f}" if s.errors_mm else f"{'-':>8s}"
    mx = f"{np.max(s.errors_mm):7.1f}" if s.errors_mm else f"{'-':>7s}"
    return f"{name:24s} {s.instances:4d} {s.tp:3d} {s.fn:3d} {s.fp:3d} {mean} {mx}"


def main() -> None:
    from sbsc_core.paths import sample_projects_dir
    from sbsc_core.simulate.catalogue import CLASS_ORDER

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--sets", nargs="+", default=["standard", "alt", "cross"], choices=list(SETS))
    ap.add_argument("--scene", nargs="+", default=["one_room"],
                    help="bundled scene descriptions in sbsc_core/data/ (name without .yaml) or paths")
    ap.add_argument("--step", type=float, default=0.12, help="scanner angular step in degrees")
    ap.add_argument("--run-dir", default="runs/bench_designs")
    ap.add_argument("--far-mm", type=float, default=5.0, help="report TPs placed further off than this")
    args = ap.parse_args()

    run_dir = Path(args.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    scenes = [Path(s) if s.endswith(".yaml") else sample_projects_dir() / f"{s}.yaml" for s in args.scene]
    report: list[str] = []
    for set_name in args.sets:
        sums: dict[str, ClassSum] = defaultdict(ClassSum)
        details: list[str] = []
        for scene in scenes:
            for seed in args.seeds:
                table, det, truth, t_sim, t_det = run_one(scene, set_name, seed, args.step, run_dir)
                for r in table.rows:
                    s = sums[r.class_id]
                    s.instances += r.instances
                    s.tp += r.tp
                    s.fn += r.fn
                    s.fp += r.fp
                for m in table.matches:
                    sums[m.class_id].errors_mm.append(m.distance_m * 1000)
                tot = table.total
                details.append(f"{scene.stem} seed {seed}: TP {tot.tp}/{tot.instances}, FP {tot.fp} "
                               f"(simulate {t_sim:.0f} s, detect {t_det:.0f} s)")
                print(f"[{set_name}] {details[-1]}", file=sys.stderr, flush=True)
                details += _details(table, det, truth, args.far_mm)
        scene_set, lib_set = SETS[set_name]
        block = format_sums(f"\n== {set_name}: scene designs {scene_set}, library designs {lib_set}; "
                            f"{', '.join(s.stem for s in scenes)}, seeds {args.seeds}",
                            sums, list(CLASS_ORDER))
        report.append(block + "\n" + "\n".join(details))
        print(report[-1], flush=True)


if __name__ == "__main__":  # the detection runs walls in worker processes (spawn)
    main()
