"""Teaching from the building itself (issue 28): designs and classes learnt from two examples.

**Design change.** A floor simulated in one design family (``--designs``) with the library of
another (``--library-designs``), realistic scanner and clutter:

1. ``sbsc detect`` with the library: TP / FN / FP before teaching;
2. ``sbsc learn`` from ``--examples`` objects per class taken from the ground truth (each given
   only by its class and position, as a reviewer's click; upright, fully visible ones first);
3. ``sbsc detect`` with the learnt library, scored on the objects that were not examples (the
   examples and any detection at them are left out of both counts);
4. with ``--next-floor SEED``: a second floor of the same building (another seed, same designs)
   detected with the learnt library, scored whole.

**New class** (``--leave-out CLASS ...``): each class in turn is removed from the library,
taught from ``--examples`` of its objects (``sbsc learn`` makes it a new class: size from the
relief under each click, medians of the crops), and the floor is detected again: the class's
recall on its other objects and the whole floor's FP.

With ``--together`` the left-out classes are removed from the design-change run's library and
taught there as new classes beside the designs: one detection measures both (with
``--no-design``: the left-out classes are taught together, and nothing else).

**An existing scene** (``--scene-dir DIR``: a folder with a scan, ``scan.ply`` or
``scan.laz``, and ``ground_truth.json``, e.g. an outside scene of an independent generator)
with another library (``--library PATH``, default ``DIR/models``; or ``--library-designs``
rendered for ``--seed``): the same design-change run on that floor, its ceilings and columns
searched when the library's classes mount there (``sbsc detect``'s default). Nothing is tuned
to such a scene: it is a check.

A floor of the same scene, designs and seed with another library reuses that floor's scan
(hard links; the library is rendered from its family and the seed, as the simulator does).

One detection runs at a time (``nice``). A floor with fewer than ``examples + 1`` instances of a
class (``one_room`` has one of each) is scored on ``--next-floor`` only.

    .venv/bin/python benchmarks/bench_teach.py --run-dir /tmp/teach --scene I --designs third \\
        --library-designs standard [--seed 1] [--next-floor 2] [--leave-out radiator exit_light]
        [--together] [--no-design] [--next-floor-learnt-only] [--json out.json]
    .venv/bin/python benchmarks/bench_teach.py --run-dir /tmp/teach \
        --scene-dir ../shared/data/outside-scenes/rotated-clutter-realistic --library sbsc_core/data/models
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sbsc_core.evaluate import evaluate  # noqa: E402
from sbsc_core.io.documents import TruthDocument, read_truth  # noqa: E402

MATCH_M = 0.10  # contract 5's match radius
WELL_SEEN = 0.95  # a reviewer marks an object whose footprint the scan saw this well


def sbsc(*args: str) -> float:
    """Run an ``sbsc`` command of this checkout with ``nice``; returns its seconds."""
    t0 = time.perf_counter()
    subprocess.run(["nice", "-n", "10", sys.executable, "-m", "sbsc_core.cli", "-q", *args], check=True, cwd=ROOT,
                   env={**os.environ, "PYTHONPATH": str(ROOT)})
    return time.perf_counter() - t0


SCAN_FILES = ("scan.ply", "ground_truth.json", "expected.json", "as_designed.ifc")


def reuse_scan(out: Path, *, seed: int, library_designs: str) -> bool:
    """Make ``out`` from a floor of the same scene, designs and seed with another library
    (``sim_<scene>_<designs>_<other>_<seed>`` beside it): its scan and truth hard-linked, the
    library of ``library_designs`` rendered (the simulator writes the library last, from the
    seed and the family only, so the result is the same as simulating again). False when
    there is none."""
    from sbsc_core.simulate.designs import design_builder
    from sbsc_core.simulate.library import write_model_library

    prefix, _, tail = out.name.rsplit("_", 2)  # sim_<scene>_<designs>, <library>, <seed>
    for other in ("standard", "alt", "third"):
        src = out.parent / f"{prefix}_{other}_{tail}"
        if other == library_designs or not (src / "ground_truth.json").is_file():
            continue
        tmp = out.parent / f".{out.name}.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        for name in SCAN_FILES:
            if (src / name).is_file():
                os.link((src / name).resolve(), tmp / name)
        write_model_library(tmp / "models", seed=seed, object_builder=design_builder(library_designs, seed))
        tmp.rename(out)
        return True
    return False


def simulate(out: Path, *, scene: str, seed: int, designs: str, library_designs: str) -> Path:
    if not (out / "ground_truth.json").is_file() and not reuse_scan(out, seed=seed, library_designs=library_designs):
        scene_args = ["--scenario", scene] if scene in ("I", "II") else ["--scene", scene]
        sbsc("simulate", *scene_args, "--realistic", "--clutter", "--designs", designs,
             "--library-designs", library_designs, "--seed", str(seed), "--out", str(out))
    return out


def scan_of(scan_dir: Path) -> Path:
    """The scan of a floor folder: ``scan.ply``, else ``scan.laz``."""
    for name in ("scan.ply", "scan.laz", "scan.las", "scan.e57"):
        if (scan_dir / name).is_file():
            return scan_dir / name
    raise SystemExit(f"{scan_dir}: no scan.ply / scan.laz")


def detect(scan_dir: Path, models: Path, out: Path) -> Path:
    if not (out / "detections.json").is_file():
        sbsc("detect", str(scan_of(scan_dir)), "--models", str(models), "--out", str(out))
    return out


def missed_by(det_dir: Path, truth: TruthDocument) -> set[int]:
    """Indices of the truth objects that a detection did not find as their class."""
    doc = json.loads((det_dir / "detections.json").read_text(encoding="utf-8"))
    found = {m.truth_index for m in evaluate(doc, truth).matches if getattr(m, "truth_index", None) is not None}
    return set(range(len(truth.objects))) - found


def seen_shares(det_dir: Path, truth: TruthDocument) -> dict[int, float]:
    """The share of each truth object's footprint that the scan saw (its surface's depth
    orthoimage in the detect output); 0 when it is on no surface."""
    from sbsc_core.errors import InputError
    from sbsc_core.recognition.learning.crops import footprint, seen_share
    from sbsc_core.recognition.learning.examples import locate, read_detect_output

    surfaces = read_detect_output(det_dir)
    out = {}
    for i, o in enumerate(truth.objects):
        try:
            s, u, v = locate("", np.asarray(o.position, float), surfaces)
        except InputError:
            out[i] = 0.0
            continue
        win = footprint(s.depth().shape, s.frame.height_m, s.pixel_m, u=u, v=v, width_m=o.width_m,
                        height_m=o.height_m)
        out[i] = 0.0 if win is None else seen_share(s.depth(), win)
    return out


def pick_examples(truth: TruthDocument, n: int, classes: list[str] | None = None,
                  missed: set[int] | None = None, seen: dict[int, float] | None = None) -> list:
    """``n`` truth objects per class, as a reviewer would mark them: upright and well seen
    (:data:`WELL_SEEN` of the footprint) first, of those the ones recognition ``missed`` (what
    is missing), then by the share seen and by place. Objects that ``sbsc learn`` cannot use
    (turned from upright, or less than its ``MIN_SEEN`` scanned) are never picked."""
    from sbsc_core.recognition.learning.crops import MIN_SEEN, upright

    missed, seen = missed or set(), seen or {}
    index = {id(o): i for i, o in enumerate(truth.objects)}
    by_class: dict[str, list] = {}
    for o in truth.objects:
        if not upright(float(o.extra.get("rotation_deg") or 0.0)) or seen.get(index[id(o)], 1.0) < MIN_SEEN:
            continue
        if classes is None or o.class_id in classes:
            by_class.setdefault(o.class_id, []).append(o)
    out = []
    for objs in by_class.values():
        objs.sort(key=lambda o: (abs(float(o.extra.get("rotation_deg") or 0.0)) > 5.0,
                                 seen.get(index[id(o)], 1.0) < WELL_SEEN, index[id(o)] not in missed,
                                 -seen.get(index[id(o)], 1.0), o.wall or "", o.u or 0.0))
        out.extend(objs[:n])
    return out


def write_reviewed(examples: list, path: Path) -> Path:
    doc = {"schema": "sbsc.detections/1",
           "detections": [{"class": o.class_id, "position": [float(x) for x in o.position], "source": "reviewer"}
                          for o in examples]}
    path.write_text(json.dumps(doc, indent=1), encoding="utf-8")
    return path


def figures(det_dir: Path, truth: TruthDocument, leave_out: list | None = None, cls: str | None = None) -> dict:
    """TP / FN / FP (and % of the instances) without the objects in ``leave_out`` and any
    detection within the match radius of one; ``cls``: that class's row, and the floor's FP."""
    doc = json.loads((det_dir / "detections.json").read_text(encoding="utf-8"))
    if leave_out:
        at = np.array([o.position for o in leave_out], float)
        doc["detections"] = [d for d in doc["detections"]
                             if np.min(np.linalg.norm(at - np.asarray(d["position"], float), axis=1)) > MATCH_M]
        ids = {id(o) for o in leave_out}
        truth = dataclasses.replace(truth, objects=[o for o in truth.objects if id(o) not in ids])
    table = evaluate(doc, truth)
    t = table.total
    out = {"instances": t.instances, "tp": t.tp, "fn": t.fn, "fp": t.fp,
           "tp_pct": round(100.0 * t.tp / max(1, t.instances), 1), "fp_pct": round(100.0 * t.fp / max(1, t.instances), 1)}
    if cls is not None:
        row = next((r for r in table.rows if r.class_id == cls), None)
        out["class"] = {"instances": row.instances, "tp": row.tp, "fn": row.fn, "fp": row.fp,
                        "recall_pct": round(100.0 * row.tp / max(1, row.instances), 1)} if row else None
    return out


def learn(det: Path, reviewed: Path, models: Path, out: Path, classes: Path | None = None) -> dict:
    if not out.is_dir():
        args = ["learn", str(det), "--reviewed", str(reviewed), "--models", str(models), "--out", str(out)]
        sbsc(*args, *(["--classes", str(classes)] if classes else []))
    return {p.name: sorted(q.name for q in p.iterdir()) for p in out.iterdir() if p.is_dir()}


def design_change(run: Path, a: argparse.Namespace) -> dict:
    tag = f"{a.scene}_{a.designs}_{a.library_designs}"
    floor = simulate(run / f"sim_{tag}_{a.seed}", scene=a.scene, seed=a.seed, designs=a.designs,
                     library_designs=a.library_designs)
    truth = read_truth(floor / "ground_truth.json")
    before = detect(floor, floor / "models", run / f"det_{tag}_{a.seed}")
    examples = pick_examples(truth, a.examples, missed=missed_by(before, truth), seen=seen_shares(before, truth))
    rev = write_reviewed(examples, run / f"reviewed_{tag}_{a.seed}.json")
    models, suffix = floor / "models", ""
    if a.together and a.leave_out:  # the left-out classes are taught as new classes in the same run
        suffix = "_minus_" + "_".join(sorted(a.leave_out))
        models = run / f"lib_{tag}{suffix}"
        if not models.is_dir():
            shutil.copytree(floor / "models", models,
                            ignore=lambda d, names: [n for n in names if n in a.leave_out and Path(d) == floor / "models"])
    lib = run / f"lib_{tag}_{a.seed}{suffix}_learnt"
    learnt = learn(before, rev, models, lib)
    res = {"scene": a.scene, "designs": a.designs, "library_designs": a.library_designs, "seed": a.seed,
           "examples": len(examples), "left_out": sorted(a.leave_out) if a.together else [],
           "new_designs": sorted(c for c, files in learnt.items() if (floor / "models" / c).is_dir()
                                 and len(files) > len(os.listdir(floor / "models" / c))),
           "before_all": figures(before, truth), "before_rest": figures(before, truth, examples)}
    if res["before_rest"]["instances"] == 0:  # every object was an example (one_room): the next floor tells
        return {**res, **next_floor(run, a, tag, lib)}
    after = detect(floor, lib, run / f"det_{tag}_{a.seed}{suffix}_learnt")
    res["after_rest"] = figures(after, truth, examples)
    if a.together:
        res["new_classes"] = {c: figures(after, truth, examples, c)["class"] for c in a.leave_out}
    return {**res, **next_floor(run, a, tag, lib)}


def scene_dir_change(run: Path, a: argparse.Namespace) -> dict:
    """``--scene-dir``: the design-change run on an existing floor with ``--library`` (or the
    library of ``--library-designs`` rendered for ``--seed``)."""
    floor = a.scene_dir.resolve()
    if a.library is not None:
        models = a.library.resolve()
        label = "bundled" if models == (ROOT / "sbsc_core" / "data" / "models").resolve() else models.parent.name
    elif a.library_designs_given:
        from sbsc_core.simulate.designs import design_builder
        from sbsc_core.simulate.library import write_model_library

        label = f"{a.library_designs}{a.seed}"
        models = run / f"lib_{label}"
        if not models.is_dir():
            tmp = run / f".lib_{label}.tmp"
            shutil.rmtree(tmp, ignore_errors=True)
            write_model_library(tmp, seed=a.seed, object_builder=design_builder(a.library_designs, a.seed))
            tmp.rename(models)
    else:
        models, label = floor / "models", "own"
    tag = f"{floor.name}_{label}"
    truth = read_truth(floor / "ground_truth.json")
    before = detect(floor, models, run / f"det_{tag}")
    examples = pick_examples(truth, a.examples, missed=missed_by(before, truth), seen=seen_shares(before, truth))
    rev = write_reviewed(examples, run / f"reviewed_{tag}.json")
    lib = run / f"lib_{tag}_learnt"
    learnt = learn(before, rev, models, lib)
    res = {"scene_dir": str(floor), "library": str(models), "examples": len(examples),
           "new_designs": sorted(c for c, files in learnt.items() if (models / c).is_dir()
                                 and len(files) > len(os.listdir(models / c))),
           "new_classes": sorted(c for c in learnt if not (models / c).is_dir()),
           "before_all": figures(before, truth), "before_rest": figures(before, truth, examples)}
    after = detect(floor, lib, run / f"det_{tag}_learnt")
    res["after_rest"] = figures(after, truth, examples)
    return res


def next_floor(run: Path, a: argparse.Namespace, tag: str, lib: Path) -> dict:
    """``--next-floor``: that floor with its library and with the learnt one ({} without it)."""
    if a.next_floor is None:
        return {}
    nxt = simulate(run / f"sim_{tag}_{a.next_floor}", scene=a.scene, seed=a.next_floor, designs=a.designs,
                   library_designs=a.library_designs)
    ntruth = read_truth(nxt / "ground_truth.json")
    out = {"seed": a.next_floor}
    if not a.next_floor_learnt_only:
        out["before"] = figures(detect(nxt, nxt / "models", run / f"det_{tag}_{a.next_floor}"), ntruth)
    out["after"] = figures(detect(nxt, lib, run / f"det_{tag}_{a.next_floor}_{lib.name}"), ntruth)
    return {"next_floor": out}


def new_class(run: Path, a: argparse.Namespace, classes: list[str]) -> dict:
    """``classes`` left out of the library together (one class: in turn), each taught from
    ``--examples`` of its objects; one detection scores them all."""
    tag = f"{a.scene}_{a.designs}_{a.library_designs}"
    floor = simulate(run / f"sim_{tag}_{a.seed}", scene=a.scene, seed=a.seed, designs=a.designs,
                     library_designs=a.library_designs)
    truth = read_truth(floor / "ground_truth.json")
    before = detect(floor, floor / "models", run / f"det_{tag}_{a.seed}")  # the orthoimages do not depend on it
    name = "_".join(sorted(classes))
    minus = run / f"lib_{tag}_minus_{name}"
    if not minus.is_dir():
        shutil.copytree(floor / "models", minus,
                        ignore=lambda d, names: [n for n in names if n in classes] if Path(d) == floor / "models" else [])
    examples = pick_examples(truth, a.examples, classes, seen=seen_shares(before, truth))
    rev = write_reviewed(examples, run / f"reviewed_{tag}_{name}.json")
    lib = run / f"lib_{tag}_{name}_learnt"
    learn(before, rev, minus, lib)
    after = detect(floor, lib, run / f"det_{tag}_{a.seed}_{name}_learnt")
    res = {"classes": sorted(classes), "examples": len(examples), "floor_rest": figures(after, truth, examples)}
    for cls in classes:
        meta = json.loads((lib / cls / "model.json").read_text(encoding="utf-8"))
        ex = [o for o in examples if o.class_id == cls]
        res[cls] = {"examples": len(ex), "learnt_size_m": [meta["width_m"], meta["height_m"]],
                    "true_size_m": [ex[0].width_m, ex[0].height_m], "rest": figures(after, truth, examples, cls)["class"]}
    if len(classes) == 1:
        cls = classes[0]
        res = {"class": cls, **res, "rest": figures(after, truth, examples, cls)}
    if a.next_floor is not None:
        nxt = simulate(run / f"sim_{tag}_{a.next_floor}", scene=a.scene, seed=a.next_floor, designs=a.designs,
                       library_designs=a.library_designs)
        res["next_floor"] = {c: figures(detect(nxt, lib, run / f"det_{tag}_{a.next_floor}_{name}_learnt"),
                                        read_truth(nxt / "ground_truth.json"), None, c) for c in classes}
    return res


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--run-dir", type=Path, required=True)
    p.add_argument("--scene", default="one_room", help="one_room, another bundled scene, or I / II")
    p.add_argument("--designs", default="third", choices=["standard", "alt", "third"])
    p.add_argument("--library-designs", default="standard", choices=["standard", "alt", "third"])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--next-floor", type=int, default=None, metavar="SEED")
    p.add_argument("--examples", type=int, default=2)
    p.add_argument("--leave-out", nargs="*", default=[], metavar="CLASS")
    p.add_argument("--no-design", action="store_true", help="only the new-class part")
    p.add_argument("--together", action="store_true",
                   help="leave the --leave-out classes out of the design-change run's library and teach them "
                        "there as new classes (one detection instead of one per class)")
    p.add_argument("--next-floor-learnt-only", action="store_true",
                   help="score the next floor with the learnt library only (not with its own library too)")
    p.add_argument("--scene-dir", type=Path, default=None,
                   help="an existing floor (scan.ply or scan.laz, ground_truth.json) instead of a simulated one")
    p.add_argument("--library", type=Path, default=None,
                   help="with --scene-dir: the library to detect with and teach (default: the scene's models/, "
                        "or --library-designs rendered for --seed when given)")
    p.add_argument("--json", type=Path)
    a = p.parse_args()
    a.library_designs_given = any(x == "--library-designs" or x.startswith("--library-designs=") for x in sys.argv[1:])
    a.run_dir.mkdir(parents=True, exist_ok=True)
    out: dict = {}
    if a.scene_dir is not None:
        out["design_change"] = scene_dir_change(a.run_dir, a)
        print(json.dumps(out["design_change"]), flush=True)
        if a.json:
            a.json.write_text(json.dumps(out, indent=1), encoding="utf-8")
        return 0
    if not a.no_design:
        out["design_change"] = design_change(a.run_dir, a)
        print(json.dumps(out["design_change"]), flush=True)
    out["new_class"] = []
    groups = [a.leave_out] if a.together and a.no_design and a.leave_out else [] if a.together else [[c] for c in a.leave_out]
    for classes in groups:
        out["new_class"].append(new_class(a.run_dir, a, classes))
        print(json.dumps(out["new_class"][-1]), flush=True)
    if a.json:
        a.json.write_text(json.dumps(out, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
