"""Table 1 of ``sbsc detect`` on the independent generator's scenes (issue 27).

    .venv/bin/python benchmarks/bench_outside.py [--scenes DIR] [--only NAME ...]
        [--tree CHECKOUT] [--expected {yes,no,both}] [--run-dir runs/outside] [--redo]

Each folder of ``--scenes`` (default ``../shared/data/outside-scenes``) holds ``scan.laz``,
``ground_truth.json``, ``expected.json`` and the scene's own model library ``models/``.
For every scene, with and/or without its counts, the real command line runs in a fresh
process with ``--tree`` first on the path (default: this checkout; give an older checkout
to measure before and after on the same machine): ``python -m sbsc_core.cli detect``.
A checkout that does not search ceilings and columns by default (no ``--no-ceilings``
option) is given ``--ceilings --columns`` when the truth has objects there. The detections
are scored by this checkout's evaluator (same class, centre within 0.10 m, closest first),
and the script prints per run Table 1's total, each class's TP/FP, and the confusions:
for every missed object, the class of the nearest detection within 0.10 m (which class was
taken for which), and for every false positive, the truth class under it or the distractor
it sits on.

These scenes are for finding what breaks, never for fitting: the final word is scenes and
designs that nobody here sees. A JSON summary of every run goes to ``RUN_DIR/summary.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DEFAULT_SCENES = ROOT.parent / "shared" / "data" / "outside-scenes"
MATCH_M = 0.10


def _flags(tree: Path, truth: dict) -> list[str]:
    """``--ceilings --columns`` for a checkout that has them and does not search them by default."""
    cli = (tree / "sbsc_core" / "cli.py").read_text(encoding="utf-8") if (tree / "sbsc_core" / "cli.py").exists() \
        else ""
    if "--no-ceilings" in cli or "--ceilings" not in cli:  # searched by default, or not at all
        return []
    kinds = {o.get("surface", "wall") for o in truth["objects"]}
    return (["--ceilings"] if "ceiling" in kinds else []) + (["--columns"] if "column" in kinds else [])


def run_detect(tree: Path, scene: Path, out: Path, *, counts: bool, truth: dict) -> dict:
    """``sbsc detect`` of ``tree`` on one scene; the wall-clock and CPU seconds."""
    cmd = [sys.executable, "-m", "sbsc_core.cli", "detect", str(scene / "scan.laz"), "--models",
           str(scene / "models"), "--out", str(out), *(["--expected", str(scene / "expected.json")] if counts else []),
           *_flags(tree, truth)]
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    out.parent.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), os.times()
    proc = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True)
    c1 = os.times()
    if proc.returncode != 0:
        raise SystemExit(f"{scene.name}: detect failed ({proc.returncode}): {proc.stderr.strip()[-400:]}")
    return {"wall_s": time.perf_counter() - t0, "cpu_s": (c1.children_user - c0.children_user)
            + (c1.children_system - c0.children_system)}


def confusions(dets: list[dict], truth: dict, table) -> tuple[Counter, Counter]:
    """(missed truth class -> what the nearest detection within 0.10 m says, or 'nothing');
    (false positive class -> 'on <truth class>' / 'on distractor <class>' / 'on nothing')."""
    from sbsc_core.evaluate import distractor_box, on_distractor

    objs = truth["objects"]
    matched_t = {m.truth_index for m in table.matches}
    matched_d = {m.detection_id for m in table.matches}
    dxyz = np.array([d["position"] for d in dets], float).reshape(-1, 3)
    txyz = np.array([o["position"] for o in objs], float).reshape(-1, 3)
    missed: Counter = Counter()
    for i, o in enumerate(objs):
        if i in matched_t:
            continue
        near = np.linalg.norm(dxyz - txyz[i], axis=1) if len(dxyz) else np.zeros(0)
        k = int(np.argmin(near)) if len(near) else -1
        taken = dets[k]["class"] if k >= 0 and near[k] <= MATCH_M else "nothing"
        missed[f"{o['class']} -> {taken}"] += 1
    boxes = [distractor_box(d) for d in truth.get("distractors", [])]
    classes = [d["class"] for d in truth.get("distractors", [])]
    false: Counter = Counter()
    for d in dets:
        if str(d["id"]) in matched_d:
            continue
        near = np.linalg.norm(txyz - np.asarray(d["position"], float), axis=1) if len(txyz) else np.zeros(0)
        k = int(np.argmin(near)) if len(near) else -1
        if k >= 0 and near[k] <= MATCH_M:
            what = f"on {objs[k]['class']}"
        else:
            on = [c for b, c in zip(boxes, classes, strict=True) if on_distractor(d["position"], b)]
            what = f"on distractor {on[0]}" if on else "on nothing"
        false[f"{d['class']} {what}"] += 1
    return missed, false


def score(out: Path, scene: Path) -> dict:
    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_truth
    from sbsc_core.io.models import read_library_metadata

    doc = json.loads((out / "detections.json").read_text(encoding="utf-8"))
    truth_doc = json.loads((scene / "ground_truth.json").read_text(encoding="utf-8"))
    table = evaluate(doc, read_truth(scene / "ground_truth.json"), MATCH_M,
                     library=read_library_metadata(scene / "models"))
    missed, false = confusions(doc["detections"], truth_doc, table)
    t = table.total
    return {"objects": t.instances, "tp": t.tp, "fp": t.fp, "tp_pct": t.tp_pct, "fp_pct": t.fp_pct,
            "classes": {r.class_id: {"n": r.instances, "tp": r.tp, "fp": r.fp} for r in table.rows},
            "missed": dict(missed), "false": dict(false)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=str(DEFAULT_SCENES), help="folder of outside scenes")
    ap.add_argument("--only", nargs="*", default=None, help="scene folder names (default: all)")
    ap.add_argument("--tree", default=str(ROOT), help="checkout whose sbsc detect runs (default: this one)")
    ap.add_argument("--expected", choices=["yes", "no", "both"], default="both")
    ap.add_argument("--run-dir", default="runs/outside")
    ap.add_argument("--redo", action="store_true", help="detect again even when a run's output exists")
    args = ap.parse_args(argv)
    scenes_dir, tree = Path(args.scenes), Path(args.tree)
    if not scenes_dir.is_dir():
        ap.error(f"--scenes: {scenes_dir} is not a folder")
    scenes = sorted(p for p in scenes_dir.iterdir() if (p / "scan.laz").exists()
                    and (args.only is None or p.name in args.only))
    modes = {"yes": [True], "no": [False], "both": [True, False]}[args.expected]
    run_dir = Path(args.run_dir)
    summary: dict[str, dict] = {}
    totals = {m: [0, 0, 0] for m in modes}
    per_class: dict[bool, Counter] = {m: Counter() for m in modes}
    for scene in scenes:
        truth = json.loads((scene / "ground_truth.json").read_text(encoding="utf-8"))
        for counts in modes:
            key = f"{scene.name}/{'counts' if counts else 'no-counts'}"
            out = run_dir / scene.name / ("counts" if counts else "no_counts")
            timing = {}
            if args.redo or not (out / "detections.json").exists():
                timing = run_detect(tree, scene, out, counts=counts, truth=truth)
            r = {**score(out, scene), **timing}
            summary[key] = r
            totals[counts][0] += r["objects"]
            totals[counts][1] += r["tp"]
            totals[counts][2] += r["fp"]
            for c, v in r["classes"].items():
                per_class[counts][(c, "n")] += v["n"]
                per_class[counts][(c, "tp")] += v["tp"]
            print(f"{key:52s} TP {r['tp']:3d}/{r['objects']:3d} = {r['tp_pct']:5.1f} %  FP {r['fp']:3d} = "
                  f"{r['fp_pct']:5.1f} %" + (f"  ({timing['wall_s']:.0f} s)" if timing else ""))
            for k, v in sorted(r["missed"].items()):
                print(f"    missed {v} x {k}")
            for k, v in sorted(r["false"].items()):
                print(f"    false  {v} x {k}")
    for counts in modes:
        n, tp, fp = totals[counts]
        print(f"ALL {'with' if counts else 'without'} counts: TP {tp}/{n} = {100 * tp / max(n, 1):.1f} %, "
              f"FP {fp} = {100 * fp / max(n, 1):.1f} %")
        weak = [f"{c} {per_class[counts][(c, 'tp')]}/{per_class[counts][(c, 'n')]}"
                for c in sorted({c for c, _ in per_class[counts]})
                if per_class[counts][(c, "n")] and per_class[counts][(c, "tp")] < 0.9 * per_class[counts][(c, "n")]]
        print("    classes under 90 %: " + (", ".join(weak) if weak else "none"))
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "summary.json").write_text(json.dumps({"tree": str(tree), "runs": summary}, indent=1) + "\n",
                                          encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
