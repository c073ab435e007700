"""Uploads against a live server (issue 10): responsiveness and memory.

1. ``--parallel`` users (8) each upload a ``--xyz-mb`` (127 MB) XYZ scan at the same time
   while ``/api/health`` and ``/api/me`` are polled every 50 ms: their p50/p95/max
   latency during the uploads (acceptance: health p95 < 200 ms).
2. One binary PLY of ``--ply-gb`` (1.5 GB) is uploaded while the resident memory of the
   server and all its child processes (the upload check) is sampled every 50 ms: peak
   minus idle (acceptance: < 300 MB).

Heavy (several GB of disk, minutes of CPU): run it under the shared lock,

    flock /tmp/sbsc-heavy.lock .venv/bin/python benchmarks/bench_uploads.py
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import psutil

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from app.config import AppSettings  # noqa: E402
from app.users import add_user  # noqa: E402
from tests.app_support import ServerProcess, auth  # noqa: E402

PLY_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])


def write_xyz(path: Path, mb: float, seed: int = 0) -> int:
    """An ``x y z r g b`` text scan of about ``mb`` megabytes (a block of 100,000 random
    points repeated, shifted by 10 m in x each time); returns its points."""
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(0, 10, (100_000, 3))
    rgb = rng.integers(0, 256, (100_000, 3))
    n_total, k = 0, 0
    with open(path, "w") as fh:
        while fh.tell() < mb * 1e6:
            block = "\n".join(f"{x + 10 * k:.4f} {y:.4f} {z:.4f} {r} {g} {b}"
                              for (x, y, z), (r, g, b) in zip(xyz, rgb, strict=True)) + "\n"
            for _ in range(10):
                fh.write(block)
                n_total += len(xyz)
            k += 1
    return n_total


def write_ply(path: Path, gb: float) -> int:
    n = int(gb * 1e9 // PLY_DTYPE.itemsize)
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n"
            "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    rng = np.random.default_rng(1)
    block = np.zeros(2_000_000, PLY_DTYPE)  # one random block, written again and again
    block["x"], block["y"], block["z"] = rng.uniform(0, 10, (3, len(block))).astype(np.float32)
    block["r"] = 128
    data = block.tobytes()
    with open(path, "wb") as fh:
        fh.write(head.encode())
        left = n
        while left:
            k = min(left, len(block))
            fh.write(data[:k * PLY_DTYPE.itemsize])
            left -= k
    return n


def tree_rss_mb(pid: int) -> float:
    try:
        p = psutil.Process(pid)
        procs = [p, *p.children(recursive=True)]
    except psutil.NoSuchProcess:
        return 0.0
    total = 0
    for q in procs:
        try:
            total += q.memory_info().rss
        except psutil.NoSuchProcess:
            pass
    return total / 1e6


def poll(url: str, token: str, stop: threading.Event, out: dict[str, list[float]]) -> None:
    with httpx.Client(base_url=url, timeout=60) as c:
        while not stop.is_set():
            for path in ("/api/health", "/api/me"):
                t = time.perf_counter()
                try:
                    ok = c.get(path, headers=auth(token)).status_code == 200
                except httpx.HTTPError:
                    ok = False
                out.setdefault(path, []).append((time.perf_counter() - t) * 1000 if ok else float("inf"))
            time.sleep(0.05)


def pct(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))] if xs else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parallel", type=int, default=8)
    ap.add_argument("--xyz-mb", type=float, default=127.0)
    ap.add_argument("--ply-gb", type=float, default=1.5)
    ap.add_argument("--work", default=None, help="scratch directory (default: a temporary one)")
    args = ap.parse_args()
    work = Path(args.work or tempfile.mkdtemp(prefix="sbsc-bench-uploads-"))
    work.mkdir(parents=True, exist_ok=True)
    data = work / "data"
    try:
        settings = AppSettings(data_dir=data)
        tokens = [add_user(settings, f"user{i}", "reviewer") for i in range(args.parallel)]
        xyz = work / "scan.xyz"
        t = time.perf_counter()
        n_xyz = write_xyz(xyz, args.xyz_mb)
        print(f"wrote {xyz.stat().st_size / 1e6:.0f} MB XYZ ({n_xyz:,} points) in {time.perf_counter() - t:.0f} s")
        server = ServerProcess(data, {"SBSC_VIEWER": "false"}).start()
        try:
            with httpx.Client(base_url=server.url, timeout=600) as c:
                pid = c.post("/api/projects", json={"name": "bench"}, headers=auth(tokens[0])).json()["id"]
            # 1. responsiveness during parallel uploads
            lat: dict[str, list[float]] = {}
            stop = threading.Event()
            poller = threading.Thread(target=poll, args=(server.url, tokens[0], stop, lat))
            results: list[tuple[int, float]] = []

            def upload(tok: str) -> None:
                t0 = time.perf_counter()
                with httpx.Client(base_url=server.url, timeout=1800) as c, open(xyz, "rb") as fh:
                    r = c.post(f"/api/projects/{pid}/scans", files={"file": ("scan.xyz", fh)}, headers=auth(tok))
                results.append((r.status_code, time.perf_counter() - t0))

            poller.start()
            time.sleep(1.0)
            lat.clear()
            t0 = time.perf_counter()
            threads = [threading.Thread(target=upload, args=(tok,)) for tok in tokens]
            for th in threads:
                th.start()
            for th in threads:
                th.join()
            wall = time.perf_counter() - t0
            stop.set()
            poller.join()
            print(f"{args.parallel} parallel uploads of {args.xyz_mb:.0f} MB: {wall:.1f} s, "
                  f"status {sorted(s for s, _ in results)}")
            for path, xs in lat.items():
                finite = [x for x in xs if x != float("inf")]
                print(f"  {path}: n={len(xs)} failed={len(xs) - len(finite)} p50={pct(finite, 0.5):.0f} ms "
                      f"p95={pct(xs, 0.95):.0f} ms max={max(xs):.0f} ms")
            xyz.unlink()
            shutil.rmtree(data / "projects", ignore_errors=True)
            # 2. memory during a large upload
            ply = work / "big.ply"
            n = write_ply(ply, args.ply_gb)
            idle = tree_rss_mb(server.proc.pid)
            peak, done = idle, threading.Event()

            def watch() -> None:
                nonlocal peak
                while not done.is_set():
                    peak = max(peak, tree_rss_mb(server.proc.pid))
                    time.sleep(0.05)

            w = threading.Thread(target=watch)
            w.start()
            t0 = time.perf_counter()
            with httpx.Client(base_url=server.url, timeout=3600) as c, open(ply, "rb") as fh:
                r = c.post(f"/api/projects/{pid}/scans", files={"file": ("big.ply", fh)}, headers=auth(tokens[0]))
            done.set()
            w.join()
            print(f"upload of a {ply.stat().st_size / 1e9:.2f} GB PLY ({n:,} points): {r.status_code} "
                  f"{r.json().get('points', r.json().get('detail'))} in {time.perf_counter() - t0:.1f} s; "
                  f"server + children RSS idle {idle:.0f} MB, peak {peak:.0f} MB (+{peak - idle:.0f} MB)")
        finally:
            server.stop()
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
