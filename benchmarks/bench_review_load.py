"""Load benchmark of the review app: concurrent reviewers making decisions on SQLite.

Starts ``sbsc serve`` (embedded SQLite default) on a free localhost port with a project of
``--detections`` detections, then ``--reviewers`` concurrent reviewers (each its own token
and HTTP connection) each make ``--decisions`` review decisions: read a random detection,
flip it accepted <-> rejected against the version it read, and on 409 (someone else was
quicker) read again and retry. Afterwards it checks that no update was lost: every
successful decision is one audit row and one version step, and each detection's final
state is that of its last decision. Prints p50/p95/p99 latency of the decisions
(PATCH requests) and decisions per second.

    .venv/bin/python benchmarks/bench_review_load.py [--reviewers 50] [--decisions 100]
"""

from __future__ import annotations

import argparse
import json
import random
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from app.config import AppSettings  # noqa: E402
from app.sample import ensure_sample_project  # noqa: E402
from app.users import add_user  # noqa: E402
from sbsc_core.io.ply import write_ply  # noqa: E402


def make_results(out: Path, n: int) -> None:
    """A finished detection output dir (contract 4) with ``n`` detections on one wall."""
    out.mkdir(parents=True)
    wall = {"id": "W01", "origin": [0.0, 0.0, 0.0], "axis_u": [1.0, 0.0, 0.0], "axis_v": [0.0, 0.0, 1.0],
            "normal": [0.0, 1.0, 0.0], "width_m": 50.0, "height_m": 2.5}
    dets = [{"id": f"D{i + 1:04d}", "class": "socket_x1", "wall": "W01",
             "position": [0.2 + 0.1 * i, 0.0, 0.3], "u": 0.2 + 0.1 * i, "v": 0.3, "width_m": 0.08,
             "height_m": 0.08, "alpha": 0.9, "rho_depth": 0.8, "rho_colour": 0.1, "source": "both"}
            for i in range(n)]
    doc = {"schema": "sbsc.detections/1", "pixel_m": 0.005, "walls": [wall], "openings": [],
           "detections": dets}
    (out / "detections.json").write_text(json.dumps(doc))


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(data: Path, port: int) -> subprocess.Popen:
    env = {**__import__("os").environ, "SBSC_DATA_DIR": str(data), "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "app", "serve", "--port", str(port)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=str(ROOT))
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1).status_code == 200:
                return proc
        except httpx.HTTPError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError("server did not start")


class Reviewer(threading.Thread):
    def __init__(self, url: str, token: str, ids: list[str], decisions: int, seed: int,
                 start: threading.Barrier) -> None:
        super().__init__()
        self.url, self.token, self.ids, self.n, self.rng = url, token, ids, decisions, random.Random(seed)
        self.start_barrier = start
        self.latencies: list[float] = []
        self.done: Counter[str] = Counter()  # detection id -> successful decisions
        self.conflicts = 0
        self.errors: list[str] = []

    def run(self) -> None:
        h = {"Authorization": f"Bearer {self.token}"}
        with httpx.Client(base_url=self.url, timeout=60, headers=h) as c:
            self.start_barrier.wait()
            made = 0
            while made < self.n:
                did = self.rng.choice(self.ids)
                try:
                    for _attempt in range(50):
                        d = c.get(f"/api/detections/{did}").json()
                        new = "rejected" if d["review"]["status"] == "accepted" else "accepted"
                        t = time.perf_counter()
                        r = c.patch(f"/api/detections/{did}", json={"status": new, "version": d["review"]["version"]})
                        self.latencies.append(time.perf_counter() - t)
                        if r.status_code == 200:
                            self.done[did] += 1
                            made += 1
                            break
                        if r.status_code == 409:
                            self.conflicts += 1
                            continue
                        self.errors.append(f"{r.status_code} {r.text[:200]}")
                        made += 1
                        break
                except httpx.HTTPError as exc:
                    self.errors.append(f"{type(exc).__name__}: {exc}")
                    made += 1


def run(reviewers: int, decisions: int, n_detections: int, workdir: Path) -> dict:
    data = workdir / "data"
    settings = AppSettings(data_dir=data)
    make_results(workdir / "out", n_detections)
    rng = np.random.default_rng(0)
    write_ply(workdir / "scan.ply", rng.uniform(0, 3, (100, 3)), rng.integers(0, 255, (100, 3)))
    pid = ensure_sample_project(workdir / "scan.ply", workdir / "out", settings=settings, name="load", points=100)
    tokens = [add_user(settings, f"reviewer{i:02d}", "reviewer") for i in range(reviewers)]
    port = free_port()
    proc = start_server(data, port)
    url = f"http://127.0.0.1:{port}"
    try:
        doc = httpx.get(f"{url}/api/projects/{pid}/detections",
                        headers={"Authorization": f"Bearer {tokens[0]}"}, timeout=60).json()
        ids = [d["id"] for d in doc["detections"]]
        barrier = threading.Barrier(reviewers + 1)
        threads = [Reviewer(url, tokens[i], ids, decisions, i, barrier) for i in range(reviewers)]
        for t in threads:
            t.start()
        barrier.wait()
        t0 = time.perf_counter()
        for t in threads:
            t.join()
        wall_s = time.perf_counter() - t0
        final = httpx.get(f"{url}/api/projects/{pid}/detections",
                          headers={"Authorization": f"Bearer {tokens[0]}"}, timeout=60).json()["detections"]
    finally:
        proc.terminate()
        proc.wait(30)
    # ---- consistency: nothing lost
    ok = Counter()
    for t in threads:
        ok.update(t.done)
    errors = [e for t in threads for e in t.errors]
    with sqlite3.connect(data / "sbsc.db") as con:
        trail = con.execute("SELECT detection_id, version_from, version_to, after FROM review_decisions "
                            "ORDER BY id").fetchall()
    per_det: dict[str, list] = {}
    for did, vf, vt, after in trail:
        per_det.setdefault(str(did), []).append((vf, vt, json.loads(after)["status"]))
    lost = []
    for d in final:
        rows = per_det.get(d["id"], [])
        steps = [(vf, vt) for vf, vt, _ in rows]
        if (d["review"]["version"] - 1 != len(rows) or len(rows) != ok[d["id"]]
                or steps != [(v, v + 1) for v in range(1, len(rows) + 1)]
                or (rows and rows[-1][2] != d["review"]["status"])):
            lost.append(d["id"])
    lat = sorted(x for t in threads for x in t.latencies)
    made = sum(ok.values())
    q = statistics.quantiles(lat, n=100)
    return {"reviewers": reviewers, "decisions_each": decisions, "detections": n_detections,
            "decisions": made, "audit_rows": len(trail), "conflicts_409": sum(t.conflicts for t in threads),
            "errors": len(errors), "error_samples": errors[:5], "lost_updates": len(lost),
            "seconds": round(wall_s, 2), "decisions_per_s": round(made / wall_s, 1),
            "patch_requests": len(lat), "p50_ms": round(q[49] * 1000, 1), "p95_ms": round(q[94] * 1000, 1),
            "p99_ms": round(q[98] * 1000, 1), "max_ms": round(lat[-1] * 1000, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reviewers", type=int, default=50)
    ap.add_argument("--decisions", type=int, default=100, help="per reviewer")
    ap.add_argument("--detections", type=int, default=250, help="shared by all (contention)")
    ap.add_argument("--json", help="also write the result here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="sbsc-load-") as tmp:
        res = run(args.reviewers, args.decisions, args.detections, Path(tmp))
    for k, v in res.items():
        print(f"{k:>16}: {v}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
    good = res["errors"] == 0 and res["lost_updates"] == 0 and res["decisions"] == res["audit_rows"] \
        == args.reviewers * args.decisions
    print("OK: no error, no lost update" if good else "FAILED")
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
