"""The ``sbsc`` command line (contract 6).

Every command exits 0 on success. Bad input prints one line, ``sbsc: error: ...``, naming
the file or field and the reason, and exits 2; no partial output is left behind.
Each sub-command imports its implementation lazily so that ``sbsc --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .errors import SbscError


def _cmd_simulate(args: argparse.Namespace) -> int:
    from .simulate.designs import design_builder
    from .simulate.scenarios import simulate_scenario

    builder = design_builder(args.designs)
    library = design_builder(args.library_designs) if args.library_designs else builder
    simulate_scenario(args.scenario, Path(args.out), seed=args.seed, angular_step_deg=args.step,
                      log=_log(args), object_builder=builder, library_builder=library)
    return 0


def _cmd_detect(args: argparse.Namespace) -> int:
    from .cpu_features import prefer_fast_sort

    prefer_fast_sort()  # before numpy is imported (AMD Zen 4: numpy's AVX2 sort is the fast one)
    from .pipeline import detect_to_dir

    detect_to_dir(
        [Path(s) for s in args.scans], Path(args.models),
        expected=Path(args.expected) if args.expected else None,
        out=Path(args.out), settings_file=Path(args.settings) if args.settings else None,
        log=_log(args), scheduler=args.scheduler,
    )
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate import evaluate_files

    print(evaluate_files(Path(args.detections), Path(args.truth),
                         json_out=Path(args.json) if args.json else None,
                         max_distance_m=args.max_distance))
    return 0


def _cmd_serve(args: argparse.Namespace) -> int:
    from app.server import serve

    serve(host=args.host, port=args.port, open_browser=args.open)
    return 0


def _cmd_user_add(args: argparse.Namespace) -> int:
    from app.users import add_user_cli

    print(add_user_cli(args.name, args.role))
    return 0


def _cmd_export_ifc(args: argparse.Namespace) -> int:
    from .bim.export import export_ifc_file

    export_ifc_file(Path(args.detections), Path(args.out), schema=args.schema,
                    accepted_only=args.accepted_only,
                    models=Path(args.models) if args.models else None)
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .bim.compare import compare_to_dir

    compare_to_dir(Path(args.as_designed), Path(args.detections), Path(args.out),
                   tolerance_m=args.tolerance)
    return 0


def _log(args: argparse.Namespace):
    if getattr(args, "quiet", False):
        return lambda msg: None
    return lambda msg: print(msg, file=sys.stderr, flush=True)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sbsc", description=__doc__.splitlines()[0])
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("simulate", help="scan a virtual floor (Scenario I or II) with ground truth")
    s.add_argument("--scenario", required=True, choices=["I", "II"])
    s.add_argument("--out", required=True)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--step", type=float, default=None, help="scanner angular step in degrees")
    s.add_argument("--designs", choices=["standard", "alt"], default="standard",
                   help="design set the objects are built with (default: standard)")
    s.add_argument("--library-designs", choices=["standard", "alt"], default=None,
                   help="design set of the model library (default: the same as --designs)")
    s.set_defaults(func=_cmd_simulate)

    d = sub.add_parser("detect", help="recognize objects on the walls of a scan")
    d.add_argument("scans", nargs="+", metavar="SCAN")
    d.add_argument("--models", required=True, help="model library directory (contract 2)")
    d.add_argument("--expected", help="expected.json (contract 3); default: search every class")
    d.add_argument("--out", required=True)
    d.add_argument("--settings", help="JSON/YAML file overriding DetectionSettings")
    d.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the per-wall work on an existing Dask cluster (e.g. tcp://10.0.0.5:8786); its "
                        "workers must see the scans and the output's folder at the same paths; default: "
                        "a local process pool")
    d.set_defaults(func=_cmd_detect)

    e = sub.add_parser("evaluate", help="compare detections with ground truth (paper's Table 1)")
    e.add_argument("--detections", required=True)
    e.add_argument("--truth", required=True)
    e.add_argument("--json")
    e.add_argument("--max-distance", type=float, default=0.10, help="match radius in metres")
    e.set_defaults(func=_cmd_evaluate)

    v = sub.add_parser("serve", help="run the review app")
    v.add_argument("--host", default="127.0.0.1")
    v.add_argument("--port", type=int, default=8000)
    v.add_argument("--open", action="store_true", help="open the browser")
    v.set_defaults(func=_cmd_serve)

    u = sub.add_parser("user", help="manage API users")
    usub = u.add_subparsers(dest="user_command", required=True)
    ua = usub.add_parser("add", help="create a user and print its API token once")
    ua.add_argument("name")
    ua.add_argument("--role", required=True, choices=["reviewer", "manager", "admin"])
    ua.set_defaults(func=_cmd_user_add)

    x = sub.add_parser("export-ifc", help="write detections as an IFC as-is model")
    x.add_argument("detections")
    x.add_argument("--out", required=True)
    x.add_argument("--schema", default="IFC4", help="IFC4 (default) or IFC4X3")
    x.add_argument("--accepted-only", action="store_true")
    x.add_argument("--models", help="model library for IFC classes (default: bundled)")
    x.set_defaults(func=_cmd_export_ifc)

    c = sub.add_parser("compare", help="Scan-vs-BIM: detections against an as-designed IFC")
    c.add_argument("--as-designed", required=True)
    c.add_argument("--detections", required=True)
    c.add_argument("--out", required=True)
    c.add_argument("--tolerance", type=float, default=0.10, help="displacement tolerance, metres")
    c.set_defaults(func=_cmd_compare)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except SbscError as exc:
        print(f"sbsc: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("sbsc: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
