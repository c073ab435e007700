"""Recognition beyond walls (issue 11): figures per surface kind with ``detect --ceilings --columns``.

    .venv/bin/python benchmarks/bench_surfaces.py [--scenario I|II|building] [--storeys N] [--realistic]
        [--survey-frame] [--scene NAME|FILE] [--full] [--no-columns] [--designs standard alt] [--seed 0]
        [--run-dir /tmp/bench_surfaces] [--redo] [--simulate-only] [--json FILE]

Simulates the floor with ``--ceiling-objects --columns`` (``--no-columns``: ceilings only),
runs ``sbsc detect --expected --ceilings --columns`` on it with the floor's ``expected.json``
and prints the paper's Table 1 with one line per surface kind (on walls, on ceilings, on
columns), then one summary line per run: TP, FP and mean position error per kind, and the
seconds of the detect run.

- ``--scenario I`` / ``II``: the paper's floors (``--full`` is ``--scenario I``);
  ``--scenario building --storeys N``: the simulated building, one scan file per station;
- ``--realistic``: the realistic scanner; ``--survey-frame``: scan and truth at UTM-like
  coordinates, turned 23.5 degrees (both for Scenario I / II and scenes);
- ``--scene NAME|FILE``: a bundled scene or a description (default: ``one_room``).

Scenario and building runs are heavy (~4 GiB and minutes each): run them under
``/work/notes/heavy`` or a lock of its kind. A run's simulation and detections are kept in
``--run-dir`` and reused unless ``--redo``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def run_tag(scene: str, design: str, seed: int, *, columns: bool, storeys: int, realistic: bool,
            survey_frame: bool = False) -> str:
    """The run's folder name in the run directory."""
    name = Path(scene).stem if scene.endswith((".yaml", ".json")) else scene
    if scene == "building":
        name += f"{storeys}"
    return (f"{name}_{design}_s{seed}" + ("_realistic" if realistic else "") + ("_survey" if survey_frame else "")
            + ("_columns" if columns else ""))


def simulate_args(scene: str, design: str, seed: int, *, columns: bool, storeys: int, realistic: bool,
                  out: Path, survey_frame: bool = False) -> list[str]:
    """``sbsc simulate`` arguments of a run."""
    if scene in ("I", "II", "building"):
        args = ["--scenario", scene]
    else:
        args = ["--scene", scene]
    if scene == "building":
        args += ["--storeys", str(storeys)]
    else:
        args += (["--realistic"] if realistic else []) + (["--survey-frame"] if survey_frame else [])
    return ["-q", "simulate", *args, "--designs", design, "--seed", str(seed), "--ceiling-objects",
            "--out", str(out)] + (["--columns"] if columns else [])


def scan_files(sim: Path) -> list[str]:
    """The scan files of a simulation: ``scan.ply``, or a building's station files."""
    if (sim / "scan.ply").exists():
        return [str(sim / "scan.ply")]
    return [str(p) for p in sorted((sim / "stations").iterdir())]


def run(scene: str, design: str, seed: int, columns: bool, run_dir: Path, redo: bool, *, storeys: int = 2,
        realistic: bool = False, survey_frame: bool = False, simulate_only: bool = False) -> dict | None:
    from sbsc_core.cli import main
    from sbsc_core.evaluate import evaluate, format_table
    from sbsc_core.io.documents import read_detections, read_truth

    tag = run_tag(scene, design, seed, columns=columns, storeys=storeys, realistic=realistic,
                  survey_frame=survey_frame)
    sim, det = run_dir / tag / "sim", run_dir / tag / "detect"
    sim.parent.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    if redo or not (sim / "ground_truth.json").exists():
        assert main(simulate_args(scene, design, seed, columns=columns, storeys=storeys, realistic=realistic,
                                  out=sim, survey_frame=survey_frame)) == 0
        print(f"{tag}: simulated in {time.perf_counter() - t:.0f} s", flush=True)
    if simulate_only:
        return None
    t = time.perf_counter()
    if redo or not (det / "detections.json").exists():
        assert main(["-q", "detect", *scan_files(sim), "--models", str(sim / "models"), "--expected",
                     str(sim / "expected.json"), "--ceilings", "--out", str(det)]
                    + (["--columns"] if columns else [])) == 0
    seconds = time.perf_counter() - t
    table = evaluate(read_detections(det / "detections.json"), read_truth(sim / "ground_truth.json"))
    print(f"== {tag}")
    print(format_table(table))
    parts = []
    for r in table.surfaces or []:
        err = "-" if r.h_mean_mm is None else f"{r.h_mean_mm:.1f}/{r.v_mean_mm:.1f} mm"
        parts.append(f"{r.class_id}: {r.tp}/{r.instances} TP ({r.tp_pct or 0:.1f} %), FP {r.fp} "
                     f"({r.fp_pct or 0:.1f} %), mean dh/dv {err}")
    print(f"{tag}: " + "; ".join(parts) + f"; detect {seconds:.0f} s", flush=True)
    return {"run": tag, "surfaces": [r.to_dict() for r in table.surfaces or []], "seconds": round(seconds, 1)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", choices=["I", "II", "building"], default=None,
                   help="the paper's floor I or II, or the simulated building")
    p.add_argument("--storeys", type=int, default=2, help="--scenario building: storeys (default: 2)")
    p.add_argument("--realistic", action="store_true", help="the realistic scanner (not for the building)")
    p.add_argument("--survey-frame", action="store_true", help="UTM-like coordinates, turned (not for the building)")
    p.add_argument("--full", action="store_true", help="the same as --scenario I")
    p.add_argument("--scene", default=None, help="a bundled scene or a description file (default: one_room)")
    p.add_argument("--columns", action="store_true", help="(the default) simulate columns with objects too")
    p.add_argument("--no-columns", action="store_true", help="ceilings only: no columns")
    p.add_argument("--designs", nargs="+", default=["standard"], choices=["standard", "alt", "third"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--run-dir", type=Path, default=Path("/tmp/bench_surfaces"))
    p.add_argument("--redo", action="store_true", help="simulate and detect again even if the run exists")
    p.add_argument("--simulate-only", action="store_true", help="only simulate (e.g. ahead of the detect runs)")
    p.add_argument("--json", type=Path, default=None, help="write the figures as JSON")
    a = p.parse_args(argv)
    if a.scenario and a.scene:
        p.error("give --scenario or --scene, not both")
    if a.scenario == "building" and (a.realistic or a.survey_frame):
        p.error("--realistic and --survey-frame are not available for --scenario building")
    scene = a.scenario or ("I" if a.full else (a.scene or "one_room"))
    import sbsc_core

    print(f"sbsc_core from {Path(sbsc_core.__file__).parent}", flush=True)  # the tree measured (PYTHONPATH)
    out = [run(scene, d, a.seed, not a.no_columns, a.run_dir, a.redo, storeys=a.storeys, realistic=a.realistic,
               survey_frame=a.survey_frame, simulate_only=a.simulate_only) for d in a.designs]
    if a.json and not a.simulate_only:
        a.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
