"""Benchmark ``sbsc detect``: the whole command and each stage, and the peak memory of its process tree.

    flock /tmp/sbsc-heavy.lock .venv/bin/python benchmarks/bench_detect.py [--scenario I]
        [--run-dir runs/bench_I] [--tiles 4] [--repeat 2] [--tree OLD_CHECKOUT] [--tree .]

Simulates the scenario once (kept in the run dir). ``--tiles N`` makes a building of N
copies of the scan side by side (files only, written once: the same floor shifted in plan,
so that every copy is found as its own rooms). Each ``--tree`` (a checkout of the project;
default this one) runs the detection in a fresh process, ``python -c`` with that tree first
on the path, one after the other in this run: that is how an old and a new commit are
compared on the same machine at the same time. For each tree it prints the wall-clock time
and points per second of the whole command, the seconds per stage that the detection
reports, the CPU seconds of all its processes (less sensitive than the wall-clock time to
other work on a shared machine), and the peak resident memory of the whole process tree
(the command and its workers, sampled every 0.1 s from /proc): all resident pages, and the
anonymous ones (without file pages the kernel may drop). ``--repeat N`` runs the trees N
times, taking turns, and compares the fastest run of each. At the end it prints a digest of
each tree's documents (detections, RoIs, suggestions) of its last run, and which trees'
are identical: a speed-up must not change the results.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

RUNNER = """
import json, sys
from pathlib import Path
try:  # what `sbsc detect` does before numpy is imported (where the checkout has it)
    try:
        from sbsc_core.pipeline.cpu_features import prefer_fast_sort
    except ImportError:  # a checkout of the flat layout (before issue 31)
        from sbsc_core.cpu_features import prefer_fast_sort
    prefer_fast_sort()
except ImportError:
    pass
try:
    from sbsc_core.pipeline.allocator import keep_freed_memory
    keep_freed_memory()
except ImportError:
    pass
try:
    from sbsc_core.pipeline.detect import detect_to_dir
except ImportError:  # a checkout of the flat layout (before issue 31)
    from sbsc_core.pipeline import detect_to_dir
args = json.loads(sys.argv[1])
s = detect_to_dir([Path(p) for p in args["scans"]], Path(args["models"]), expected=args["expected"] and Path(args["expected"]),
                  out=Path(args["out"]))
print("SUMMARY " + json.dumps({k: s[k] for k in ("points", "walls", "detections", "timings")}))
"""


class TreeRssSampler(threading.Thread):
    """Peak resident memory (all pages, and anonymous pages) of a process and its descendants."""

    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid = pid
        self.peak = 0
        self.peak_anon = 0
        self.peak_main = 0  # the command's own process
        self.peak_child = 0  # the largest single worker
        self._halt = threading.Event()

    @staticmethod
    def _mem(pid: int) -> tuple[int, int]:
        rss = anon = 0
        try:
            with open(f"/proc/{pid}/status") as fh:
                for line in fh:
                    if line.startswith("VmRSS:"):
                        rss = int(line.split()[1]) * 1024
                    elif line.startswith("RssAnon:"):
                        anon = int(line.split()[1]) * 1024
        except (OSError, ValueError, IndexError):
            pass
        return rss, anon

    @staticmethod
    def _tree(root: int) -> list[int]:
        parent: dict[int, int] = {}
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                try:
                    with open(f"/proc/{entry}/stat") as fh:
                        parent[int(entry)] = int(fh.read().rsplit(")", 1)[1].split()[1])
                except (OSError, ValueError, IndexError):
                    continue
        out, todo = [root], [root]
        while todo:
            p = todo.pop()
            kids = [c for c, pp in parent.items() if pp == p]
            out += kids
            todo += kids
        return out

    def run(self) -> None:
        while not self._halt.wait(0.1):
            mems = [self._mem(p) for p in self._tree(self.pid)]
            self.peak = max(self.peak, sum(m[0] for m in mems))
            self.peak_anon = max(self.peak_anon, sum(m[1] for m in mems))
            self.peak_main = max(self.peak_main, mems[0][0])
            self.peak_child = max([self.peak_child] + [m[0] for m in mems[1:]])

    def stop(self) -> tuple[int, int]:
        self._halt.set()
        self.join()
        return self.peak, self.peak_anon


def tile_scans(scan: Path, tiles: int, out_dir: Path) -> list[Path]:
    """``scan`` and ``tiles - 1`` copies shifted in plan by the scan's extent plus 5 m (binary
    PLY, float32 world coordinates: a floor in local coordinates), written chunk by chunk."""
    from sbsc_core.io.scans import iter_scan, scan_point_count

    paths = [scan]
    if tiles <= 1:
        return paths
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for c in iter_scan(scan):
        w = c.xyz.astype(np.float64) + c.origin
        lo, hi = np.minimum(lo, w.min(axis=0)), np.maximum(hi, w.max(axis=0))
    size = hi - lo + 5.0
    cols = int(np.ceil(np.sqrt(tiles)))
    for k in range(1, tiles):
        path = out_dir / f"tile_{k}.ply"
        paths.append(path)
        if path.exists():
            continue
        shift = np.array([(k % cols) * size[0], (k // cols) * size[1], 0.0])
        n = scan_point_count(scan)
        header = ("ply\nformat binary_little_endian 1.0\ncomment a shifted copy of a scan (bench_detect.py)\n"
                  f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
                  "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
        record = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as fh:
            fh.write(header.encode("ascii"))
            for c in iter_scan(scan):
                w = c.xyz.astype(np.float64) + c.origin + shift
                rec = np.empty(len(c), record)
                rec["x"], rec["y"], rec["z"] = w.T
                rec["r"], rec["g"], rec["b"] = c.rgb.T
                rec.tofile(fh)
        tmp.rename(path)
    return paths


def output_digest(out: Path) -> str:
    """SHA-256 (first 16 hex digits) of a detection's documents (detections, RoIs, suggestions):
    equal digests mean byte-identical results."""
    h = hashlib.sha256()
    for name in ("detections.json", "rois.json", "suggestions.json"):
        f = out / name
        h.update(name.encode())
        h.update(f.read_bytes() if f.exists() else b"-")
    return h.hexdigest()[:16]


def _children_cpu() -> float:
    """User + system CPU seconds of this process's finished descendants."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_tree(tree: Path, scans: list[Path], models: Path, expected: Path | None, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    args = json.dumps({"scans": [str(p) for p in scans], "models": str(models),
                       "expected": str(expected) if expected else None, "out": str(out)})
    load0 = os.getloadavg()[0]
    cpu0 = _children_cpu()
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", RUNNER, args], env=env, cwd=tree, stdout=subprocess.PIPE, text=True)
    sampler = TreeRssSampler(proc.pid)
    sampler.start()
    stdout, _ = proc.communicate()
    wall = time.perf_counter() - t
    cpu = _children_cpu() - cpu0  # the command and its workers (each waited for by its parent)
    peak, anon = sampler.stop()
    if proc.returncode != 0:
        raise SystemExit(f"{tree}: detect failed ({proc.returncode})")
    summary = json.loads(next(line for line in stdout.splitlines() if line.startswith("SUMMARY "))[8:])
    return {"tree": str(tree), "wall_s": wall, "cpu_s": cpu, "peak_tree_rss_bytes": peak, "peak_tree_anon_bytes": anon,
            "peak_main_rss_bytes": sampler.peak_main, "peak_worker_rss_bytes": sampler.peak_child,
            "load_before": load0, "load_after": os.getloadavg()[0], **summary}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="I", choices=["I", "II"])
    ap.add_argument("--run-dir", default=None)
    ap.add_argument("--tiles", type=int, default=1, help="copies of the floor side by side (a bigger building)")
    ap.add_argument("--tree", action="append", default=None, help="checkout to run (repeatable; default: this one)")
    ap.add_argument("--repeat", type=int, default=1, help="runs of each tree, taking turns (the fastest is compared)")
    args = ap.parse_args()
    run = Path(args.run_dir or f"runs/bench_{args.scenario}")
    scan = run / "scan"
    if not (scan / "scan.ply").exists():
        run.mkdir(parents=True, exist_ok=True)  # simulate creates only the last folder
        subprocess.run([sys.executable, "-m", "sbsc_core", "simulate", "--scenario", args.scenario,
                        "--out", str(scan)], check=True)
    scans = tile_scans(scan / "scan.ply", args.tiles, run)
    expected = scan / "expected.json" if args.tiles == 1 else None
    trees = [Path(t) for t in (args.tree or [Path(__file__).resolve().parents[1]])]
    results = []
    for rep in range(args.repeat):  # the trees take turns, so that other work on the machine hits each alike
        for k, tree in enumerate(trees):
            r = run_tree(tree, scans, scan / "models", expected, run / f"detect_{k}")
            r["repeat"] = rep
            results.append(r)
            n = r["points"]
            print(f"{tree}: {n:,} points in {len(scans)} file(s), {r['walls']} walls, {r['detections']} detections")
            print(f"  whole command {r['wall_s']:.1f} s = {n / r['wall_s'] / 1e6:.2f} Mpoints/s, {r['cpu_s']:.1f} CPU s "
                  f"(all processes); peak of the process tree {r['peak_tree_rss_bytes'] / 2**30:.2f} GiB resident, "
                  f"{r['peak_tree_anon_bytes'] / 2**30:.2f} GiB anonymous; machine load (1 min) "
                  f"{r['load_before']:.1f} before, {r['load_after']:.1f} after; largest single process: main "
                  f"{r['peak_main_rss_bytes'] / 2**30:.2f} GiB, a worker {r['peak_worker_rss_bytes'] / 2**30:.2f} GiB",
                  flush=True)
            print(f"  {'stage':<14}{'seconds':>10}{'Mpoints/s':>12}")
            for stage, sec in r["timings"].items():
                rate = n / sec / 1e6 if sec > 0 else float("inf")
                print(f"  {stage:<14}{sec:>10.2f}{rate:>12.2f}", flush=True)
    digests = {str(t): output_digest(run / f"detect_{k}") for k, t in enumerate(trees)}
    for t, dig in digests.items():
        same = [str(u) for u in trees if str(u) != t and digests[str(u)] == dig]
        print(f"outputs of {t}: {dig}" + (f" (identical to {', '.join(same)})" if same else ""))
    if len(trees) > 1:  # the fastest run of each tree (the one least disturbed by other work)
        best = [min((r for r in results if r["tree"] == str(t)), key=lambda r: r["wall_s"]) for t in trees]
        base = best[0]
        for r in best[1:]:
            print(f"throughput {r['tree']} / {base['tree']} (fastest of {args.repeat} run(s) each): "
                  f"{(r['points'] / r['wall_s']) / (base['points'] / base['wall_s']):.2f}x; "
                  f"per CPU second {(r['points'] / r['cpu_s']) / (base['points'] / base['cpu_s']):.2f}x")
    (run / "bench.json").write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
