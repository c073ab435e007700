"""IFC export, Scan-vs-BIM and BCF with objects on ceilings and columns (issue 11, point 5).

    .venv/bin/python benchmarks/bench_bim_surfaces.py [--scene one_room benchmarks/scenes/two_halls.yaml]
        [--full] [--seeds 0 1] [--run-dir /work/scenes/bim/bench] [--redo] [--json FILE]

For each scene and seed: ``sbsc simulate --ceiling-objects --columns`` (which writes the
as-designed IFC with deliberate differences: one removed, moved and added object per kind
of surface, more on walls), ``sbsc detect --expected --ceilings --columns``, then

- the as-is IFC of the detections in IFC4, IFC2X3 and IFC4X3: ``ifcopenshell.validate``
  errors with express rules, and the largest distance between a detection's ``position``
  and its IfcElement's placement read back from the file, per kind of surface;
- Scan-vs-BIM (``sbsc_core.bim.compare``) of the as-designed IFC against the detections:
  the verdicts per kind of surface, and how many of the deliberate differences of each
  kind it reports (a removed object as unexpected, a moved one as displaced, an added one
  as missing, within 1 mm of where it is);
- the BCF file of the findings: topics per kind, and XSD errors when the BCF 2.1 schemas
  are found (``../shared/data/bcf-xsd-2.1`` or ``$SBSC_SHARED_DATA``).

``--full`` adds Scenario I (run it under ``/work/notes/heavy``: ~4 GiB and minutes per run).
A scene ``building:N`` is the simulated building of N Scenario-style storeys (``sbsc simulate
--scenario building``, one file per station; heavy): the simulator writes no as-designed IFC
for it, so the benchmark writes one from its truth (``write_as_designed_ifc``, one
IfcBuildingStorey per storey) with the same kinds of differences.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCHEMAS = ("IFC4", "IFC2X3", "IFC4X3")
STATUS_OF = {"removed": "unexpected", "moved": "displaced", "added": "missing"}


def _xsd_folder() -> Path | None:
    env = os.environ.get("SBSC_SHARED_DATA")
    cands = ([Path(env) / "bcf-xsd-2.1"] if env else []) + [p / "shared" / "data" / "bcf-xsd-2.1" for p in ROOT.parents]
    return next((c for c in cands if c.is_dir()), None)


def bcf_xsd_errors(path: Path) -> int | None:
    folder = _xsd_folder()
    if folder is None:
        return None
    from lxml import etree

    schemas = {"markup.bcf": "markup.xsd", ".bcfv": "visinfo.xsd", "project.bcfp": "project.xsd",
               "bcf.version": "version.xsd"}
    xsd = {n: etree.XMLSchema(etree.parse(str(folder / n))) for n in set(schemas.values())}
    errors = 0
    with zipfile.ZipFile(path) as z:
        for name in z.namelist():
            schema = next((s for k, s in schemas.items() if name.endswith(k)), None)
            if schema and not xsd[schema].validate(etree.fromstring(z.read(name))):
                errors += len(xsd[schema].error_log)
    return errors


def export_figures(doc: dict, out: Path) -> dict:
    """Validate errors and the largest read-back error per kind, for each schema."""
    import ifcopenshell.util.placement
    import ifcopenshell.validate

    from sbsc_core.bim.design import open_ifc
    from sbsc_core.bim.export import export_ifc

    kinds = {d["id"]: d.get("surface", "wall") for d in doc["detections"]}
    res = {}
    for schema in SCHEMAS:
        path = out / f"asis_{schema}.ifc"
        t = time.perf_counter()
        export_ifc(doc, schema=schema).write(str(path))
        seconds = time.perf_counter() - t
        logger = ifcopenshell.validate.json_logger()
        ifcopenshell.validate.validate(str(path), logger, express_rules=True)
        f = open_ifc(path)
        placed = {el.Tag: el for el in f.by_type("IfcElement") if el.Tag in kinds}
        err: dict[str, float] = {}
        for d in doc["detections"]:
            el = placed.get(d["id"])
            e = np.inf if el is None else float(np.linalg.norm(
                ifcopenshell.util.placement.get_local_placement(el.ObjectPlacement)[:3, 3] - d["position"]))
            err[kinds[d["id"]]] = max(err.get(kinds[d["id"]], 0.0), e)
        res[schema] = {"validate_errors": len(logger.statements), "objects": len(placed),
                       "coverings": len(f.by_type("IfcCovering")), "columns": len(f.by_type("IfcColumn")),
                       "ifc_storeys": len(f.by_type("IfcBuildingStorey")),
                       "max_error_mm": {k: round(v * 1000, 4) for k, v in err.items()},
                       "export_s": round(seconds, 2)}
    return res


def compare_figures(sim: Path, det: Path, out: Path) -> dict:
    from sbsc_core.bim.bcf import write_bcf
    from sbsc_core.bim.compare import compare
    from sbsc_core.bim.design import read_as_designed

    truth = json.loads((sim / "ground_truth.json").read_text())
    doc = json.loads((det / "detections.json").read_text())
    cmp = compare(read_as_designed(sim / "as_designed.ifc"), doc, 0.10, detections_path=str(det / "detections.json"))
    diffs = truth.get("design_differences")
    if diffs is None:  # a building: the benchmark wrote the design and its differences
        diffs = json.loads((sim.parent / "design_differences.json").read_text())
    reported: dict[str, dict[str, str]] = {}
    for kind in ("wall", "ceiling", "column"):
        mine = [d for d in diffs if d.get("surface", "wall") == kind]
        hits = 0
        for d in mine:
            want = STATUS_OF[d["kind"]]
            for it in cmp.items:
                if it.status != want or it.class_id != d["class"] or it.surface != kind:
                    continue
                ok = True
                if d["designed_position"] is not None:
                    ok &= it.designed is not None and np.linalg.norm(it.designed_position - d["designed_position"]) <= 1e-3
                if d["built_position"] is not None:  # the detection is near where it is built
                    ok &= it.detection is not None and np.linalg.norm(it.detected_position - d["built_position"]) <= 0.1
                if ok:
                    hits += 1
                    break
        reported[kind] = f"{hits}/{len(mine)}"
    bcf = out / "findings.bcf"
    write_bcf(cmp, bcf, image_dir=det / "orthoimages")
    per_kind: dict[str, int] = {}
    for it in cmp.findings:
        per_kind[it.surface] = per_kind.get(it.surface, 0) + 1
    return {"summary_by_surface": cmp.summary_by_surface(), "differences_reported": reported,
            "bcf_topics": per_kind, "bcf_xsd_errors": bcf_xsd_errors(bcf)}


def run(scene: str, seed: int, run_dir: Path, redo: bool) -> dict:
    from sbsc_core.cli import main

    name = Path(scene).stem if scene.endswith((".yaml", ".json")) else scene
    tag = f"{name}_s{seed}"
    sim, det, out = run_dir / tag / "sim", run_dir / tag / "detect", run_dir / tag / "bim"
    sim.parent.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    building = scene.startswith("building:")
    if building:
        tag = f"building{scene.split(':')[1]}_s{seed}"
        sim, det, out = run_dir / tag / "sim", run_dir / tag / "detect", run_dir / tag / "bim"
        sim.parent.mkdir(parents=True, exist_ok=True)
    if redo or not (sim / "as_designed.ifc").exists():
        args = ["-q", "simulate", "--scene", scene, "--seed", str(seed), "--ceiling-objects", "--columns",
                "--out", str(sim)]
        if scene in ("I", "II"):
            args[2:4] = ["--scenario", scene]
        if building:
            args[2:4] = ["--scenario", "building", "--storeys", scene.split(":")[1]]
        if not (sim / "ground_truth.json").exists() or redo:
            if sim.exists():
                import shutil

                shutil.rmtree(sim)
            assert main(args) == 0
        if building:
            from sbsc_core.bim.design_writer import write_as_designed_ifc
            from sbsc_core.simulate.catalogue import CATALOGUE

            res = write_as_designed_ifc(json.loads((sim / "ground_truth.json").read_text()), sim / "as_designed.ifc",
                                        seed=seed, mount_heights={c: s.mount_height_m for c, s in CATALOGUE.items()})
            (sim.parent / "design_differences.json").write_text(json.dumps(res["design_differences"], indent=1))
    if redo or not (det / "detections.json").exists():
        scans = sorted((sim / "stations").iterdir()) if building else [sim / "scan.ply"]
        assert main(["-q", "detect", *map(str, scans), "--models", str(sim / "models"), "--expected",
                     str(sim / "expected.json"), "--ceilings", "--columns", "--out", str(det)]) == 0
    sim_detect_s = time.perf_counter() - t
    out.mkdir(parents=True, exist_ok=True)
    doc = json.loads((det / "detections.json").read_text())
    counts: dict[str, int] = {}
    for d in doc["detections"]:
        counts[d.get("surface", "wall")] = counts.get(d.get("surface", "wall"), 0) + 1
    storeys = len(doc.get("storeys") or []) or 1
    res = {"run": tag, "storeys": storeys, "detections": counts, "export": export_figures(doc, out),
           **compare_figures(sim, det, out), "simulate_detect_s": round(sim_detect_s, 1)}
    ex = res["export"]
    print(f"{tag}: detections {counts}; validate errors "
          + ", ".join(f"{s} {ex[s]['validate_errors']}" for s in SCHEMAS)
          + "; max read-back error (mm) " + json.dumps(ex["IFC4"]["max_error_mm"])
          + f"; IfcCovering {ex['IFC4']['coverings']}, IfcColumn {ex['IFC4']['columns']}, storeys {storeys} "
          f"(IfcBuildingStorey {ex['IFC4']['ifc_storeys']})")
    print(f"{tag}: differences reported per kind {res['differences_reported']}; BCF topics {res['bcf_topics']}, "
          f"XSD errors {res['bcf_xsd_errors']}; by surface {json.dumps(res['summary_by_surface'])}")
    return res


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", nargs="+", default=["one_room", str(ROOT / "benchmarks" / "scenes" / "two_halls.yaml")])
    p.add_argument("--full", action="store_true", help="add Scenario I (heavy)")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    p.add_argument("--run-dir", type=Path, default=Path("/work/scenes/bim/bench"))
    p.add_argument("--redo", action="store_true")
    p.add_argument("--json", type=Path, help="write the figures here")
    a = p.parse_args(argv)
    scenes = list(a.scene) + (["I"] if a.full else [])
    results = [run(scene, seed, a.run_dir, a.redo) for scene in scenes for seed in a.seeds]
    if a.json:
        a.json.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
