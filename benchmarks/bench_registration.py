"""What refining the stations' registration does to the position error (``sbsc_core.scene.registration``).

    .venv/bin/python benchmarks/bench_registration.py [--designs standard alt] [--seeds 5521]
        [--storeys 1] [--expected {yes,no,both}] [--run-dir /tmp/bench_registration] [--quiet]

Simulates a building of ``--storeys`` Scenario I floors (``sbsc simulate --scenario building``:
one file per station) with the realistic scanner and wall clutter. Every station but the first
is off by a small rigid motion (``ScanEffects``: 2 mm and 0.005 degrees, one sigma per axis), as
a target-based registration leaves it. Each scene is detected twice, with the registration
refined and as given (``registration.enabled`` false), and each run prints the paper's Table 1
totals (TP, FP, the mean horizontal and vertical errors dh and dv) and the time of the
refinement. For the refined runs it also prints the stations' mean error before and after: the
mean distance, over each station's points, between where the (refined) registration puts them
and where they truly are (the simulator's own draw of each station's error).

Heavy (a Scenario I storey is ~100 million points; minutes and ~7 GB per simulation): run it
alone. The third design family is for testing only: never tune anything on these figures.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

EXPECTED_MODES = {"yes": [True], "no": [False], "both": [True, False]}


def simulate(out: Path, design: str, seed: int, storeys: int, quiet: bool) -> None:
    from sbsc_core.simulate.building_scenario import simulate_building
    from sbsc_core.simulate.designs import design_builder

    if (out / "ground_truth.json").is_file():
        return
    simulate_building(out, storeys, seed=seed, object_builder=design_builder(design), realistic=True, clutter=True,
                      log=None if quiet else print)


def detect(sim: Path, out: Path, expected: bool, refine: bool) -> tuple[dict, dict]:
    from sbsc_core.pipeline.detect import detect_to_dir
    from sbsc_core.settings import DetectionSettings

    s = DetectionSettings.from_dict({"registration": {"enabled": refine}})
    if not (out / "detections.json").is_file():
        t = time.perf_counter()
        summary = detect_to_dir(sorted((sim / "stations").iterdir()), sim / "models", settings=s, out=out,
                                expected=sim / "expected.json" if expected else None)
        (out / "summary.json").write_text(json.dumps({**summary, "seconds": time.perf_counter() - t}, default=str))
    return json.loads((out / "detections.json").read_text()), json.loads((out / "summary.json").read_text())


def station_errors_mm(sim: Path, seed: int, records: list[dict] | None) -> np.ndarray:
    """Mean error (mm) of each station's points, with the refined poses of ``records`` (None: as given)."""
    from sbsc_core.imaging.partition import scan_origin
    from sbsc_core.io.scans import open_scan, sample_scan
    from sbsc_core.simulate.building_scenario import plan_building
    from sbsc_core.simulate.realism import station_pose_error

    truth = json.loads((sim / "ground_truth.json").read_text())
    files = sorted((sim / "stations").iterdir())
    origin = scan_origin(files[0])
    effects = plan_building(len(truth["storeys"]), "scenario", realistic=True, clutter=True)[0].scene.effects
    out = []
    for k, f in enumerate(files):
        R, t = station_pose_error(seed, k, effects)
        o = np.asarray(truth["stations"][k], float) - origin
        E = np.eye(4)
        E[:3, :3], E[:3, 3] = R, o - R @ o + t
        P = np.eye(4)
        if records is not None:
            P = _pose(records[k])
        D = P @ E
        x = sample_scan(open_scan(f), origin, 200)[0].astype(np.float64)
        out.append(np.mean(np.linalg.norm(x @ D[:3, :3].T + D[:3, 3] - x, axis=1)) * 1000)
    return np.asarray(out)


def _pose(record: dict) -> np.ndarray:
    return np.asarray(record["pose"], float)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", nargs="+", default=["standard"], choices=["standard", "alt", "third"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[5521])
    ap.add_argument("--storeys", type=int, default=1)
    ap.add_argument("--expected", choices=list(EXPECTED_MODES), default="no")
    ap.add_argument("--run-dir", default="/tmp/bench_registration")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_truth

    root = Path(args.run_dir)
    print(f"{'design':<9}{'seed':>6} {'counts':<7}{'registration':<13}{'TP %':>6}{'FP %':>6}{'dh mm':>7}{'dv mm':>7}"
          f"{'refine s':>9}{'detect s':>9}  stations' mean error (mm)")
    for design in args.designs:
        for seed in args.seeds:
            sim = root / f"{design}{seed}_s{args.storeys}"
            simulate(sim, design, seed, args.storeys, args.quiet)
            truth = read_truth(sim / "ground_truth.json")
            for expected in EXPECTED_MODES[args.expected]:
                for refine in (False, True):
                    run = root / f"{sim.name}_{'e1' if expected else 'e0'}_{'refined' if refine else 'given'}"
                    doc, summary = detect(sim, run, expected, refine)
                    t = evaluate(doc, truth).total
                    err = station_errors_mm(sim, seed, doc.get("registration") if refine else None)
                    print(f"{design:<9}{seed:>6} {'yes' if expected else 'no':<7}{'refined' if refine else 'as given':<13}"
                          f"{t.tp_pct:6.1f}{t.fp_pct:6.1f}{t.h_mean_mm:7.2f}{t.v_mean_mm:7.2f}"
                          f"{summary['timings'].get('registration', 0.0):9.1f}{summary['seconds']:9.1f}"
                          f"  {err.mean():.2f} (max {err.max():.2f})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
