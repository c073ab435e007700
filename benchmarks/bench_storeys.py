"""Storeys: a building detected whole against each of its floors detected alone (issue 12).

    flock /tmp/sbsc-heavy.lock .venv/bin/python benchmarks/bench_storeys.py --storeys 2 4 \
        [--scene scenario|one_room] [--step 0.25] [--expected storeys|building|none] \
        [--run-dir /tmp/bench_storeys] [--redo]

For each storey count a building is simulated (``sbsc simulate --scenario building``, one
PLY per station, kept in the run dir) and detected twice over:

* whole: ``sbsc detect`` on every station file of the building, with ``--expected``:
  ``storeys`` the simulator's ``expected.json`` (the building's counts and each storey's,
  contract 3), ``building`` the building's counts only, ``none`` without expected counts;
* alone: ``sbsc detect`` on the station files of one storey only (the same floor scanned
  alone: exactly the same points), with the expected counts of that storey's objects
  (none with ``--expected none``).

Both are evaluated per storey against the building's ground truth (objects of that storey;
a detection of the whole run counts for the storey of its wall), with
:func:`sbsc_core.evaluate.evaluate` at its 10 cm radius. The acceptance is that every storey
is found (same count, floor and ceiling within 2 cm of the truth) and that TP and FP per
storey of the whole run are within 1 of the storey alone (counts; the table gives the
percentages of the storey's instances too). Prints one table and a verdict;
``--json`` writes the figures. Each ``sbsc detect`` runs as its own process and its wall
time and peak RSS (with the worker processes) are reported.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sbsc_core.evaluate import evaluate
from sbsc_core.io.documents import read_truth

SBSC = [sys.executable, "-m", "sbsc_core"]


def _run(cmd: list[str]) -> tuple[float, float]:
    """Run ``cmd``; (wall seconds, peak RSS GiB of the process and its children)."""
    t = time.perf_counter()
    proc = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}\n{proc.stderr}")
    rss_kb = float(proc.stderr.strip().splitlines()[-1])
    return time.perf_counter() - t, rss_kb / 2**20


def _detect(scans: list[Path], sim: Path, expected: Path | None, out: Path, redo: bool
            ) -> tuple[dict, float, float]:
    if redo or not (out / "detections.json").exists():
        exp = [] if expected is None else ["--expected", str(expected)]
        secs, rss = _run([*SBSC, "-q", "detect", *map(str, scans), "--models", str(sim / "models"), *exp,
                          "--out", str(out)])
        (out / "run.json").write_text(json.dumps({"seconds": secs, "rss_gib": rss}))
    run = json.loads((out / "run.json").read_text())
    return json.loads((out / "detections.json").read_text()), run["seconds"], run["rss_gib"]


def _storey_table(doc: dict, truth: dict, sid: str, walls_of: set[str] | None) -> tuple[int, int, int, int]:
    """(instances, TP, FN, FP) of one storey."""
    t = dict(truth, objects=[o for o in truth["objects"] if o["storey"] == sid])
    d = dict(doc, detections=[x for x in doc["detections"] if walls_of is None or x["wall"] in walls_of])
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "truth.json").write_text(json.dumps(t))
        total = evaluate(d, read_truth(Path(tmp) / "truth.json")).total
    return total.instances, total.tp, total.fn, total.fp


def _frame_difference(whole: dict, alone: dict, sid: str) -> tuple[int, float]:
    """(walls of the storey with the same id and frame whole and alone, the largest difference
    of a frame's origin, normal, width or height over the walls of the same id, metres)."""
    w = {x["id"].split("-")[-1]: x for x in whole["walls"] if x.get("storey") == sid}
    a = {x["id"]: x for x in alone["walls"]}
    same, worst = 0, 0.0
    for k in sorted(set(w) & set(a)):
        d = max(float(np.abs(np.subtract(w[k][f], a[k][f])).max()) for f in ("origin", "normal", "width_m", "height_m"))
        same += d == 0.0
        worst = max(worst, d)
    return same, worst


def bench(n: int, scene: str, step: float, run_dir: Path, redo: bool, mode: str = "storeys") -> dict:
    sim = run_dir / f"{scene}_{n}storeys_step{step:g}"
    if not (sim / "ground_truth.json").exists():
        secs, rss = _run([*SBSC, "-q", "simulate", "--scenario", "building", "--scene", scene,
                          "--storeys", str(n), "--step", str(step), "--out", str(sim)])
        print(f"simulated {sim.name} in {secs:.0f} s, peak {rss:.2f} GiB", flush=True)
    truth = json.loads((sim / "ground_truth.json").read_text())
    files = sorted((sim / "stations").iterdir())
    whole_exp: Path | None = None
    if mode == "storeys":
        whole_exp = sim / "expected.json"
        if "storeys" not in json.loads(whole_exp.read_text()):
            raise SystemExit(f"{whole_exp}: no per-storey counts (simulated by an older sbsc: delete {sim})")
    elif mode == "building":
        whole_exp = run_dir / f"{sim.name}_building_expected.json"
        counts = json.loads((sim / "expected.json").read_text())["counts"]
        whole_exp.write_text(json.dumps({"schema": "sbsc.expected/1", "counts": counts}))
    tag = {"storeys": "", "building": "_building", "none": "_noexp"}[mode]
    whole, w_secs, w_rss = _detect(files, sim, whole_exp, run_dir / f"{sim.name}_whole{tag}", redo)
    rows = []
    found = {s["id"]: s for s in whole.get("storeys", [])}
    for st in truth["storeys"]:
        sid = st["id"]
        counts: dict[str, int] = {}
        for o in truth["objects"]:
            if o["storey"] == sid:
                counts[o["class"]] = counts.get(o["class"], 0) + 1
        expected = run_dir / f"{sim.name}_{sid}_expected.json"  # the floor alone holds its own objects
        expected.write_text(json.dumps({"schema": "sbsc.expected/1", "counts": counts}))
        alone, a_secs, a_rss = _detect([f for f in files if f.name.startswith(sid + "_")], sim,
                                       None if mode == "none" else expected,
                                       run_dir / f"{sim.name}_{sid}_alone{'_noexp' if mode == 'none' else ''}",
                                       redo)
        walls = {w["id"] for w in whole["walls"] if w.get("storey") == sid}
        # surfaces beyond walls (ceilings, columns: ``--ceilings`` / ``--columns``) carry the storey in their id
        surfaces = {x["id"] for x in whole.get("surfaces", []) if str(x["id"]).startswith(f"{sid}-")}
        got = found.get(sid)
        rows.append({
            "storey": sid, "truth_floor_z": st["floor_z"], "truth_ceiling_z": st["ceiling_z"],
            "found_floor_z": got and got["floor_z"], "found_ceiling_z": got and got["ceiling_z"],
            "walls_whole": len(walls), "walls_alone": len(alone["walls"]),
            "walls_same": _frame_difference(whole, alone, sid)[0],
            "frame_difference_m": _frame_difference(whole, alone, sid)[1],
            "whole": _storey_table(whole, truth, sid, walls | surfaces), "alone": _storey_table(alone, truth, sid, None),
            "alone_seconds": a_secs, "alone_rss_gib": a_rss,
        })
    return {"storeys": n, "scene": scene, "step": step, "expected": mode, "whole_seconds": w_secs,
            "whole_rss_gib": w_rss,
            "storeys_found": len(found), "rows": rows}


def _pct(n: int, of: int) -> str:
    return f"{100.0 * n / of:.1f}" if of else "-"


def verdict(res: dict) -> bool:
    ok = res["storeys_found"] == res["storeys"]
    for r in res["rows"]:
        ok &= r["found_floor_z"] is not None and abs(r["found_floor_z"] - r["truth_floor_z"]) <= 0.02
        ok &= r["found_ceiling_z"] is not None and abs(r["found_ceiling_z"] - r["truth_ceiling_z"]) <= 0.02
        ok &= abs(r["whole"][1] - r["alone"][1]) <= 1 and abs(r["whole"][3] - r["alone"][3]) <= 1
    return bool(ok)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--storeys", type=int, nargs="+", default=[2, 4])
    ap.add_argument("--scene", choices=["scenario", "one_room"], default="scenario")
    ap.add_argument("--step", type=float, default=0.25, help="scanner angular step, degrees")
    ap.add_argument("--run-dir", type=Path, default=Path("/tmp/bench_storeys"))
    ap.add_argument("--expected", choices=["storeys", "building", "none"], default="storeys",
                    help="expected counts of the whole run: per storey (default), the building's, none")
    ap.add_argument("--redo", action="store_true", help="detect again")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    args.run_dir.mkdir(parents=True, exist_ok=True)
    results = []
    for n in args.storeys:
        res = bench(n, args.scene, args.step, args.run_dir, args.redo, args.expected)
        results.append(res)
        print(f"\n{n} storeys ({args.scene}, {args.step:g} deg, expected: {args.expected}): "
              f"{res['storeys_found']} found; whole building "
              f"{res['whole_seconds']:.0f} s, peak {res['whole_rss_gib']:.2f} GiB")
        print(f"{'storey':6} {'floor z truth/found':>20} {'ceiling z truth/found':>22} {'walls w/a':>9} {'same':>4} "
              f"{'inst':>4} {'TP whole/alone':>14} {'FP whole/alone':>14} {'TP % whole/alone':>16} "
              f"{'FP % whole/alone':>16}")
        for r in res["rows"]:
            ff = "-" if r["found_floor_z"] is None else f"{r['found_floor_z']:.3f}"
            fc = "-" if r["found_ceiling_z"] is None else f"{r['found_ceiling_z']:.3f}"
            print(f"{r['storey']:6} {r['truth_floor_z']:>9.3f}/{ff:<10} {r['truth_ceiling_z']:>10.3f}/{fc:<11} "
                  f"{r['walls_whole']:>4}/{r['walls_alone']:<4} {r.get('walls_same', '-'):>4} {r['whole'][0]:>4} "
                  f"{r['whole'][1]:>7}/{r['alone'][1]:<6} {r['whole'][3]:>7}/{r['alone'][3]:<6} "
                  f"{_pct(r['whole'][1], r['whole'][0]):>8}/{_pct(r['alone'][1], r['alone'][0]):<7} "
                  f"{_pct(r['whole'][3], r['whole'][0]):>8}/{_pct(r['alone'][3], r['alone'][0]):<7}")
        print("largest wall frame difference whole / alone: "
              + ", ".join(f"{r['storey']} {1000 * r['frame_difference_m']:.3g} mm" for r in res["rows"]))
        print("verdict:", "PASS" if verdict(res) else "FAIL")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
