"""Look-alike signs: Table 1's sign rows on scenes whose two signs are same-size square plates.

    .venv/bin/python benchmarks/bench_lookalikes.py [--full] [--designs standard alt]
        [--seeds 21] [--expected {yes,no,both}] [--plain] [--run-dir /tmp/bench_lookalikes] [--redo]

The ``standard`` and ``alt`` designs with both signs made same-size square red plates
(:mod:`sbsc_core.simulate.designs_lookalike`): only the pictogram tells the extinguisher
sign from the call-point sign, as in issue 13. Each scene has the realistic scanner and
wall clutter (``--plain``: neither). Prints, per run, TP % and FP % of all classes, each
sign class's TP, FN and FP, and the swaps (a sign detected within 0.1 m of the other
sign's truth). ``--full`` is the Scenario I layout (heavy: run it under the shared lock).
The third design family is not offered here: it is for testing only (bench_realism.py).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from bench_realism import (  # benchmarks/ is on sys.path as a script
    EXPECTED_MODES,
    scene_and_run_dir,
)

SIGNS = ("extinguisher_sign", "fire_alarm_switch_sign")


def swaps(detections: dict, truth: dict, radius_m: float = 0.1) -> int:
    """Signs detected as the other sign class within ``radius_m`` of a truth sign."""
    dets = [d for d in detections["detections"] if d["class"] in SIGNS]
    n = 0
    for o in truth["objects"]:
        if o["class"] not in SIGNS:
            continue
        p = np.asarray(o["position"], float)
        near = [d for d in dets if np.linalg.norm(np.asarray(d["position"], float) - p) < radius_m]
        if near and all(d["class"] != o["class"] for d in near):
            n += 1
    return n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the Scenario I layout (heavy: use the shared lock)")
    ap.add_argument("--designs", nargs="+", default=["standard", "alt"], choices=["standard", "alt"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[21])
    ap.add_argument("--expected", choices=["yes", "no", "both"], default="both")
    ap.add_argument("--plain", action="store_true", help="the plain simulator (no realistic scanner, no clutter)")
    ap.add_argument("--run-dir", default="/tmp/bench_lookalikes")
    ap.add_argument("--redo", action="store_true", help="detect again even if cached")
    args = ap.parse_args(argv)

    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_truth
    from sbsc_core.pipeline.detect import detect_to_dir
    from sbsc_core.simulate.designs_lookalike import lookalike_builder
    from sbsc_core.simulate.scenarios import simulate_scene

    scene, run_dir = scene_and_run_dir(args.full, args.run_dir)
    modes = EXPECTED_MODES[args.expected]
    lines = []
    for design in args.designs:
        for seed in args.seeds:
            sim = run_dir / f"{'plain' if args.plain else 'acceptance'}_{design}_s{seed}"
            if not (sim / "ground_truth.json").is_file():
                simulate_scene(scene, sim, seed=seed, design=False, object_builder=lookalike_builder(design),
                               realistic=not args.plain, clutter=not args.plain)
            truth_doc = json.loads((sim / "ground_truth.json").read_text())
            truth = read_truth(sim / "ground_truth.json")
            for exp in modes:
                out = sim / ("detect_expected" if exp else "detect_free")
                t = time.perf_counter()
                if args.redo or not (out / "detections.json").is_file():
                    detect_to_dir([sim / "scan.ply"], sim / "models", out=out,
                                  expected=sim / "expected.json" if exp else None)
                sec = time.perf_counter() - t
                det = json.loads((out / "detections.json").read_text())
                table = evaluate(det, truth)
                rows = {r.class_id: r for r in table.rows}
                signs = "  ".join(f"{c.split('_')[0][:4]} TP {rows[c].tp_pct:5.1f} ({rows[c].tp}/{rows[c].tp + rows[c].fn},"
                                  f" FP {rows[c].fp})" for c in SIGNS if c in rows)
                line = (f"{design:<9}{seed:>5} {'yes' if exp else 'no ':<4} TP {table.total.tp_pct:5.1f} FP "
                        f"{table.total.fp_pct:5.1f}  {signs}  swaps {swaps(det, truth_doc)}  ({sec:.0f} s)")
                print(line, flush=True)
                lines.append(line)
    print(f"\n(scene {scene.name}, {'plain' if args.plain else 'realistic scanner + clutter'}, same-size square signs)")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
