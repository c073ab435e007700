"""Recognition of turned objects: Table 1 and the turn error on scenes with a share of the
rotatable objects turned by random angles (issue 13, item 2).

Usage (heavy for Scenario I: run under the shared lock)::

    flock /tmp/sbsc-heavy.lock python benchmarks/bench_rotation.py \
        [--scene sbsc_core/data/scenario_I.yaml] [--fraction 0.34] [--seeds 31 32] [--work DIR]

For each seed the scene gets ``object_rotation: {fraction, seed}``, is simulated and
detected with and without ``--expected``. Printed per run: objects, turned objects, TP %,
FP %, TP % of the turned objects, and the turn error of the turned objects found (degrees,
modulo a quarter turn, since square reliefs and prints may repeat every 90 degrees; and
modulo a full turn).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sbsc_core.evaluate import evaluate  # noqa: E402
from sbsc_core.io.documents import read_detections, read_truth  # noqa: E402
from sbsc_core.pipeline.detect import detect_to_dir  # noqa: E402
from sbsc_core.simulate.scenarios import simulate_scene  # noqa: E402


def turn_error(a: float, b: float, period: float) -> float:
    d = (a - b) % period
    return min(d, period - d)


def report(scan: Path, out: Path, radius: float) -> str:
    doc = read_detections(out / "detections.json")
    table = evaluate(doc, read_truth(scan / "ground_truth.json"))
    truth = json.loads((scan / "ground_truth.json").read_text())["objects"]
    dets = doc["detections"]
    turned = [o for o in truth if o.get("rotation_deg")]
    found, err90, err360 = 0, [], []
    for o in turned:
        near = [d for d in dets if d["class"] == o["class"]
                and np.linalg.norm(np.subtract(d["position"], o["position"])) <= radius]
        if near:
            found += 1
            d = min(near, key=lambda d: np.linalg.norm(np.subtract(d["position"], o["position"])))
            err90.append(turn_error(d.get("rotation_deg", 0.0), o["rotation_deg"], 90.0))
            err360.append(turn_error(d.get("rotation_deg", 0.0), o["rotation_deg"], 360.0))
    t = table.total
    e90 = np.array(err90) if err90 else np.array([np.nan])
    e360 = np.array(err360) if err360 else np.array([np.nan])
    return (f"{t.instances:4d} objects, {len(turned):3d} turned | TP {t.tp_pct:5.1f} % FP {t.fp_pct:5.1f} % | "
            f"turned TP {100.0 * found / max(1, len(turned)):5.1f} % | turn error mod 90: median "
            f"{np.median(e90):.1f}, max {np.max(e90):.1f} deg; mod 360: median {np.median(e360):.1f}, "
            f"within 3 deg {100.0 * np.mean(e360 <= 3.0):.0f} %")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=ROOT / "sbsc_core" / "data" / "scenario_I.yaml")
    ap.add_argument("--fraction", type=float, default=0.34)
    ap.add_argument("--seeds", type=int, nargs="+", default=[31])
    ap.add_argument("--step", type=float, default=None, help="scanner angular step (degrees)")
    ap.add_argument("--radius", type=float, default=0.10, help="match radius of the turned objects (m)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/sbsc-bench-rotation"))
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    for seed in args.seeds:
        data = yaml.safe_load(args.scene.read_text())
        data["object_rotation"] = {"fraction": args.fraction, "seed": seed}
        scene = args.work / f"{args.scene.stem}_turned_s{seed}.yaml"
        scene.write_text(yaml.safe_dump(data))
        scan = args.work / f"{args.scene.stem}_s{seed}"
        if not (scan / "ground_truth.json").is_file():
            simulate_scene(scene, scan, seed=seed, angular_step_deg=args.step, design=False)
        for expected in (True, False):
            out = scan.with_name(scan.name + ("_exp" if expected else "_free"))
            detect_to_dir([scan / "scan.ply"], scan / "models", expected=scan / "expected.json" if expected else None,
                          out=out)
            print(f"{scan.name} {'--expected' if expected else 'no counts '}: {report(scan, out, args.radius)}",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
