"""Bulk decisions at the largest allowed size while reviewers decide on another project (issue 30).

Starts ``sbsc serve`` (embedded SQLite) with project A of ``--bulk`` detections (default: the
largest bulk allowed, ``BULK_MAX``) and project B of 250. One client sends bulk decisions on
A over all its ids (accept all, reject all, ... ``--rounds`` times) while ``--reviewers``
reviewers, members of B only, make single decisions on B for as long as the bulk requests
run (read, flip, PATCH against the version read). Prints the bulk requests' durations and p50/p95/p99 of the
single decisions; the target is p99 <= 500 ms. Checks that every bulk changed all of A, with
one audit row per change.

    .venv/bin/python benchmarks/bench_bulk_decisions.py [--bulk 100000] [--reviewers 20]
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_review_load import Reviewer, free_port, make_results, start_server  # noqa: E402

from app.config import AppSettings  # noqa: E402
from app.db import Database  # noqa: E402
from app.membership import set_member  # noqa: E402
from app.review_service import BULK_MAX  # noqa: E402
from app.sample import ensure_sample_project  # noqa: E402
from app.users import add_user  # noqa: E402
from sbsc_core.io.ply import write_ply  # noqa: E402


def run(bulk: int, rounds: int, reviewers: int, workdir: Path, hold_s: float = 30.0) -> dict:
    data = workdir / "data"
    settings = AppSettings(data_dir=data, viewer=False)
    rng = np.random.default_rng(0)
    write_ply(workdir / "scan.ply", rng.uniform(0, 3, (100, 3)), rng.integers(0, 255, (100, 3)))
    t = time.perf_counter()
    make_results(workdir / "big", bulk)
    make_results(workdir / "small", 250)
    big = ensure_sample_project(workdir / "scan.ply", workdir / "big", settings=settings, name="A", points=100)
    small = ensure_sample_project(workdir / "scan.ply", workdir / "small", settings=settings, name="B", points=100)
    setup_s = time.perf_counter() - t
    boss = add_user(settings, "boss", "manager")
    tokens = [add_user(settings, f"reviewer{i:02d}", "reviewer") for i in range(reviewers)]
    db = Database(settings.db_url)
    with db.write() as s:
        set_member(s, big, "boss", "manager", None)
        for i in range(reviewers):
            set_member(s, small, f"reviewer{i:02d}", "reviewer", None)
    db.dispose()
    port = free_port()
    proc = start_server(data, port)
    url = f"http://127.0.0.1:{port}"
    hb = {"Authorization": f"Bearer {boss}"}
    bulk_s: list[float] = []
    results: list[dict] = []
    try:
        big_ids = [int(d["id"]) for d in httpx.get(f"{url}/api/projects/{big}/detections", headers=hb,
                                                   timeout=600).json()["detections"]]
        small_ids = [d["id"] for d in httpx.get(f"{url}/api/projects/{small}/detections",
                                                headers={"Authorization": f"Bearer {tokens[0]}"},
                                                timeout=60).json()["detections"]]
        barrier = threading.Barrier(reviewers + 1)
        threads = [Reviewer(url, tokens[i], small_ids, 10**6, i, barrier) for i in range(reviewers)]
        for th in threads:
            th.start()
        barrier.wait()
        t0 = time.perf_counter()
        with httpx.Client(base_url=url, timeout=600, headers=hb) as c:
            body_bytes = 0
            for r in range(rounds):
                status = "accepted" if r % 2 == 0 else "rejected"
                body = json.dumps({"status": status, "ids": big_ids}, separators=(",", ":"))
                body_bytes = len(body)
                t = time.perf_counter()
                resp = c.post(f"/api/projects/{big}/decisions", content=body,
                              headers={"Content-Type": "application/json"})
                bulk_s.append(time.perf_counter() - t)
                results.append({"status": resp.status_code, "changed": resp.json().get("changed")})
            if not rounds:  # the baseline: the reviewers alone, for as long
                time.sleep(hold_s)
        for th in threads:  # the reviewers decide for as long as the bulk requests run
            th.n = 0
        for th in threads:
            th.join()
        wall_s = time.perf_counter() - t0
    finally:
        proc.terminate()
        proc.wait(30)
    with sqlite3.connect(data / "sbsc.db") as con:
        audit = con.execute("SELECT batch, count(*) FROM review_decisions WHERE project_id = ? "
                            "GROUP BY batch", (big,)).fetchall()
    lat = sorted(x for th in threads for x in th.latencies)
    q = statistics.quantiles(lat, n=100)
    errors = [e for th in threads for e in th.errors]
    return {"bulk_size": bulk, "bulk_body_bytes": body_bytes, "rounds": rounds, "setup_s": round(setup_s, 1),
            "bulk_s": [round(x, 2) for x in bulk_s], "bulk_results": results,
            "audit_rows_per_batch": sorted(n for _, n in audit),
            "reviewers": reviewers, "single_decisions": len(lat), "errors": len(errors),
            "error_samples": errors[:3], "seconds": round(wall_s, 1),
            "p50_ms": round(q[49] * 1000, 1), "p95_ms": round(q[94] * 1000, 1), "p99_ms": round(q[98] * 1000, 1),
            "max_ms": round(lat[-1] * 1000, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bulk", type=int, default=BULK_MAX, help="detections of project A, all in each bulk")
    ap.add_argument("--rounds", type=int, default=2, help="bulk requests, one after the other")
    ap.add_argument("--reviewers", type=int, default=20)
    ap.add_argument("--hold", type=float, default=30.0,
                    help="with --rounds 0 (a baseline without bulk requests): how long the reviewers decide")
    ap.add_argument("--json", help="also write the result here")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="sbsc-bulk-") as tmp:
        res = run(args.bulk, args.rounds, args.reviewers, Path(tmp), args.hold)
    for k, v in res.items():
        print(f"{k:>22}: {v}")
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2) + "\n")
    good = (res["errors"] == 0 and res["p99_ms"] <= 500.0
            and all(r == {"status": 200, "changed": args.bulk} for r in res["bulk_results"])
            and res["audit_rows_per_batch"] == [args.bulk] * args.rounds)
    print("OK: p99 of single decisions <= 500 ms, every bulk complete" if good else "FAILED")
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
