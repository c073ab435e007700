"""The ``sbsc learn`` command (contract 6): its arguments and what it prints."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_learn(cmds) -> None:  # noqa: ANN001 - sbsc_core.cli.Commands (imported lazily by the cli)
    """Register ``sbsc learn DETECT_OUT --reviewed FILE --models DIR --out NEWDIR [--classes FILE]``."""
    from ..cli import json_option, output_option

    p = cmds.add("learn", func=_cmd_learn,
                 help="teach a model library new classes and designs from reviewed objects of a detect output")
    p.add_argument("detect_out", metavar="DETECT_OUT", help="a folder written by sbsc detect --out")
    p.add_argument("--reviewed", required=True, metavar="FILE",
                   help="detections document of the accepted, relabelled and added objects (contract 4); "
                        "an object may give only its class and position")
    p.add_argument("--models", required=True, metavar="DIR", help="the model library the detection used")
    output_option(p, "dir")
    p.add_argument("--classes", metavar="FILE",
                   help="CLASSES.json: new class id -> {name, ifc_class, predefined_type?, mount?}")
    json_option(p)


def _cmd_learn(args: argparse.Namespace) -> int:
    from ..cli import console, output_parent
    from ..errors import InputError
    from .library import learn_library

    con = console()
    out = output_parent(args.out)
    detect_out = Path(args.detect_out)
    if not detect_out.is_dir():
        raise InputError(detect_out, "no such folder (give the --out folder of sbsc detect)")
    taught = learn_library(detect_out, Path(args.reviewed), Path(args.models), out,
                           classes=Path(args.classes) if args.classes else None, log=con.info)
    changed = [t for t in taught if t.action != "matches"]
    con.info(f"wrote {out}: {sum(t.action == 'new class' for t in taught)} new class(es), "
             f"{sum(t.action == 'new design' for t in taught)} new design(s), "
             f"{len(taught) - len(changed)} class(es) already matching")
    if args.json:
        con.result({"out": out, "classes": [t.to_dict() for t in taught]})
    return 0
