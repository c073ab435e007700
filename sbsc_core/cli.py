"""The ``sbsc`` command line (contract 6).

Conventions, the same for every command:

- ``--version``; ``-q/--quiet``, ``-v/--verbose`` and ``--debug`` anywhere on the line
  (before or after the command).
- Messages and progress go to stderr: progress bars per stage and per wall only when stderr
  is a terminal and ``-q`` is not given; ``-q`` keeps only warnings and errors; ``-v`` adds
  details. ``--json`` prints a machine-readable summary on stdout (``evaluate --json -``).
- Exit 0 on success. Bad input prints one line, ``sbsc: error: ...``, naming the file or
  field and the reason, and exits 2; no partial output is left behind, and a missing parent
  folder of an output is an error, never created. An internal error is one line too (exit 1)
  with a hint to ``--debug``, which shows the traceback. Numerical warnings are not printed.

Each command imports its implementation lazily so that ``sbsc --help`` stays fast. Commands
of other packages (the review app's ``serve`` and ``user``) register through the entry-point
group ``sbsc.commands``: a callable that receives a :class:`Commands` and adds its sub-parsers.
The library never imports them.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import math
import os
import re
import signal
import sys
import traceback
import warnings
from collections.abc import Callable, Iterator, Sequence
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from . import __version__
from .errors import InputError, SbscError
from .stages import Stage

ENTRY_POINT_GROUP = "sbsc.commands"
LOGGER = "sbsc"
EXIT_BAD_INPUT = 2
EXIT_INTERNAL = 1

Command = Callable[[argparse.Namespace], int | None]
Registrar = Callable[["Commands"], None]


# --------------------------------------------------------------------------- parser


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line, like every other error."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(EXIT_BAD_INPUT, f"sbsc: error: {message} (see {self.prog} --help)\n")


def number(kind: type, *, minimum: float | None = None, above: float | None = None,
           maximum: float | None = None) -> Callable[[str], Any]:
    """An argparse ``type``: an int or a finite float within bounds, else a usage error (exit 2)."""
    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not {'an integer' if kind is int else 'a number'}: {text!r}") from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number, not {text}")
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, not {text}")
        if above is not None and not value > above:
            raise argparse.ArgumentTypeError(f"must be more than {above}, not {text}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"must be at most {maximum}, not {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


def output_path(what: str) -> Callable[[str], str]:
    """An argparse ``type`` for an output (``dir`` or ``file``): checked before any work starts.

    A folder output must not be an existing file, a file output not an existing folder, and
    the parent folder must exist (it is never created silently); ``-`` is stdout.
    """
    def check(text: str) -> str:
        if text == "-" and what == "file":
            return text
        p = Path(text)
        if what == "dir" and p.exists() and not p.is_dir():
            raise argparse.ArgumentTypeError(f"{text} exists and is not a folder")
        if what == "file" and p.is_dir():
            raise argparse.ArgumentTypeError(f"{text} is a folder, not a file")
        parent = p.absolute().parent
        if parent.exists() and not parent.is_dir():
            raise argparse.ArgumentTypeError(f"{parent} is a file, not a folder")
        if not parent.is_dir():
            raise argparse.ArgumentTypeError(f"folder {parent} does not exist (create it first)")
        return text

    check.__name__ = f"output {what}"
    return check


def common_options() -> argparse.ArgumentParser:
    """``-q``, ``-v`` and ``--debug``, accepted before and after the command.

    Their defaults are suppressed so that a sub-parser does not reset what the main
    parser has read.
    """
    c = argparse.ArgumentParser(add_help=False)
    g = c.add_argument_group("output")
    g.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                   help="print only warnings and errors; no progress")
    g.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                   help="print more details (debug messages)")
    g.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                   help="show the traceback of an error and every warning")
    return c


class Commands:
    """The sub-commands of ``sbsc``; what an ``sbsc.commands`` entry point receives."""

    def __init__(self, subparsers: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
        self.subparsers = subparsers
        self.common = common
        self.names: list[str] = []

    def add(self, name: str, *, help: str, func: Command | None = None,
            description: str | None = None) -> argparse.ArgumentParser:
        """Add the sub-command ``name`` (with the common options) and return its parser.

        A name that is already taken raises ``ValueError``.
        """
        if name in self.subparsers.choices:
            raise ValueError(f"command {name!r} exists already")
        p = self.subparsers.add_parser(name, help=help, description=description or help,
                                       parents=[self.common])
        if func is not None:
            p.set_defaults(func=func)
        self.names.append(name)
        return p


def output_option(p: argparse.ArgumentParser, what: str, required: bool = True) -> None:
    p.add_argument("--out", required=required, metavar="DIR" if what == "dir" else "FILE", type=output_path(what),
                   help=("output folder (created; its parent folder must exist)" if what == "dir"
                         else "output file (its folder must exist)"))


def json_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")


def _add_simulate(cmds: Commands) -> None:
    s = cmds.add("simulate", func=_cmd_simulate,
                 help="scan a virtual floor (a bundled scene or a description) with ground truth")
    s.add_argument("--scenario", choices=["I", "II", "building"],
                   help="the paper's floor: I (neutral walls) or II (walls close to the objects' colours); "
                        "building: several storeys, one file per station")
    s.add_argument("--scene", metavar="NAME|FILE",
                   help="a bundled scene (one_room, scenario_I, scenario_II) or a scene description .yaml; "
                        "with --scenario building the style of its floors: scenario (default) or one_room")
    s.add_argument("--storeys", type=number(int, minimum=1, maximum=100), default=2, metavar="N",
                   help="--scenario building: number of storeys (default: 2)")
    s.add_argument("--format", choices=["ply", "e57", "las"], default="ply",
                   help="--scenario building: file format, one file per station (default: ply)")
    output_option(s, "dir")
    s.add_argument("--seed", type=number(int, minimum=0, maximum=2**32 - 1), default=0, help="random seed of the scanner noise and the design changes (default: 0)")
    s.add_argument("--step", type=number(float, above=0.0, maximum=90.0), default=None, metavar="DEG",
                   help="scanner angular step in degrees (default: the scene's)")
    s.add_argument("--designs", choices=["standard", "alt", "third", "random"], default="standard",
                   help="design set the objects are built with (default: standard; third: for testing only; "
                        "random: a new family for --design-seed)")
    s.add_argument("--library-designs", choices=["standard", "alt", "third", "random", "sibling"], default=None,
                   help="design set of the model library (default: the same as --designs; sibling, with --designs "
                        "random: the family of --library-design-seed made at the scene family's sizes, as alt is "
                        "to standard)")
    s.add_argument("--design-seed", type=int, default=None, metavar="N",
                   help="--designs random: the family's seed (default: --seed)")
    s.add_argument("--library-design-seed", type=int, default=None, metavar="N",
                   help="--library-designs random or sibling: the library family's seed (default: the scene's "
                        "family seed; for sibling, that seed + 1)")
    s.add_argument("--realistic", action="store_true",
                   help="realistic scanner: mixed pixels, range noise growing with range and incidence, "
                        "dropouts, registration error, per-station exposure, highlights")
    s.add_argument("--clutter", action="store_true", help="wall clutter that is none of the classes")
    s.add_argument("--furniture", action="store_true", help="furniture in front of the walls")
    s.add_argument("--survey-frame", action="store_true",
                   help="write scan and truth at UTM-like coordinates, turned 23.5 degrees in plan")
    s.add_argument("--all-realism", action="store_true", help="all four options above together")
    s.add_argument("--ceiling-objects", action="store_true",
                   help="smoke detectors and exit lights on the ceilings too (the truth says each object's surface)")
    s.add_argument("--columns", action="store_true",
                   help="free-standing columns, rectangular and round, with objects on their faces")
    json_option(s)


def _add_detect(cmds: Commands) -> None:
    from .io.scans import scan_extensions

    d = cmds.add("detect", func=_cmd_detect, help="recognize objects on the walls of a scan")
    d.add_argument("scans", nargs="+", metavar="SCAN",
                   help=f"scan files of one building ({' '.join(scan_extensions())}), registered")
    d.add_argument("--models", required=True, metavar="DIR", help="model library directory (contract 2)")
    d.add_argument("--expected", metavar="FILE", help="expected.json (contract 3); default: search every class")
    output_option(d, "dir")
    d.add_argument("--settings", metavar="FILE", help="JSON/YAML file overriding DetectionSettings")
    d.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the per-wall work on an existing Dask cluster (e.g. tcp://10.0.0.5:8786); its "
                        "workers must see the scans and the output's folder at the same paths; default: "
                        "a local process pool")
    d.add_argument("--no-ceilings", dest="ceilings", action="store_false", default=None,
                   help="do not search the ceilings (by default they are, when a class's model.json mount "
                        "has 'ceiling' or no mount)")
    d.add_argument("--no-columns", dest="columns", action="store_false", default=None,
                   help="do not look for free-standing columns (by default they are searched, when a "
                        "class's mount has 'column' or no mount)")
    d.add_argument("--ceilings", dest="ceilings", action="store_true",
                   help="search the ceilings even when a settings file turns them off (the default otherwise)")
    d.add_argument("--columns", dest="columns", action="store_true",
                   help="search the columns even when a settings file turns them off (the default otherwise)")
    json_option(d)


def _add_evaluate(cmds: Commands) -> None:
    e = cmds.add("evaluate", func=_cmd_evaluate,
                 help="compare detections with ground truth (the paper's Table 1)")
    e.add_argument("--detections", required=True, metavar="FILE", help="detections.json of sbsc detect")
    e.add_argument("--truth", required=True, metavar="FILE", help="ground_truth.json of sbsc simulate")
    e.add_argument("--json", metavar="FILE", type=output_path("file"),
                   help="also write the table as JSON to FILE; '-' prints only the JSON on stdout")
    e.add_argument("--max-distance", type=number(float, above=0.0), default=0.10, metavar="M",
                   help="match radius in metres (default: 0.10)")
    e.add_argument("--models", metavar="DIR",
                   help="model library whose class order and names the table uses (default: the bundled one)")


def _add_export_ifc(cmds: Commands) -> None:
    x = cmds.add("export-ifc", func=_cmd_export_ifc, help="write detections as an IFC as-is model")
    x.add_argument("detections", metavar="DETECTIONS", help="detections.json of sbsc detect")
    output_option(x, "file")
    x.add_argument("--schema", default="IFC4", metavar="SCHEMA",
                   help="IFC4 (default), IFC4X3 or IFC2X3")
    x.add_argument("--accepted-only", action="store_true",
                   help="only detections a reviewer accepted (review documents)")
    x.add_argument("--models", metavar="DIR", help="model library for IFC classes (default: bundled)")
    x.add_argument("--crs", metavar="EPSG:NNNN",
                   help="projected CRS of the scan's coordinates (default: the CRS recorded in the detections, if any)")
    json_option(x)


def _add_compare(cmds: Commands) -> None:
    c = cmds.add("compare", func=_cmd_compare, help="Scan-vs-BIM: detections against an as-designed IFC")
    c.add_argument("--as-designed", required=True, metavar="IFC", help="the as-designed IFC model")
    c.add_argument("--detections", required=True, metavar="FILE", help="detections.json of sbsc detect")
    output_option(c, "dir")
    c.add_argument("--tolerance", type=number(float, above=0.0), default=0.10, metavar="M",
                   help="displacement tolerance in metres (default: 0.10)")
    json_option(c)


def _add_learn(cmds: Commands) -> None:
    """Register ``sbsc learn DETECT_OUT --reviewed FILE --models DIR --out NEWDIR [--classes FILE]``."""

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
    from .recognition.learning.library import learn_library

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


BUILTIN: tuple[Registrar, ...] = (_add_simulate, _add_detect, _add_evaluate, _add_export_ifc, _add_compare,
                                  _add_learn)


def plugin_registrars() -> list[Registrar]:
    """The callables of the ``sbsc.commands`` entry points of the installed packages."""
    found = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        try:
            found.append(ep.load())
        except Exception as exc:  # a broken plugin must not break the other commands
            logging.getLogger(LOGGER).warning("sbsc: command %r not loaded: %s", ep.name, exc)
    return found


def build_parser(registrars: Sequence[Registrar] | None = None) -> argparse.ArgumentParser:
    """The parser of ``sbsc`` with the built-in commands and those of ``registrars``.

    ``registrars`` defaults to the ``sbsc.commands`` entry points; a registrar adding a name
    that already exists is skipped.
    """
    common = common_options()
    p = Parser(prog="sbsc", parents=[common],
               description="Find secondary building service components (sockets, switches, signs, ...) "
                           "in coloured laser scans, review them and export them to IFC.",
               epilog="Options -q, -v and --debug may also follow the command.")
    p.add_argument("--version", action="version", version=f"sbsc {__version__}",
                   help="print the version and exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    cmds = Commands(sub, common)
    for reg in BUILTIN:
        reg(cmds)
    for reg in plugin_registrars() if registrars is None else registrars:
        try:
            reg(cmds)
        except ValueError as exc:
            logging.getLogger(LOGGER).warning("sbsc: %s: %s", getattr(reg, "__name__", reg), exc)
    return p


# --------------------------------------------------------------------------- output


class Console:
    """Where a command writes: log messages and progress bars on stderr, results on stdout."""

    def __init__(self, quiet: bool = False, verbose: int = 0, debug: bool = False) -> None:
        self.quiet, self.verbose, self.debug = quiet, verbose, debug
        self.progress_enabled = not quiet and _isatty(sys.stderr)
        self._bar = None
        self._stage: str | None = None
        self.logger = logging.getLogger(LOGGER)

    def info(self, msg: str) -> None:
        self.logger.info(msg)

    def step(self, msg: str) -> None:
        """A line per item of a long loop (a scanner station): shown on a terminal, else only with -v."""
        if self.progress_enabled:
            self.logger.info(msg)
        else:
            self.logger.debug(msg)

    def simulation_log(self, msg: str) -> None:
        """The simulator's messages: its per-station lines are progress (:meth:`step`)."""
        (self.step if _STATION_LINE.match(msg) else self.info)(msg)

    def progress(self, stage: str, fraction: float) -> None:
        """A bar per stage; the ``walls`` stage counts walls (``Progress`` of the pipeline)."""
        if not self.progress_enabled:
            return
        from tqdm import tqdm

        if stage != self._stage:
            self.close()
            self._stage = stage
            if stage == Stage.DONE:
                return
            total, unit = 100, "%"
            if stage == Stage.WALLS and fraction > 0:
                n = 1.0 / fraction
                if abs(n - round(n)) < 1e-6:
                    total, unit = round(n), " walls"
            self._bar = tqdm(total=total, desc=f"{stage:<12}", unit=unit, file=sys.stderr, leave=False,
                             dynamic_ncols=True, bar_format="{desc} {percentage:3.0f}%|{bar}| "
                             "{n_fmt}/{total_fmt}{unit} [{elapsed}]" if unit != "%" else
                             "{desc} {percentage:3.0f}%|{bar}| [{elapsed}]")
        if self._bar is not None:
            n = round(fraction * self._bar.total)
            self._bar.update(max(0, n - self._bar.n))

    def close(self) -> None:
        if self._bar is not None:
            self._bar.refresh()  # the stage's last state, then the line is cleared
            self._bar.close()
            self._bar = None

    def result(self, data: Any) -> None:
        """The ``--json`` summary on stdout."""
        print(json.dumps(_jsonable(data), indent=2), flush=True)


_STATION_LINE = re.compile(r"^(S\d+ )?station \d+/\d+")


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


class _TqdmHandler(logging.Handler):
    """Log lines on stderr that do not break a progress bar."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            msg = self.format(record)
            from tqdm import tqdm

            tqdm.write(msg, file=sys.stderr)
        except Exception:  # pragma: no cover - logging must not raise
            self.handleError(record)


def _jsonable(x: Any) -> Any:
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return _jsonable(dataclasses.asdict(x))
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if hasattr(x, "tolist"):
        return x.tolist()
    return x


_console: Console | None = None


def console() -> Console:
    """The console of the running command (a quiet one outside ``main``)."""
    return _console or Console(quiet=True)


@contextlib.contextmanager
def _configured(con: Console) -> Iterator[None]:
    """Log handler and warning filters for one run of ``main``; undone afterwards."""
    global _console
    level = (logging.DEBUG if con.verbose or con.debug else logging.WARNING if con.quiet else logging.INFO)
    handler = _TqdmHandler()
    handler.setFormatter(logging.Formatter("%(message)s"))
    loggers = [logging.getLogger(n) for n in (LOGGER, "sbsc_core")]
    saved = [(lg, lg.level, lg.propagate) for lg in loggers]
    env_saved = os.environ.get("PYTHONWARNINGS")
    for lg in loggers:
        lg.addHandler(handler)
        lg.setLevel(level)
        lg.propagate = False
    _console = con
    try:
        with warnings.catch_warnings():
            if not con.debug:
                # numpy's RuntimeWarnings (empty slices, NaN means) are expected on real scans;
                # worker processes inherit the filter through the environment
                warnings.simplefilter("ignore", RuntimeWarning)
                os.environ["PYTHONWARNINGS"] = "ignore::RuntimeWarning"
            yield
    finally:
        con.close()
        _console = None
        for lg, lvl, prop in saved:
            lg.removeHandler(handler)
            lg.setLevel(lvl)
            lg.propagate = prop
        if env_saved is None:
            os.environ.pop("PYTHONWARNINGS", None)
        else:
            os.environ["PYTHONWARNINGS"] = env_saved


# --------------------------------------------------------------------------- checks


def output_parent(path: str | Path, option: str = "--out") -> Path:
    """``path`` if its parent folder exists; else the one-line error (never created silently)."""
    p = Path(path)
    parent = p.absolute().parent
    if not parent.is_dir():
        raise InputError(option, f"folder {parent} does not exist (create it first)")
    return p


# --------------------------------------------------------------------------- commands


def _cmd_simulate(args: argparse.Namespace) -> int:
    from .paths import scene_path
    from .simulate.designs import design_builder, library_builder
    from .simulate.scenarios import simulate_scenario, simulate_scene

    if (args.scenario is None) == (args.scene is None) and args.scenario != "building":
        raise InputError("--scenario", "give either --scenario or --scene")
    con = console()
    out = output_parent(args.out)
    design_seed = args.seed if args.design_seed is None else args.design_seed
    builder = design_builder(args.designs, design_seed)
    library = library_builder(args.library_designs, builder, design_seed, args.library_design_seed)
    everything = args.all_realism
    realism = {"realistic": args.realistic or everything, "clutter": args.clutter or everything,
               "furniture": args.furniture or everything, "survey_frame": args.survey_frame or everything}
    surfaces = {"ceiling_objects": args.ceiling_objects, "columns": args.columns}
    if args.scenario == "building":
        from .simulate.building_scenario import simulate_building

        summary = simulate_building(out, args.storeys, scene=args.scene or "scenario", fmt=args.format,
                                    seed=args.seed, angular_step_deg=args.step, log=con.simulation_log,
                                    object_builder=builder, **realism, **surfaces)
    elif args.scene:
        summary = simulate_scene(scene_path(args.scene), out, seed=args.seed, angular_step_deg=args.step,
                                 log=con.simulation_log, object_builder=builder, library_builder=library,
                                 **realism, **surfaces)
    else:
        summary = simulate_scenario(args.scenario, out, seed=args.seed, angular_step_deg=args.step,
                                    log=con.simulation_log, object_builder=builder, library_builder=library,
                                    **realism, **surfaces)
    if args.json:
        con.result({"out": out, **_jsonable(summary)})
    return 0


def _cmd_detect(args: argparse.Namespace) -> int:
    from .pipeline.allocator import keep_freed_memory
    from .pipeline.cpu_features import prefer_fast_sort

    prefer_fast_sort()  # before numpy is imported (AMD Zen 4: numpy's AVX2 sort is the fast one)
    keep_freed_memory()  # arrays freed are used again, not faulted in again (here and in the workers)
    from .pipeline.detect import detect_to_dir

    con = console()
    out = output_parent(args.out)
    settings = None
    if args.ceilings is not None or args.columns is not None:  # the flags override the settings file
        from .settings import load_settings

        settings = load_settings(Path(args.settings) if args.settings else None)
        if args.ceilings is not None:
            settings.ceilings.enabled = args.ceilings
        if args.columns is not None:
            settings.columns.enabled = args.columns
    summary = detect_to_dir(
        [Path(s) for s in args.scans], Path(args.models),
        expected=Path(args.expected) if args.expected else None,
        out=out, settings_file=Path(args.settings) if args.settings else None, settings=settings,
        log=con.info, progress=con.progress, scheduler=args.scheduler,
    )
    con.close()
    con.info(f"wrote {out / 'detections.json'}")
    if args.json:
        con.result({"out": out, **summary})
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate import evaluate, format_table, read_detections, read_truth

    if not (args.max_distance > 0):
        raise InputError("--max-distance", f"must be > 0, got {args.max_distance}")
    to_stdout = args.json == "-"
    json_out = output_parent(args.json, "--json") if args.json and not to_stdout else None
    library = None
    if args.models:
        from .io.models import read_library_metadata

        library = read_library_metadata(Path(args.models))
    table = evaluate(read_detections(Path(args.detections)), read_truth(Path(args.truth)),
                     args.max_distance, library=library)
    if to_stdout:
        console().result(table.to_dict())
        return 0
    if json_out is not None:
        from .io.atomic import write_json_atomic

        write_json_atomic(json_out, table.to_dict())
    print(format_table(table))
    return 0


def _cmd_export_ifc(args: argparse.Namespace) -> int:
    from .bim.export import export_ifc_file

    con = console()
    out = output_parent(args.out)
    summary = export_ifc_file(Path(args.detections), out, schema=args.schema,
                              accepted_only=args.accepted_only,
                              models=Path(args.models) if args.models else None,
                              **({"crs": args.crs} if args.crs else {}))
    summary = summary or {}
    counts = ", ".join(f"{v} {k}" for k, v in summary.items() if isinstance(v, int))
    con.info(f"wrote {out}" + (f" ({summary.get('schema', '')}: {counts})" if counts else ""))
    if args.json:
        con.result({"out": out, **summary})
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from .bim.compare_outputs import compare_to_dir

    con = console()
    out = output_parent(args.out)
    comparison = compare_to_dir(Path(args.as_designed), Path(args.detections), out,
                                tolerance_m=args.tolerance)
    summary = comparison.summary()
    con.info(f"wrote {out}/comparison.json, report.html, findings.bcf: "
             + ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in summary.items()))
    by_surface = comparison.summary_by_surface()
    if set(by_surface) - {"wall"}:  # objects on ceilings or columns: one line per kind of surface
        for kind, counts in by_surface.items():
            con.info(f"  on {kind}s: " + ", ".join(f"{n} {k.replace('_', ' ')}" for k, n in counts.items()))
    if args.json:
        con.result({"out": out, "summary": summary, "summary_by_surface": by_surface,
                    "findings": len(comparison.findings)})
    return 0


# --------------------------------------------------------------------------- main


class Stopped(BaseException):
    """SIGTERM or SIGINT: the command stops, cleaning up as it goes (not an ``Exception``, so
    nothing on the way mistakes it for an error of its own)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _stop(signum: int, _frame: Any) -> None:
    """The handler of SIGTERM / SIGINT: end the worker processes at once (the pools then
    shut down without waiting for their tasks), then unwind the command (its ``with``
    blocks remove the scratch folder and any partial output). Further signals are ignored
    while it cleans up."""
    import multiprocessing

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, signal.SIG_IGN)
    for child in multiprocessing.active_children():
        with contextlib.suppress(Exception):
            child.terminate()
    raise Stopped(signum)


@contextlib.contextmanager
def _stoppable() -> Iterator[None]:
    """SIGTERM and SIGINT stop the whole command (in the main thread; restored afterwards)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved = {sig: signal.signal(sig, _stop) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)


def main(argv: Sequence[str] | None = None, registrars: Sequence[Registrar] | None = None) -> int:
    """Run ``sbsc`` with ``argv`` (default: the process's arguments); return the exit code.

    SIGTERM (as ``timeout`` or a batch scheduler sends it) and SIGINT stop the command with
    its worker processes and scratch folder; the exit status is 128 + the signal (143, 130).
    """
    args = build_parser(registrars).parse_args(argv)
    con = Console(quiet=getattr(args, "quiet", False), verbose=getattr(args, "verbose", 0) or 0,
                  debug=getattr(args, "debug", False))
    with _configured(con), _stoppable():
        try:
            return int(args.func(args) or 0)
        except Stopped as exc:
            con.close()
            print(f"sbsc: stopped by {exc}", file=sys.stderr)
            code = 128 + exc.signum
        except SbscError as exc:
            con.close()
            if con.debug:
                traceback.print_exc()
            print(f"sbsc: error: {exc}", file=sys.stderr)
            return EXIT_BAD_INPUT
        except KeyboardInterrupt:
            con.close()
            print("sbsc: interrupted", file=sys.stderr)
            return 130
        except OSError as exc:  # a file of the user's that cannot be read or written
            con.close()
            if con.debug:
                traceback.print_exc()
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"sbsc: error: {where}{exc.strerror or exc} (--debug shows the traceback)",
                  file=sys.stderr)
            return EXIT_BAD_INPUT if exc.filename else EXIT_INTERNAL
        except Exception as exc:
            con.close()
            if con.debug:
                traceback.print_exc()
                return EXIT_INTERNAL
            text = " ".join(str(exc).split()) or "no message"
            print(f"sbsc: internal error: {type(exc).__name__}: {text} "
                  "(run again with --debug for the traceback)", file=sys.stderr)
            return EXIT_INTERNAL
    # Stopped: the command has cleaned up (scratch folder, partial output) and its workers are
    # gone. The process ends here: at a normal exit Python joins the worker pools' manager
    # threads, and one may wait forever on a result that a terminated worker half sent.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    sys.exit(main())
