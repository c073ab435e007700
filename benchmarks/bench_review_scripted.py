"""A scripted reviewer: uncertain-first review with a bulk accept at or above a threshold.

Imports a finished ``sbsc detect`` output (with its scan and ground truth) into a fresh
review service, then reviews it through the REST API the way issue 14 asks:

1. a dry run of ``POST /api/projects/{pid}/decisions`` with
   ``{"status": "accepted", "filter": {"min_confidence": T, "review": "pending"}}`` states
   the count; the reviewer confirms it (``expect``) and the objects are accepted in bulk;
2. the rest are decided one by one, least sure first (``?order=uncertain``): accepted when
   the ground truth has an object of that class there (contract 5, 0.10 m), else rejected.

Prints the single decisions without and with the bulk step, their fall in percent, and how
many wrong objects (no truth object of that class there) were accepted in bulk, and which
objects were wrong in bulk or left to single decisions (class, confidence, what the truth has
there). ``T`` applies to the detections' calibrated ``confidence`` when they have one, else
to ``alpha``.

The calibrated threshold. ``confidence`` is calibrated: an object of confidence c is an
object of its class at that place with probability c (``sbsc_core/recognition/confidence.py``, fitted
and checked on held-out simulated seeds by ``benchmarks/bench_confidence.py``; the shipped
calibration's held-out expected calibration error is in its ``info``). A bulk accept that
may get at most a share ``1 - P`` of its objects wrong therefore accepts the objects with
``confidence >= P``: ``T = P``, by default ``P = 0.99`` (``--precision``). It is not fitted
to the scene reviewed. ``--threshold`` overrides it (e.g. for alpha without a calibration).

    .venv/bin/python benchmarks/bench_review_scripted.py DETECT_OUT SCAN TRUTH [--precision 0.99]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from fastapi.testclient import TestClient  # noqa: E402

from app.config import AppSettings  # noqa: E402
from app.sample import ensure_sample_project  # noqa: E402
from app.server import create_app  # noqa: E402
from app.users import add_user  # noqa: E402
from sbsc_core.evaluate import evaluate  # noqa: E402
from sbsc_core.io.documents import read_truth  # noqa: E402


def review(out_dir: Path, scan: Path, truth_path: Path, threshold: float) -> dict:
    with tempfile.TemporaryDirectory(prefix="sbsc-review-") as tmp:
        settings = AppSettings(data_dir=Path(tmp) / "data", viewer=False)
        pid = ensure_sample_project(scan, out_dir, settings=settings, name="scripted", points=1,
                                    models=out_dir.parent / "models" if (out_dir.parent / "models").is_dir()
                                    else None)
        admin = add_user(settings, "admin", "admin")  # an imported project has only the admins as members
        token = add_user(settings, "bot", "reviewer")
        h = {"Authorization": f"Bearer {token}"}
        with TestClient(create_app(settings, start_jobs=False)) as c:
            c.post(f"/api/projects/{pid}/members", json={"user": "bot", "role": "reviewer"},
                   headers={"Authorization": f"Bearer {admin}"}).raise_for_status()
            doc = c.get(f"/api/projects/{pid}/detections", headers=h).json()
            ref_doc = {**doc, "detections": [{**d, "id": d["id"]} for d in doc["detections"]]}
            table = evaluate(ref_doc, read_truth(truth_path))
            correct = {m.detection_id for m in table.matches}
            n = len(doc["detections"])
            score_kind = "confidence" if any(d.get("confidence") is not None for d in doc["detections"]) \
                else "alpha"
            t0 = time.perf_counter()
            body = {"status": "accepted", "filter": {"min_confidence": threshold, "review": "pending"}}
            dry = c.post(f"/api/projects/{pid}/decisions", headers=h, json={**body, "dry_run": True}).json()
            bulk = c.post(f"/api/projects/{pid}/decisions", headers=h,
                          json={**body, "expect": dry["matched"]}).json()
            bulk_ids = set(bulk["ids"])
            singles = 0
            rest = c.get(f"/api/projects/{pid}/detections?status=pending&order=uncertain",
                         headers=h).json()["detections"]
            for d in rest:
                status = "accepted" if d["id"] in correct else "rejected"
                r = c.patch(f"/api/detections/{d['id']}", headers=h,
                            json={"status": status, "version": d["review"]["version"]})
                r.raise_for_status()
                singles += 1
            elapsed = time.perf_counter() - t0
            summary = c.get(f"/api/projects/{pid}/summary", headers=h).json()
    wrong_bulk = sorted(bulk_ids - correct)
    truth = read_truth(truth_path)

    def why(d: dict) -> dict:
        """The object, and the nearest truth object (or distractor) to it."""
        p = np.asarray(d["position"], float)
        near = min(((float(np.linalg.norm(np.asarray(o.position) - p)), o.class_id) for o in truth.objects),
                   default=(float("inf"), None))
        out = {"class": d["class"], "confidence": d.get("confidence"), "alpha": d.get("alpha"),
               "source": d.get("source"), "correct": d["id"] in correct,
               "nearest_truth": near[1], "nearest_truth_m": round(near[0], 3)}
        dis = [x for x in truth.extra.get("distractors") or []
               if "position" in x]
        if dis:
            dd = min(dis, key=lambda x: float(np.linalg.norm(np.asarray(x["position"], float) - p)))
            out["nearest_distractor"] = dd.get("kind") or dd.get("class")
            out["nearest_distractor_m"] = round(float(np.linalg.norm(np.asarray(dd["position"], float) - p)), 3)
        return out

    by_id = {d["id"]: d for d in doc["detections"]}
    return {"detections": n, "true_positives": len(correct), "score": score_kind,
            "threshold": threshold, "bulk_accepted": len(bulk_ids), "wrong_in_bulk": len(wrong_bulk),
            "single_without_bulk": n, "single_with_bulk": singles,
            "single_fall_pct": round(100.0 * (n - singles) / n, 1) if n else None,
            "review_s": round(elapsed, 2), "summary_bulk": summary["bulk"],
            "summary_single": summary["single"],
            "wrong_in_bulk_objects": [why(by_id[i]) for i in wrong_bulk],
            "single_objects": [why(by_id[d["id"]]) for d in rest]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("detect_out", type=Path)
    ap.add_argument("scan", type=Path)
    ap.add_argument("truth", type=Path)
    ap.add_argument("--precision", type=float, default=0.99,
                    help="the share of right objects a bulk accept must reach; the calibrated threshold")
    ap.add_argument("--threshold", type=float, default=None, help="override the calibrated threshold")
    ap.add_argument("--json", type=Path, help="also write the result here")
    args = ap.parse_args()
    threshold = args.precision if args.threshold is None else args.threshold
    res = review(args.detect_out, args.scan, args.truth, threshold)
    res["threshold_from"] = "--threshold" if args.threshold is not None else f"calibrated precision >= {args.precision}"
    if args.json:
        args.json.write_text(json.dumps(res, indent=1), encoding="utf-8")
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
