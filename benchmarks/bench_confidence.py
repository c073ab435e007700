"""Fit the detection confidence on simulated scenes and report its calibration on others.

Usage (heavy: run under the shared lock)::

    flock /tmp/sbsc-heavy.lock python benchmarks/bench_confidence.py [--work DIR] [--write]
        [--variants acceptance clutter ...] [--pairs standard/standard alt/alt ...]
        [--turned 0 0.34] [--fit-seeds 11 12] [--eval-seeds 21 22] [--eval-pairs third/third]

Scenes: ``one_room.yaml`` for every realism VARIANT (as in ``bench_realism.py``: ``baseline``,
``clutter``, ``realistic``, ``acceptance``, ...), every pairing of scene and library design
sets (``standard/standard``, ``alt/alt`` and, by default, the crosses ``standard/alt`` and
``alt/standard``: objects whose design differs from their model, as every real building's
do, which give real mistakes and right hits with a misfit to learn from), upright and with a share of the rotatable objects turned, at several seeds. ``--fit-families`` / ``--eval-families`` add random design families (issue 27: scene
and library of one family drawn per seed, ``sbsc simulate --designs random``), so that the
calibration is fitted on many designs and reported on families left out of the fit;
``--fit-crosses`` / ``--eval-crosses N/M`` add random crosses (a scene of family N with the
library of its sibling M, ``sbsc simulate --library-designs sibling``: M's designs at N's
sizes, objects whose design differs from their model, as between standard and alt). The FIT
seeds and the EVALUATION seeds are disjoint; ``--eval-pairs`` may name other design sets
for the evaluation only (the third family is never fitted on). Each scene is detected once
(its candidates are kept in ``--work``) and its candidates go through consensus both with
and without the expected counts. A hit is right when a ground-truth object of its class
lies within ``--radius`` of it (each object counts once). The logistic model is fitted on
the FIT scenes only; the reliability table and the expected calibration error (ECE) are
printed for the EVALUATION scenes. ``--write`` stores the fitted model as
``sbsc_core/recognition/calibration/confidence.json`` (``--out PATH`` writes it elsewhere, to try it first).

The shipped calibration adds Scenario I scenes with the realistic scanner and clutter, where
long walls are seen from far and obliquely (flat signs lost in depth, mixed-pixel trails),
which one room does not show. It was made so (each scene is detected once, its candidates
kept in it as ``candidates.pkl`` with the commit that made them; the calibration records
those commits as ``candidates_code``: refit it when recognition changes what it measures)::

    sbsc simulate --scenario I --realistic --clutter --designs alt --seed 2204 --out S/alt2204
    (likewise standard 2205, standard 2207, alt 2208 to fit; alt 2201, standard 2202, alt 2206
    to evaluate)
    python benchmarks/bench_confidence.py --variants acceptance clutter baseline --work W \
        --fit-scenes S/alt2204 S/std2205 S/std2207 S/alt2208 \
        --eval-scenes S/alt2201 S/std2202 S/alt2206 --write

A fit on random families alone (issue 27; docs/benchmarks.md, "A calibration fitted on random
families with crosses", not shipped) was made with ``--objective ranking``, from one-room
floors and Scenario I floors (``S``: ``simulate_scene(scenario_I.yaml, seed=N, design=False,
realistic=True, clutter=True)`` with ``object_builder=random_family(N)`` and, for the crosses,
``library_builder=sibling_family(random_family(N), M)``)::

    python benchmarks/bench_confidence.py --work W --variants acceptance --turned 0 0.34 \
        --fit-seeds --eval-seeds --fit-families 3001 3002 3003 3004 3005 3006 3007 3008 \
        --fit-crosses 3001/3501 3002/3502 3003/3503 3004/3504 3005/3505 3006/3506 3007/3507 3008/3508 \
        --eval-families 3101 3102 --eval-crosses 3101/3601 3102/3602 \
        --fit-scenes S/f5001 S/f5002 S/f5003 S/f5004 S/x5001_5501 S/x5002_5502 S/x5003_5503 S/x5004_5504 \
        --eval-scenes S/f5101 ... S/f5120 --table --objective ranking

The shipped calibration (2026-11-29, fitted on random families only) is the likelihood fit with
the isotonic link on the same one-room floors and eleven Scenario I floors::

    python benchmarks/bench_confidence.py --work W --variants acceptance --turned 0 0.34 \
        --fit-seeds --eval-seeds --fit-families 3001 ... 3008 --fit-crosses 3001/3501 ... 3008/3508 \
        --eval-families 3101 3102 --eval-crosses 3101/3601 3102/3602 \
        --fit-scenes S/f5001 ... S/f5004 S/f5201 S/f5202 S/f5203 S/f5204 S/f5206 S/f5208 S/f5210 \
            S/x5001_5501 ... S/x5004_5504 \
        --objective likelihood --link isotonic --features in_depth in_colour rho_depth colour_goodness \
            alpha class_margin lookalike_margin relief_misfit unmatched_relief relief_margin \
            colour_only_print face_shortfall face_excess relief_surplus

and calibrations are compared on scenes left out of every fit, from their kept candidates::

    python benchmarks/bench_confidence.py --compare before=OLD.json after=NEW.json --eval-scenes S/f5205 ...
"""

from __future__ import annotations

import argparse
import json
import pickle
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sbsc_core.io.models import load_model_library  # noqa: E402
from sbsc_core.io.scans import read_scans  # noqa: E402
from sbsc_core.paths import sample_projects_dir  # noqa: E402
from sbsc_core.pipeline.detect import detect  # noqa: E402
from sbsc_core.recognition.confidence import (  # noqa: E402
    CALIBRATION_PATH,
    FEATURES,
    MONOTONE,
    fit_logistic,
    fit_ranking_logistic,
    hit_features,
    isotonic_relink,
    model_reliefs,
    reliability,
    screened_consensus,
)
from sbsc_core.recognition.consensus import consensus_all  # noqa: E402
from sbsc_core.recognition.mounting import within_wall_height  # noqa: E402
from sbsc_core.recognition.placement import place_hits  # noqa: E402
from sbsc_core.recognition.templates import make_templates  # noqa: E402
from sbsc_core.settings import DetectionSettings  # noqa: E402
from sbsc_core.simulate.designs import RANDOM, SIBLING, design_builder, library_builder  # noqa: E402
from sbsc_core.simulate.scenarios import simulate_scene  # noqa: E402
from sbsc_core.types import Orthoimage  # noqa: E402

FIT_SEEDS = (11, 12, 13)
EVAL_SEEDS = (21, 22)
PAIRS = ("standard/standard", "alt/alt", "standard/alt", "alt/standard")
VARIANTS: dict[str, dict[str, bool]] = {
    "baseline": {},
    "clutter": {"clutter": True},
    "furniture": {"furniture": True},
    "realistic": {"realistic": True},
    "acceptance": {"realistic": True, "clutter": True},
}
TURNED = (0.0,)


def scene_file(work: Path, turned: float, seed: int) -> Path:
    data = yaml.safe_load((sample_projects_dir() / "one_room.yaml").read_text())
    if turned:
        data["object_rotation"] = {"fraction": turned, "seed": seed}
    path = work / f"one_room_t{turned:g}_s{seed}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def code_version() -> str:
    """The commit of this working tree (``+changes`` when sbsc_core differs from it), or ``unknown``."""
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "sbsc_core"], cwd=ROOT, capture_output=True,
                               text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return rev + ("+changes" if dirty else "")


def candidates_of(scan: Path, settings: DetectionSettings) -> dict:
    """Depth and colour candidates, classes and wall frames of a detected scene (cached in the scene)."""
    cache = scan / "candidates.pkl"
    if cache.is_file():
        return pickle.loads(cache.read_bytes())
    res = detect(read_scans([scan / "scan.ply"]), load_model_library(scan / "models"), None,
                 settings=settings)
    data = {"depth": [c for w in res.walls.values() for c in w.depth_candidates],
            "colour": [c for w in res.walls.values() for c in w.colour_candidates],
            "classes": res.classes,
            "frames": {k: (w.ortho.frame, w.ortho.pixel_m) for k, w in res.walls.items()},
            "code": code_version()}
    cache.write_bytes(pickle.dumps(data))
    return data


def rows_of(scan: Path, settings: DetectionSettings, radius: float,
            codes: set[str] | None = None) -> list[tuple[np.ndarray, int, tuple]]:
    """(features, right, group) of every hit, with and without the expected counts (group:
    scene, counts or not, class: the hits that compete for one class's count); the commit
    that made the scene's candidates is added to ``codes``."""
    data = candidates_of(scan, settings)
    if codes is not None:
        codes.add(data.get("code", "unknown"))
    truth = json.loads((scan / "ground_truth.json").read_text())["objects"]
    expected = json.loads((scan / "expected.json").read_text())["counts"]
    depth, colour = data["depth"], data["colour"]
    data["reliefs"] = model_reliefs(make_templates(load_model_library(scan / "models"), settings.orthoimage.pixel_m,
                                                   data["classes"]))
    orthos = parked(data["frames"])
    out = []
    for counted, exp in enumerate((None, expected)):
        hits = [h for v in consensus_all(depth, colour, exp, settings.consensus, data["classes"]).values() for h in v]
        feats = [hit_features(h, depth, colour, data["reliefs"]) for h in hits]
        pos = []
        for h in hits:
            o = orthos[h.wall_id]
            u, v = o.pixel_to_uv(h.centre[0], h.centre[1])
            pos.append(o.frame.to_world(u, v, 0.0))
        order = np.argsort([-f[2] - f[3] for f in feats])  # the best evidence takes an object first
        taken: set[int] = set()
        right = [0] * len(hits)
        for k in order:
            best = None
            for j, t in enumerate(truth):
                if j in taken or t["class"] != hits[k].class_id:
                    continue
                dist = float(np.linalg.norm(np.subtract(t["position"], pos[k])))
                if dist <= radius and (best is None or dist < best[0]):
                    best = (dist, j)
            if best is not None:
                taken.add(best[1])
                right[k] = 1
        out.extend(zip(feats, right, [(str(scan), counted, h.class_id) for h in hits], strict=True))
    return out


def parked(frames: dict) -> dict[str, Orthoimage]:
    """Orthoimages without images (frame and pixel size only) of every surface of ``frames``."""
    return {k: Orthoimage(wall_id=k, frame=f, pixel_m=px, colour=np.zeros((0, 0, 3), np.uint8),
                          depth=np.zeros((0, 0), np.float32), mask=np.zeros((0, 0), bool))
            for k, (f, px) in frames.items()}


def table_of(scan: Path, settings: DetectionSettings, calibration: Path, *,
             counts: bool = True) -> tuple[int, int, int, np.ndarray, np.ndarray]:
    """Table 1 of a scene detected with its expected counts (or without, ``counts=False``) and
    ``calibration``, from its kept candidates: the steps of ``sbsc detect`` after recognition
    (mount heights, screened consensus, counts filled by confidence, placement), scored like
    ``sbsc evaluate``.

    Returns instances, TP, FP, and each detection's confidence and whether it is right.
    """
    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_truth
    from sbsc_core.io.models import read_library_metadata

    data = candidates_of(scan, settings)
    orthos = parked(data["frames"])
    margin = settings.consensus.mount_margin_m
    depth = within_wall_height(data["depth"], orthos, margin_m=margin)
    colour = within_wall_height(data["colour"], orthos, margin_m=margin)
    templates = make_templates(load_model_library(scan / "models"), settings.orthoimage.pixel_m, data["classes"])
    conf = DetectionSettings().confidence
    conf.calibration = str(calibration)
    expected = json.loads((scan / "expected.json").read_text())["counts"] if counts else None
    hits = screened_consensus(depth, colour, expected, data["classes"], consensus_settings=settings.consensus,
                              settings=conf, reliefs=model_reliefs(templates), frames=data["frames"])
    doc = {"detections": [d.to_dict() for d in place_hits(hits, orthos, templates)]}
    table = evaluate(doc, read_truth(scan / "ground_truth.json"), library=read_library_metadata(scan / "models"))
    used = {m.detection_id for m in table.matches}
    p = np.array([d.get("confidence") or 0.0 for d in doc["detections"]], float)
    right = np.array([d["id"] in used for d in doc["detections"]], float)
    return table.total.instances, table.total.tp, table.total.fp, p, right


def print_tables(scans: list[Path], settings: DetectionSettings, calibrations: dict[str, Path], *,
                 counts: bool = True) -> None:
    """Table 1 (with counts, or without) of every scene under each calibration, their mean and
    worst, and the ECE of every detection."""
    pooled: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {k: [] for k in calibrations}
    tps: dict[str, list[float]] = {k: [] for k in calibrations}
    fps: dict[str, list[float]] = {k: [] for k in calibrations}
    print(f"\nTable 1 {'with' if counts else 'without'} counts, TP % / FP %: "
          + ", ".join(f"{k} = {v}" for k, v in calibrations.items()))
    for scan in scans:
        cells = []
        for name, path in calibrations.items():
            n, tp, fp, p, right = table_of(scan, settings, path, counts=counts)
            tps[name].append(100.0 * tp / n)
            fps[name].append(100.0 * fp / n)
            pooled[name].append((p, right))
            cells.append(f"{name} {tps[name][-1]:5.1f} / {fps[name][-1]:4.1f}")
        print(f"  {scan.name:28s} " + "   ".join(cells), flush=True)
    for name in calibrations:
        p = np.concatenate([a for a, _ in pooled[name]])
        y = np.concatenate([b for _, b in pooled[name]])
        _, ece = reliability(p, y)
        print(f"{name}: TP mean {np.mean(tps[name]):.1f} %, worst {np.min(tps[name]):.1f} %; FP mean "
              f"{np.mean(fps[name]):.1f} %, worst {np.max(fps[name]):.1f} %; ECE {ece:.4f} ({len(y)} detections)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/sbsc-bench-confidence"))
    ap.add_argument("--radius", type=float, default=0.05, help="a hit within this of its object is right (m)")
    ap.add_argument("--step", type=float, default=0.15, help="scanner angular step (degrees)")
    ap.add_argument("--variants", nargs="+", default=["acceptance", "clutter"], choices=list(VARIANTS))
    ap.add_argument("--pairs", nargs="+", default=list(PAIRS), help="SCENE/LIBRARY design sets fitted on")
    ap.add_argument("--eval-pairs", nargs="+", default=None, help="design sets evaluated on (default: --pairs)")
    ap.add_argument("--turned", nargs="+", type=float, default=list(TURNED), help="shares of objects turned")
    ap.add_argument("--fit-seeds", nargs="*", type=int, default=list(FIT_SEEDS),
                    help="seeds of the --pairs scenes fitted on (none: only the families and scenes given)")
    ap.add_argument("--eval-seeds", nargs="*", type=int, default=list(EVAL_SEEDS))
    ap.add_argument("--fit-families", nargs="+", type=int, default=[], metavar="SEED",
                    help="random design families fitted on (scene and library of one family, "
                         "``sbsc simulate --designs random``), beside --pairs x --fit-seeds")
    ap.add_argument("--eval-families", nargs="+", type=int, default=[], metavar="SEED",
                    help="random design families evaluated on (never ones fitted on)")
    ap.add_argument("--fit-crosses", nargs="+", default=[], metavar="N/M",
                    help="random crosses fitted on: a scene of family N with the library of its sibling M "
                         "(family M's designs at N's sizes, ``--library-designs sibling``): objects whose design "
                         "differs from their model, as between standard and alt")
    ap.add_argument("--eval-crosses", nargs="+", default=[], metavar="N/M",
                    help="random crosses evaluated on (no family of them fitted on)")
    ap.add_argument("--fit-scenes", nargs="+", type=Path, default=[],
                    help="simulated scenes (any layout, e.g. bench_realism.py --full runs) also fitted on")
    ap.add_argument("--eval-scenes", nargs="+", type=Path, default=[], help="simulated scenes also evaluated on")
    ap.add_argument("--table", action="store_true",
                    help="also Table 1 with counts of every evaluation scene, with the shipped calibration "
                         "and the fitted one (the steps of sbsc detect after recognition, from the kept candidates)")
    ap.add_argument("--objective", choices=["likelihood", "ranking"], default="likelihood",
                    help="likelihood: one logistic fit of every hit (default, the shipped calibration's); ranking: "
                         "weights that order each class's hits in a scene right before wrong, then Platt-scaled "
                         "(fit_ranking_logistic)")
    ap.add_argument("--link", choices=["platt", "isotonic"], default="platt",
                    help="how the score becomes a probability (Platt scaling or, for --objective likelihood, the "
                         "logistic fit itself; or "
                         "the isotonic_link of confidence.py)")
    ap.add_argument("--features", nargs="+", choices=list(FEATURES), default=None, metavar="NAME",
                    help="the features fitted on (default: all of confidence.FEATURES)")
    ap.add_argument("--compare", nargs="+", default=None, metavar="NAME=CALIBRATION",
                    help="fit nothing: Table 1 with and without counts, and the ECE, of these calibration files "
                         "on --eval-scenes (from their kept candidates)")
    ap.add_argument("--write", action="store_true", help="store the fitted model in the package")
    ap.add_argument("--out", type=Path, default=None, help="store the fitted model there (to try it first)")
    args = ap.parse_args()
    if args.compare is not None:
        if not args.eval_scenes or any("=" not in c for c in args.compare):
            ap.error("--compare NAME=CALIBRATION ... needs --eval-scenes")
        settings = DetectionSettings()
        settings.confidence.enabled = False
        calibrations = {c.split("=", 1)[0]: Path(c.split("=", 1)[1]) for c in args.compare}
        for counts in (True, False):
            print_tables(args.eval_scenes, settings, calibrations, counts=counts)
        return 0
    if set(args.fit_seeds) & set(args.eval_seeds):
        ap.error("--fit-seeds and --eval-seeds must be disjoint")
    crosses = {part: [tuple(int(x) for x in c.split("/")) for c in cs]
               for part, cs in (("fit", args.fit_crosses), ("eval", args.eval_crosses))}
    fitted_families = set(args.fit_families) | {f for c in crosses["fit"] for f in c}
    if fitted_families & (set(args.eval_families) | {f for c in crosses["eval"] for f in c}):
        ap.error("the families fitted on (--fit-families, --fit-crosses) and evaluated on must be disjoint")
    if any(p.split("/")[0] == "third" or p.endswith("/third") for p in args.pairs):
        ap.error("the third design family is for testing only: never fit on it")
    args.work.mkdir(parents=True, exist_ok=True)
    settings = DetectionSettings()
    settings.confidence.enabled = False
    data: dict[str, list[tuple[np.ndarray, int]]] = {"fit": [], "eval": []}
    codes: set[str] = set()
    t0 = time.perf_counter()
    # (part, scene seed, scene design set, library design set, library family seed or None)
    plan = [(part, seed, *pair.split("/"), None) for part, seeds, pairs in
            (("fit", args.fit_seeds, args.pairs), ("eval", args.eval_seeds, args.eval_pairs or args.pairs))
            for seed in seeds for pair in pairs]
    plan += [(part, family, RANDOM, RANDOM, None) for part, families in
             (("fit", args.fit_families), ("eval", args.eval_families)) for family in families]
    plan += [(part, n, RANDOM, SIBLING, m) for part in ("fit", "eval") for n, m in crosses[part]]
    for part, seed, scene_d, lib_d, lib_seed in plan:
        for variant in args.variants:
            for turned in args.turned:
                scan = args.work / f"{variant}-{scene_d}-{lib_d}{lib_seed or ''}-t{turned:g}-s{seed}"
                if not (scan / "ground_truth.json").is_file():
                    builder = design_builder(scene_d, seed)
                    library = library_builder(lib_d, builder, seed, lib_seed)
                    simulate_scene(scene_file(args.work, turned, seed), scan, seed=seed,
                                   angular_step_deg=args.step, design=False,
                                   object_builder=builder, library_builder=library, **VARIANTS[variant])
                rows = rows_of(scan, settings, args.radius, codes)
                data[part].extend(rows)
                n_right = sum(r for _, r, _ in rows)
                print(f"{part:4s} {scan.name:44s} hits {len(rows):3d} right {n_right:3d} "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
    for part, scans in (("fit", args.fit_scenes), ("eval", args.eval_scenes)):
        for scan in scans:
            rows = rows_of(scan, settings, args.radius, codes)
            data[part].extend(rows)
            print(f"{part:4s} {str(scan):44s} hits {len(rows):3d} right {sum(r for _, r, _ in rows):3d} "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
    xf = np.stack([f for f, _, _ in data["fit"]])
    yf = np.array([r for _, r, _ in data["fit"]], float)
    xe = np.stack([f for f, _, _ in data["eval"]])
    ye = np.array([r for _, r, _ in data["eval"]], float)
    names = tuple(args.features or FEATURES)
    cols = [FEATURES.index(f) for f in names]
    signs = [MONOTONE.get(f, 0) for f in names]
    cal = (fit_ranking_logistic(xf[:, cols], yf, [g for _, _, g in data["fit"]], signs=signs, link=args.link)
           if args.objective == "ranking"
           else fit_logistic(xf[:, cols], yf, signs=signs))
    if args.objective == "likelihood" and args.link == "isotonic":
        cal = isotonic_relink(cal, xf[:, cols], yf)
    cal = replace(cal, features=names)  # predict() then takes every feature's column and picks these
    table, ece = reliability(cal.predict(xe), ye)
    _, ece_fit = reliability(cal.predict(xf), yf)
    fixed = f"seeds {args.fit_seeds} of {args.pairs}, " if args.fit_seeds else ""
    fixed_e = f"seeds {args.eval_seeds} of {args.eval_pairs or args.pairs}, " if args.eval_seeds else ""
    print(f"\nfitted on {len(yf)} hits ({int(yf.sum())} right) of {fixed}random families {args.fit_families}, "
          f"crosses {args.fit_crosses}; evaluated on {len(ye)} hits ({int(ye.sum())} right) of {fixed_e}random "
          f"families {args.eval_families}, crosses {args.eval_crosses}; "
          f"variants {args.variants}")
    print(f"candidates made by {', '.join(sorted(codes))}")
    print("coefficients: " + ", ".join(f"{n} {c:+.3f}" for n, c in zip(names, cal.coef, strict=True))
          + f", intercept {cal.intercept:+.3f}")
    print("\nreliability on the evaluation scenes")
    print(f"{'confidence':>12s} {'hits':>6s} {'mean conf':>10s} {'accuracy':>9s}")
    for lo, hi, n, conf, acc in table:
        print(f"{lo:5.1f}-{hi:4.1f}   {n:6d} {conf:10.3f} {acc:9.3f}")
    print(f"\nECE (evaluation scenes, 10 bins): {ece:.4f}   (fit scenes: {ece_fit:.4f})")
    if args.table:
        fitted = args.work / "fitted_confidence.json"
        fitted.write_text(json.dumps(cal.to_dict(), indent=1) + "\n", encoding="utf-8")
        print_tables(list(args.eval_scenes), settings, {"shipped": CALIBRATION_PATH, "fitted": fitted})
    if args.write or args.out:
        cal.info = {"fit_seeds": list(args.fit_seeds), "eval_seeds": list(args.eval_seeds), "scenes": "one_room.yaml",
                    "fit_families": list(args.fit_families), "eval_families": list(args.eval_families),
                    "fit_crosses": list(args.fit_crosses), "eval_crosses": list(args.eval_crosses),
                    "objective": args.objective, "link": args.link if args.objective == "ranking" or args.link == "isotonic" else "logistic",
                    "variants": list(args.variants), "pairs": list(args.pairs) if args.fit_seeds else [],
                    "eval_pairs": list(args.eval_pairs or args.pairs) if args.eval_seeds else [], "turned": list(args.turned),
                    "radius_m": args.radius,
                    "fit_scenes": [p.name for p in args.fit_scenes], "eval_scenes": [p.name for p in args.eval_scenes],
                    "fit_hits": int(len(yf)), "eval_hits": int(len(ye)), "eval_ece": round(ece, 4),
                    "candidates_code": sorted(codes)}
        for path in [CALIBRATION_PATH] * args.write + [args.out] * (args.out is not None):
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(cal.to_dict(), indent=1) + "\n", encoding="utf-8")
            print(f"written {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
