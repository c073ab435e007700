"""Benchmark ``sbsc detect`` on a simulated floor: points per second per stage, peak memory.

    .venv/bin/python benchmarks/bench_detect.py [--scenario I] [--run-dir runs/bench_I]

Simulates the scenario once (kept in the run dir), then runs the detection in this process
and prints, per stage, seconds and points per second, the total, and the peak resident
memory as a multiple of the scan's size in memory (float32 xyz + uint8 rgb).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

from sbsc_core.pipeline import detect_to_dir


def peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


class TreeRssSampler(threading.Thread):
    """Samples the resident memory of this process and its children (the per-wall workers)
    every 0.1 s from /proc and keeps the largest sum: the job's real peak footprint."""

    def __init__(self) -> None:
        super().__init__(daemon=True)
        self.peak = 0
        self._halt = threading.Event()

    @staticmethod
    def _rss(pid: int) -> int:
        try:
            with open(f"/proc/{pid}/statm") as fh:
                return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError, IndexError):
            return 0

    def _children(self) -> list[int]:
        me, out = os.getpid(), []
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                try:
                    with open(f"/proc/{entry}/stat") as fh:
                        if int(fh.read().rsplit(")", 1)[1].split()[1]) == me:
                            out.append(int(entry))
                except (OSError, ValueError, IndexError):
                    continue
        return out

    def run(self) -> None:
        while not self._halt.wait(0.1):
            total = self._rss(os.getpid()) + sum(self._rss(p) for p in self._children())
            self.peak = max(self.peak, total)

    def stop(self) -> int:
        self._halt.set()
        self.join()
        return self.peak


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="I", choices=["I", "II"])
    ap.add_argument("--run-dir", default=None)
    args = ap.parse_args()
    run = Path(args.run_dir or f"runs/bench_{args.scenario}")
    scan = run / "scan"
    if not (scan / "scan.ply").exists():
        subprocess.run([sys.executable, "-m", "sbsc_core", "simulate", "--scenario", args.scenario,
                        "--out", str(scan)], check=True)
    base_rss = peak_rss_bytes()
    sampler = TreeRssSampler()
    sampler.start()
    t = time.perf_counter()
    summary = detect_to_dir([scan / "scan.ply"], scan / "models", expected=scan / "expected.json",
                            out=run / "detect")
    wall = time.perf_counter() - t
    n = summary["points"]
    scan_bytes = n * (3 * 4 + 3)
    print(f"scenario {args.scenario}: {n:,} points, {summary['walls']} walls, "
          f"{summary['detections']} detections")
    print(f"{'stage':<14}{'seconds':>10}{'Mpoints/s':>12}")
    for stage, sec in summary["timings"].items():
        rate = n / sec / 1e6 if sec > 0 else float("inf")
        print(f"{stage:<14}{sec:>10.2f}{rate:>12.2f}")
    tree = sampler.stop()
    peak = peak_rss_bytes()
    print(f"wall-clock total {wall:.1f} s = {n / wall / 1e6:.2f} Mpoints/s")
    print(f"peak RSS main process {peak / 2**30:.2f} GiB (before detection {base_rss / 2**30:.2f} GiB); "
          f"peak of main + workers together {tree / 2**30:.2f} GiB; scan in memory "
          f"{scan_bytes / 2**30:.2f} GiB; peak/scan = {tree / scan_bytes:.2f}")
    (run / "bench.json").write_text(json.dumps({
        "points": n, "timings": summary["timings"], "wall_s": wall,
        "peak_rss_bytes": peak, "peak_tree_rss_bytes": tree, "scan_bytes": scan_bytes},
        indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
