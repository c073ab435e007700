"""Recognition beyond walls (issue 11): figures per surface kind with ``detect --ceilings``.

    .venv/bin/python benchmarks/bench_surfaces.py [--full] [--scene NAME|FILE] [--columns]
        [--designs standard alt] [--seed 0] [--run-dir /tmp/bench_surfaces] [--redo]

Simulates the scene with ``--ceiling-objects`` (and ``--columns`` if asked), runs
``sbsc detect --ceilings`` (and ``--columns``) on it with the scene's ``expected.json`` and
prints the paper's Table 1 with one line per surface kind (on walls, on ceilings, on
columns), then one summary line per run: TP %, FP % and mean position error per kind, and
the seconds of the detect run.

The small scene (``one_room``) is the default; ``--full`` uses Scenario I (run it under
``/work/notes/heavy`` or a lock of its kind: ~4 GiB and minutes per run).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def run(scene: str, design: str, seed: int, columns: bool, run_dir: Path, redo: bool) -> dict:
    from sbsc_core.cli import main
    from sbsc_core.evaluate import evaluate, format_table
    from sbsc_core.io.documents import read_detections, read_truth

    name = Path(scene).stem if scene.endswith((".yaml", ".json")) else scene
    tag = f"{name}_{design}_s{seed}" + ("_columns" if columns else "")
    sim, det = run_dir / tag / "sim", run_dir / tag / "detect"
    sim.parent.mkdir(parents=True, exist_ok=True)
    if redo or not (sim / "ground_truth.json").exists():
        args = ["-q", "simulate", "--scene", scene, "--designs", design, "--seed", str(seed),
                "--ceiling-objects", "--out", str(sim)] + (["--columns"] if columns else [])
        if scene in ("I", "II"):
            args[2:4] = ["--scenario", scene]
        assert main(args) == 0
    t = time.perf_counter()
    if redo or not (det / "detections.json").exists():
        assert main(["-q", "detect", str(sim / "scan.ply"), "--models", str(sim / "models"), "--expected",
                     str(sim / "expected.json"), "--ceilings", "--out", str(det)]
                    + (["--columns"] if columns else [])) == 0
    seconds = time.perf_counter() - t
    table = evaluate(read_detections(det / "detections.json"), read_truth(sim / "ground_truth.json"))
    print(f"== {tag}")
    print(format_table(table))
    kinds = {r.class_id: r for r in table.surfaces or []}
    parts = []
    for kind, r in kinds.items():
        err = "-" if r.h_mean_mm is None else f"{r.h_mean_mm:.1f}/{r.v_mean_mm:.1f} mm"
        parts.append(f"{kind}: {r.tp}/{r.instances} TP ({r.tp_pct or 0:.1f} %), FP {r.fp} "
                     f"({r.fp_pct or 0:.1f} %), mean dh/dv {err}")
    print(f"{tag}: " + "; ".join(parts) + f"; detect {seconds:.0f} s")
    return {"run": tag, "surfaces": [r.to_dict() for r in table.surfaces or []], "seconds": round(seconds, 1)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--full", action="store_true", help="Scenario I instead of one_room")
    p.add_argument("--scene", default=None, help="a bundled scene or a description file (default: one_room)")
    p.add_argument("--columns", action="store_true", help="simulate columns with objects too")
    p.add_argument("--designs", nargs="+", default=["standard"], choices=["standard", "alt", "third"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--run-dir", type=Path, default=Path("/tmp/bench_surfaces"))
    p.add_argument("--redo", action="store_true", help="simulate and detect again even if the run exists")
    p.add_argument("--json", type=Path, default=None, help="write the figures as JSON")
    a = p.parse_args(argv)
    scene = "I" if a.full else (a.scene or "one_room")
    out = [run(scene, d, a.seed, a.columns, a.run_dir, a.redo) for d in a.designs]
    if a.json:
        a.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
