"""Learning from decisions (issue 14, item 9): review one floor, run the next with its exemplars.

Two floors of one building are two simulated scans of the same scene with the same object
products (``--designs``) and different scanner noise, clutter and design changes (two
seeds). The model library is another product family (``--library-designs``), as when a
library is bought and the building has other products: recognition misses some objects.

1. ``sbsc detect`` on floor 1 with the library; the result is imported into a fresh review
   service.
2. A scripted reviewer decides floor 1 by its ground truth through the REST API: a
   detection of the right class at a truth object (contract 5, 0.10 m) is accepted, one of
   another class there is relabelled (accepted as the truth's class), the rest rejected;
   every truth object nothing was found at is added (``POST /api/projects/{pid}/detections``,
   snapped to the relief).
3. A manager learns the exemplars (``POST /api/projects/{pid}/exemplars``) and downloads
   them (``GET /api/projects/{pid}/exemplars.zip``).
4. ``sbsc detect`` on floor 2 with the library and with the exemplar library; both are
   evaluated against floor 2's ground truth.

Prints TP / FN / FP of floor 2 without and with the exemplars, and the detect seconds.

    .venv/bin/python benchmarks/bench_learning.py --run-dir /tmp/learn [--scene one_room]
        [--seeds 1 2] [--designs alt] [--library-designs standard] [--json out.json]
"""

from __future__ import annotations

import argparse
import io
import json
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fastapi.testclient import TestClient  # noqa: E402

from app.config import AppSettings  # noqa: E402
from app.sample import ensure_sample_project  # noqa: E402
from app.server import create_app  # noqa: E402
from app.users import add_user  # noqa: E402
from sbsc_core.evaluate import evaluate  # noqa: E402
from sbsc_core.io.documents import read_truth  # noqa: E402

MATCH_M = 0.10  # contract 5's match radius


def sbsc(*args: str) -> float:
    """Run an ``sbsc`` command of this checkout; returns its seconds."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "sbsc_core.cli", "-q", *args], check=True, cwd=ROOT,
                   env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    return time.perf_counter() - t0


def simulate(out: Path, *, scene: str, seed: int, designs: str, library_designs: str) -> None:
    if (out / "ground_truth.json").is_file():
        return
    scene_args = ["--scenario", scene] if scene in ("I", "II") else ["--scene", scene]
    sbsc("simulate", *scene_args, "--realistic", "--clutter", "--designs", designs,
         "--library-designs", library_designs, "--seed", str(seed), "--out", str(out))


def detect(scan_dir: Path, models: Path, out: Path) -> float:
    if (out / "detections.json").is_file():
        return float("nan")
    return sbsc("detect", str(scan_dir / "scan.ply"), "--models", str(models), "--out", str(out))


def figures(det_dir: Path, truth: Path) -> dict:
    doc = json.loads((det_dir / "detections.json").read_text(encoding="utf-8"))
    t = evaluate(doc, read_truth(truth)).total
    return {"instances": t.instances, "tp": t.tp, "fn": t.fn, "fp": t.fp}


def wall_uv(walls: list[dict], p: np.ndarray, normal: np.ndarray | None) -> tuple[str, float, float] | None:
    """The detected wall a truth position lies on (closest plane within 0.15 m, facing the
    same way), with its (u, v) there."""
    best = None
    for w in walls:
        o = np.asarray(w["origin"], float)
        n = np.asarray(w["normal"], float)
        if normal is not None and float(np.dot(n, normal)) < 0.7:
            continue
        dist = abs(float(np.dot(p - o, n)))
        u = float(np.dot(p - o, np.asarray(w["axis_u"], float)))
        v = float(np.dot(p - o, np.asarray(w["axis_v"], float)))
        if dist < 0.15 and 0.0 <= u <= w["width_m"] and 0.0 <= v <= w["height_m"]:
            if best is None or dist < best[0]:
                best = (dist, w["id"], u, v)
    return None if best is None else best[1:]


def review_floor(det_dir: Path, scan: Path, truth_path: Path, models: Path, dest: Path) -> dict:
    """Review floor 1 by its truth through the REST API and write its exemplar library to
    ``dest``; returns the counts of the decisions."""
    truth = read_truth(truth_path)
    walls = json.loads((det_dir / "detections.json").read_text(encoding="utf-8"))["walls"]
    with tempfile.TemporaryDirectory(prefix="sbsc-learn-") as tmp:
        settings = AppSettings(data_dir=Path(tmp) / "data", viewer=False)
        pid = ensure_sample_project(scan, det_dir, settings=settings, name="floor 1", points=1, models=models)
        rev = {"Authorization": f"Bearer {add_user(settings, 'bot', 'reviewer')}"}
        boss = {"Authorization": f"Bearer {add_user(settings, 'boss', 'manager')}"}
        counts = {"accepted": 0, "relabelled": 0, "rejected": 0, "added": 0, "not_addable": 0}
        with TestClient(create_app(settings, start_jobs=False)) as c:
            dets = c.get(f"/api/projects/{pid}/detections", headers=rev).json()["detections"]
            t_xyz = np.array([o.position for o in truth.objects], float).reshape(-1, 3)
            found: set[int] = set()
            # nearest truth object of each detection; each truth object explains one detection
            pairs = sorted(((float(np.linalg.norm(t_xyz - np.asarray(d["position"]), axis=1).min()), k)
                            for k, d in enumerate(dets)) if len(t_xyz) else [])
            taken: dict[int, int] = {}
            for dist, k in pairs:
                d = dets[k]
                if dist > MATCH_M:
                    continue
                near = np.linalg.norm(t_xyz - np.asarray(d["position"]), axis=1)
                # the same class first, else the nearest free truth object
                order = sorted(range(len(near)), key=lambda i: (truth.objects[i].class_id != d["class"], near[i]))
                for i in order:
                    if near[i] <= MATCH_M and i not in found:
                        found.add(i)
                        taken[k] = i
                        break
            for k, d in enumerate(dets):
                body = {"version": d["review"]["version"]}
                if k in taken:
                    cls = truth.objects[taken[k]].class_id
                    body["status"] = "accepted"
                    if cls != d["class"]:
                        body["class"] = cls
                        counts["relabelled"] += 1
                    else:
                        counts["accepted"] += 1
                else:
                    body["status"] = "rejected"
                    counts["rejected"] += 1
                r = c.patch(f"/api/detections/{d['id']}", headers=rev, json=body)
                r.raise_for_status()
            for i, o in enumerate(truth.objects):
                if i in found:
                    continue
                where = wall_uv(walls, np.asarray(o.position, float), np.asarray(o.normal, float))
                if where is None:
                    counts["not_addable"] += 1
                    continue
                r = c.post(f"/api/projects/{pid}/detections", headers=rev,
                           json={"class": o.class_id, "wall": where[0], "u": where[1], "v": where[2]})
                if r.status_code != 201:
                    counts["not_addable"] += 1
                    continue
                counts["added"] += 1
            r = c.post(f"/api/projects/{pid}/exemplars", headers=boss)
            r.raise_for_status()
            counts["views_added"] = r.json()["views_added"]
            z = c.get(f"/api/projects/{pid}/exemplars.zip", headers=rev)
            z.raise_for_status()
            with zipfile.ZipFile(io.BytesIO(z.content)) as zf:
                zf.extractall(dest)
    return counts


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run-dir", type=Path, required=True)
    ap.add_argument("--scene", default="one_room", help="a bundled scene, or I / II for the scenarios")
    ap.add_argument("--seeds", type=int, nargs=2, default=(1, 2), metavar=("FLOOR1", "FLOOR2"))
    ap.add_argument("--designs", default="alt")
    ap.add_argument("--library-designs", default="standard")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    run = a.run_dir
    run.mkdir(parents=True, exist_ok=True)
    f1, f2 = run / f"floor1_seed{a.seeds[0]}", run / f"floor2_seed{a.seeds[1]}"
    for f, seed in ((f1, a.seeds[0]), (f2, a.seeds[1])):
        simulate(f, scene=a.scene, seed=seed, designs=a.designs, library_designs=a.library_designs)
    library = f1 / "models"  # the same library on both floors
    detect(f1, library, run / "detect1")
    learnt = run / "exemplars"
    counts = None
    if not (learnt / "models").is_dir():
        counts = review_floor(run / "detect1", f1 / "scan.ply", f1 / "ground_truth.json", library, learnt)
    t_without = detect(f2, library, run / "detect2_library")
    t_with = detect(f2, learnt / "models", run / "detect2_exemplars")
    res = {"scene": a.scene, "seeds": list(a.seeds), "designs": a.designs, "library_designs": a.library_designs,
           "floor1": figures(run / "detect1", f1 / "ground_truth.json"), "review_floor1": counts,
           "floor2_without": {**figures(run / "detect2_library", f2 / "ground_truth.json"),
                              "detect_s": round(t_without, 1)},
           "floor2_with_exemplars": {**figures(run / "detect2_exemplars", f2 / "ground_truth.json"),
                                     "detect_s": round(t_with, 1)}}
    print(json.dumps(res, indent=1))
    if a.json:
        a.json.write_text(json.dumps(res, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
