"""Benchmark ``sbsc detect --scheduler`` on a local Dask cluster with one and with two workers.

    flock /tmp/sbsc-heavy.lock .venv/bin/python benchmarks/bench_dask.py [--run-dir runs/bench_I]
        [--workers 1 2]

For each worker count, starts ``dask scheduler`` and that many ``dask worker`` processes (one
thread each) on 127.0.0.1, runs the detection of the run dir's scan through the scheduler,
stops the cluster, and prints the elapsed seconds of the task stages (reading the parts for
the sample, writing the partitions, the per-wall stages) and the speed-up of each count over
the first. Uses the scan that ``bench_detect.py`` simulated (``RUN_DIR/scan``).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def start_cluster(n: int, tmp: Path) -> tuple[str, list[subprocess.Popen]]:
    dask = str(Path(sys.executable).with_name("dask"))
    from sbsc_core.pipeline.worker_env import worker_environment

    env = {**os.environ, **worker_environment(), "PYTHONPATH": str(ROOT)}
    info = tmp / f"scheduler-{n}.json"
    info.unlink(missing_ok=True)
    log = open(tmp / f"cluster-{n}.log", "w")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(info)], env=env, stdout=log, stderr=subprocess.STDOUT,
                              start_new_session=True)]
    while not info.exists():
        time.sleep(0.2)
    address = json.loads(info.read_text())["address"]
    for _ in range(n):
        procs.append(subprocess.Popen([dask, "worker", address, "--host", "127.0.0.1", "--nworkers", "1",
                                       "--nthreads", "1", "--no-dashboard", "--memory-limit", "0"],
                                      env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True))
    from distributed import Client

    with Client(address, timeout="30s") as client:
        client.wait_for_workers(n, timeout=300)
    return address, procs


def stop_cluster(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run-dir", default="runs/bench_I")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args()
    from sbsc_core.pipeline.detect import detect_to_dir

    run = Path(args.run_dir)
    scan = run / "scan"
    rows = []
    for n in args.workers:
        address, procs = start_cluster(n, run)
        try:
            t = time.perf_counter()
            s = detect_to_dir([scan / "scan.ply"], scan / "models", expected=scan / "expected.json",
                              out=run / f"dask_{n}", scheduler=address)
            wall = time.perf_counter() - t
        finally:
            stop_cluster(procs)
        tm = s["timings"]
        tasks = tm["reading"] + tm["partition"] + tm["walls_elapsed"]
        rows.append({"workers": n, "wall_s": wall, "reading": tm["reading"], "partition": tm["partition"],
                     "walls_elapsed": tm["walls_elapsed"], "task_stages": tasks, "detections": s["detections"],
                     "points": s["points"]})
        print(f"{n} worker(s): whole {wall:.1f} s; reading {tm['reading']:.1f} s, partition {tm['partition']:.1f} s, "
              f"per-wall stages {tm['walls_elapsed']:.1f} s; {s['detections']} detections", flush=True)
    base = rows[0]
    for r in rows[1:]:
        print(f"{r['workers']} vs {base['workers']} worker(s): per-wall stages "
              f"{base['walls_elapsed'] / r['walls_elapsed']:.2f}x, all task stages "
              f"{base['task_stages'] / r['task_stages']:.2f}x, whole command {base['wall_s'] / r['wall_s']:.2f}x")
    (run / "bench_dask.json").write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
