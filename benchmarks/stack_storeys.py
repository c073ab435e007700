"""A building of several storeys made of one outside floor, for issue 27's "whole buildings as
good as one floor" (a two-storey scan within one object of its storeys alone).

    .venv/bin/python benchmarks/stack_storeys.py SCENE_DIR --out DIR [--storeys 2] [--slab 0.3]

``SCENE_DIR`` is a folder of ``bench_outside.py`` (``scan.laz``, ``ground_truth.json``,
``expected.json``, ``models/``). The floor is copied ``--storeys`` times, each copy raised by
the floor's height (the highest point of the scan, 99.99th percentile, above the lowest,
0.01th) plus ``--slab`` metres of floor slab that no scanner sees into. ``DIR`` gets
``SCENE_DIR``'s name with ``-xN`` and is itself a folder of outside scenes for
``bench_outside.py --scenes DIR``:

- ``scan.laz``: the copies in one file (laspy; the input's scales and offsets);
- ``ground_truth.json``: the objects and distractors of every copy, raised, with their
  ``storey`` (``S1`` from the bottom) and ids made unique; walls, surfaces and columns are
  left out (the evaluator scores objects only);
- ``expected.json``: the building's counts and each storey's (``storeys``, contract 3's
  extension), as an as-designed model of the building would give them;
- ``models/``: a link to the floor's library.

The stacked scan is what a building of identical storeys scanned floor by floor would be:
the same objects, clutter and scanner pattern on every storey. So the building's Table 1
should be the floor's, storey by storey; what differs is what the whole-building pipeline
does (storeys found from the scan, each storey's walls, ceilings and counts).
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np


def raise_objects(items: list[dict], dz: float, storey: str) -> list[dict]:
    """Copies of ground-truth objects or distractors ``dz`` metres higher, on ``storey``."""
    out = []
    for o in items:
        o = copy.deepcopy(o)
        o["position"] = [o["position"][0], o["position"][1], o["position"][2] + dz]
        for key in ("wall", "u", "v"):  # the raised copy stands on no wall of the floor's ids
            o.pop(key, None)
        if "id" in o:
            o["id"] = f"{storey}-{o['id']}"
        o["storey"] = storey
        out.append(o)
    return out


def stack(scene: Path, out_root: Path, *, storeys: int, slab_m: float) -> Path:
    """Write the stacked scene folder (see the module) and return it."""
    import laspy

    las = laspy.read(scene / "scan.laz")
    z = np.asarray(las.z)
    lo, hi = np.percentile(z, [0.01, 99.99])
    pitch = float(hi - lo) + slab_m
    out = out_root / f"{scene.name}-x{storeys}"
    out.mkdir(parents=True, exist_ok=True)
    header = laspy.LasHeader(point_format=las.header.point_format, version=las.header.version)
    header.scales, header.offsets = las.header.scales, las.header.offsets
    n = len(las.points)
    stacked = laspy.ScaleAwarePointRecord.zeros(n * storeys, header=header)
    for k in range(storeys):
        part = slice(k * n, (k + 1) * n)
        stacked.x[part], stacked.y[part], stacked.z[part] = las.x, las.y, z + k * pitch
        for dim in ("red", "green", "blue", "intensity"):
            if dim in set(las.point_format.dimension_names):
                stacked[dim][part] = las[dim]
    new = laspy.LasData(header=header, points=stacked)
    new.write(out / "scan.laz")

    truth = json.loads((scene / "ground_truth.json").read_text())
    expected = json.loads((scene / "expected.json").read_text())
    doc = {"schema": truth.get("schema", "sbsc.truth/1"), "objects": [], "distractors": []}
    for k in range(storeys):
        sid = f"S{k + 1}"
        doc["objects"] += raise_objects(truth["objects"], k * pitch, sid)
        doc["distractors"] += raise_objects(truth.get("distractors", []), k * pitch, sid)
    doc["storeys"] = [{"id": f"S{k + 1}", "floor_z": round(float(lo) + k * pitch, 4),
                       "ceiling_z": round(float(hi) + k * pitch, 4)} for k in range(storeys)]
    (out / "ground_truth.json").write_text(json.dumps(doc, indent=1))
    counts = {c: int(v) * storeys for c, v in expected["counts"].items()}
    per = {f"S{k + 1}": dict(expected["counts"]) for k in range(storeys)}
    (out / "expected.json").write_text(json.dumps({"schema": "sbsc.expected/1", "counts": counts, "storeys": per},
                                                  indent=1))
    link = out / "models"
    if not link.exists():
        link.symlink_to((scene / "models").resolve(), target_is_directory=True)
    print(f"{out}: {storeys} storeys {pitch:.2f} m apart, {n * storeys:,} points, "
          f"{len(doc['objects'])} objects")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", type=Path, help="an outside scene folder")
    ap.add_argument("--out", type=Path, required=True, help="folder that gets the stacked scene folder")
    ap.add_argument("--storeys", type=int, default=2)
    ap.add_argument("--slab", type=float, default=0.3, help="floor slab between storeys (m)")
    args = ap.parse_args(argv)
    if args.storeys < 2:
        ap.error("--storeys must be 2 or more")
    stack(args.scene, args.out, storeys=args.storeys, slab_m=args.slab)
    return 0


if __name__ == "__main__":
    sys.exit(main())
