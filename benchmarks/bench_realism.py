"""Table 1 of ``sbsc detect`` on scans that have what real scans have.

    .venv/bin/python benchmarks/bench_realism.py [--full] [--variants baseline clutter ...]
        [--designs standard alt third] [--seeds 101] [--step 0.1] [--expected {yes,no,both}]
        [--run-dir /tmp/bench_realism] [--redo] [--quiet]

Simulates a scene per VARIANT (the realism options of ``sbsc simulate``):

* ``baseline``: the plain simulator;
* ``clutter``: wall clutter that is none of the classes (pictures, posters, boards, clocks,
  thermostats, room controllers, trunking, coat hooks, door stops);
* ``furniture``: desks, cabinets, shelves, chairs and bins in front of the walls;
* ``realistic``: the realistic scanner (mixed pixels, range noise growing with range and
  incidence, dropouts, registration error, per-station exposure and white balance,
  highlights; published phase-based TLS figures);
* ``survey``: scan and truth at UTM-like coordinates turned 23.5 degrees;
* ``all``: all four together;
* ``acceptance``: realistic scanner + clutter (issue 13's acceptance scene; use with
  ``--designs third`` and a seed never used in development);

per DESIGN family (``standard``, ``alt``, ``third``; the model library is rendered with
the same family), detects it in-process (the code of ``sbsc detect``) with and/or without
``--expected`` and prints the paper's Table 1 per run, then one summary line per run:
TP %, FP %, mean position error, sign classes' TP, false positives on distractors and the
share of clutter items carrying one.

The small scene (``one_room``) is the default; ``--full`` uses the Scenario I layout
(run it under ``flock /tmp/sbsc-heavy.lock``: ~4 GiB and minutes per run). The third
design family is for testing only: never tune anything on these figures.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

VARIANTS: dict[str, dict[str, bool]] = {
    "baseline": {},
    "clutter": {"clutter": True},
    "furniture": {"furniture": True},
    "realistic": {"realistic": True},
    "survey": {"survey_frame": True},
    "all": {"realistic": True, "clutter": True, "furniture": True, "survey_frame": True},
    "acceptance": {"realistic": True, "clutter": True},
}
SIGNS = ("extinguisher_sign", "fire_alarm_switch_sign")
EXPECTED_MODES = {"yes": [True], "no": [False], "both": [True, False]}  # --expected: detect with counts, without, both


def scene_and_run_dir(full: bool, run_dir: str) -> tuple[Path, Path]:
    """The bundled scene (Scenario I with ``full``, else one_room) and the run folder for it."""
    from sbsc_core.paths import sample_projects_dir

    scene = sample_projects_dir() / ("scenario_I.yaml" if full else "one_room.yaml")
    return scene, Path(run_dir) / ("scenario_I" if full else "one_room")


@dataclass
class Result:
    variant: str
    design: str
    seed: int
    expected: bool
    table: object
    seconds: float


def simulate(scene: Path, out: Path, variant: str, design: str, seed: int, step: float | None, quiet: bool) -> None:
    from sbsc_core.simulate.designs import design_builder
    from sbsc_core.simulate.scenarios import simulate_scene

    if (out / "ground_truth.json").is_file():
        return
    simulate_scene(scene, out, seed=seed, angular_step_deg=step, design=False,
                   object_builder=design_builder(design), log=None if quiet else print, **VARIANTS[variant])


def detect(sim: Path, out: Path, expected: bool, redo: bool) -> tuple[dict, float]:
    from sbsc_core.pipeline.detect import detect_to_dir

    t = time.perf_counter()
    if redo or not (out / "detections.json").is_file():
        detect_to_dir([sim / "scan.ply"], sim / "models", expected=sim / "expected.json" if expected else None, out=out)
    return json.loads((out / "detections.json").read_text()), time.perf_counter() - t


def summary_line(r: Result) -> str:
    t = r.table.total
    signs = [row for row in r.table.rows if row.class_id in SIGNS]
    sign_txt = " ".join(f"{row.class_id.split('_')[0][:4]}{'' if row.tp_pct is None else f' {row.tp_pct:.0f}'}"
                        for row in signs)
    d = r.table.distractors
    dis = "-" if d is None else (f"{d.fp_on_distractors} FP on distr., clutter {d.clutter_with_fp}/{d.clutter}"
                                 f", furn. {d.furniture_with_fp}/{d.furniture}")
    fmt = lambda v: "   -" if v is None else f"{v:5.1f}"  # noqa: E731
    return (f"{r.variant:<11}{r.design:<9}{r.seed:>5} {'yes' if r.expected else 'no ':<4}{t.instances:>5}"
            f" {fmt(t.tp_pct)} {fmt(t.fp_pct)} {t.fn:>3} {t.fp:>3}  {fmt(t.h_mean_mm)} {fmt(t.v_mean_mm)}"
            f"  signs TP% {sign_txt:<14} {dis}  ({r.seconds:.0f} s)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the Scenario I layout (heavy: use the shared lock)")
    ap.add_argument("--variants", nargs="+", default=["baseline", "clutter", "furniture", "realistic", "survey", "all"],
                    choices=list(VARIANTS))
    ap.add_argument("--designs", nargs="+", default=["standard", "alt", "third"], choices=["standard", "alt", "third"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[101])
    ap.add_argument("--step", type=float, default=None, help="scanner angular step (default: the scene's)")
    ap.add_argument("--expected", choices=["yes", "no", "both"], default="yes")
    ap.add_argument("--run-dir", default="/tmp/bench_realism")
    ap.add_argument("--redo", action="store_true", help="detect again even if cached")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--tables", action="store_true", help="print the full Table 1 of every run")
    args = ap.parse_args(argv)

    from sbsc_core.evaluate import evaluate, format_table
    from sbsc_core.io.documents import read_truth
    scene, run_dir = scene_and_run_dir(args.full, args.run_dir)
    modes = EXPECTED_MODES[args.expected]
    results: list[Result] = []
    for design in args.designs:
        for variant in args.variants:
            for seed in args.seeds:
                sim = run_dir / f"{variant}_{design}_s{seed}"
                simulate(scene, sim, variant, design, seed, args.step, args.quiet)
                truth = read_truth(sim / "ground_truth.json")
                for exp in modes:
                    det, sec = detect(sim, sim / ("detect_expected" if exp else "detect_free"), exp, args.redo)
                    r = Result(variant, design, seed, exp, evaluate(det, truth), sec)
                    results.append(r)
                    if args.tables:
                        print(f"\n== {variant} / {design} / seed {seed} / expected {'yes' if exp else 'no'}")
                        print(format_table(r.table))
                    print(summary_line(r), flush=True)
    print(f"\n{'variant':<11}{'designs':<9}{'seed':>5} {'exp':<4}{'inst':>5} {'TP%':>5} {'FP%':>5} {'FN':>3} {'FP':>3}"
          f"  {'dh mm':>5} {'dv mm':>5}  (scene {scene.name})")
    for r in results:
        print(summary_line(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
