"""Where the position error of ``sbsc detect`` comes from: the scanner's registration or recognition.

    .venv/bin/python benchmarks/bench_position.py [--full] [--designs alt] [--seeds 101]
        [--expected {yes,no,both}] [--run-dir /tmp/bench_position] [--classes] [--quiet]

The realistic scanner (``sbsc simulate --realistic``) moves every station but the first by a
small rigid motion, as a target-based registration leaves it (``ScanEffects``:
``registration_translation_m`` 2 mm and ``registration_rotation_deg`` 0.005 degrees, one
sigma per axis). Part of a detection's error is then in the scan itself, where no method
working on the registered cloud can remove it. For each design family and seed this
simulates the realistic scanner with wall clutter twice, with the published registration
error and with none (the same seed: the same scene, noise, exposure and highlights), detects
both, and prints per run the paper's mean horizontal and vertical errors (dh, dv) and the
signed error split along the wall's normal, along the wall and vertically (mean and standard
deviation, mm), so that a bias (e.g. one side of an object's relief in the scanner's shadow)
shows apart from the scatter. ``--classes`` adds the split per class.

The small scene (``one_room``) is the default; ``--full`` uses the Scenario I layout (~7 GB and
minutes per simulation: run it alone). The third design family is for testing only: never
tune anything on these figures.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np
from bench_realism import (  # benchmarks/ is on sys.path as a script
    EXPECTED_MODES,
    detect,
    scene_and_run_dir,
)

REGISTRATION = {"published": None,
                "none": {"registration_translation_m": 0.0, "registration_rotation_deg": 0.0}}


def simulate(scene: Path, out: Path, design: str, seed: int, registration: str, quiet: bool) -> None:
    """Realistic scanner + clutter; with ``registration`` "none" the stations are registered exactly."""
    from sbsc_core.simulate.designs import design_builder
    from sbsc_core.simulate.scenarios import simulate_scene

    if (out / "ground_truth.json").is_file():
        return
    with tempfile.TemporaryDirectory() as tmp:
        description = scene
        if REGISTRATION[registration] is not None:
            overrides = ", ".join(f"{k}: {v}" for k, v in REGISTRATION[registration].items())
            description = Path(tmp) / scene.name
            description.write_text(scene.read_text() + f"\nrealism: {{{overrides}}}\n")
        simulate_scene(description, out, seed=seed, design=False, object_builder=design_builder(design),
                       log=None if quiet else print, realistic=True, clutter=True)


def signed_errors(detections: dict, truth, table) -> list[tuple[str, float, float, float]]:
    """(class, along the normal, along the wall, vertical) in mm for every true positive on a wall."""
    by_id = {d["id"]: d for d in detections["detections"]}
    out = []
    for m in table.matches:
        t = truth.objects[m.truth_index]
        n = np.asarray(t.normal, float)
        if abs(n[2]) > 0.5:  # ceilings: no wall frame
            continue
        along = np.cross([0.0, 0.0, 1.0], n)
        along /= np.linalg.norm(along)
        e = (np.asarray(by_id[m.detection_id]["position"], float) - np.asarray(t.position, float)) * 1000.0
        out.append((t.class_id, float(e @ n), float(e @ along), float(e[2])))
    return out


def split_text(errors: list[tuple[str, float, float, float]]) -> str:
    if not errors:
        return "no true positives"
    a = np.array([e[1:] for e in errors])
    return "  ".join(f"{name} {a[:, k].mean():+5.2f} ({a[:, k].std():4.2f})"
                     for k, name in enumerate(("normal", "along", "vertical")))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the Scenario I layout (heavy: run it alone)")
    ap.add_argument("--designs", nargs="+", default=["alt"], choices=["standard", "alt", "third"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[101])
    ap.add_argument("--expected", choices=["yes", "no", "both"], default="no")
    ap.add_argument("--run-dir", default="/tmp/bench_position")
    ap.add_argument("--classes", action="store_true", help="the signed split per class too")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)

    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_truth
    scene, run_dir = scene_and_run_dir(args.full, args.run_dir)
    modes = EXPECTED_MODES[args.expected]
    lines = []
    for design in args.designs:
        for seed in args.seeds:
            for registration in REGISTRATION:
                sim = run_dir / f"{design}_s{seed}_registration_{registration}"
                simulate(scene, sim, design, seed, registration, args.quiet)
                truth = read_truth(sim / "ground_truth.json")
                for exp in modes:
                    det, _ = detect(sim, sim / ("detect_expected" if exp else "detect_free"), exp, False)
                    table = evaluate(det, truth)
                    errors = signed_errors(det, truth, table)
                    t = table.total
                    line = (f"{design:<9}{seed:>6} {registration:<10}{'yes' if exp else 'no':<4}"
                            f"{t.tp:>4}/{t.instances:<4} dh {t.h_mean_mm or 0:4.2f} dv {t.v_mean_mm or 0:4.2f}  "
                            + split_text(errors))
                    lines.append(line)
                    print(line, flush=True)
                    if args.classes:
                        per: dict[str, list] = defaultdict(list)
                        for e in errors:
                            per[e[0]].append(e)
                        for cls in sorted(per):
                            print(f"    {cls:<24} n {len(per[cls]):>3}  {split_text(per[cls])}")
    print(f"\n{'designs':<9}{'seed':>6} {'registr.':<10}{'exp':<4}{'TP':>9}  mean |error| and signed split, mm "
          f"(mean (sd)); scene {scene.name}")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
