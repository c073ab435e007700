"""The review app's commands of ``sbsc``: ``serve``, ``user`` and ``import``.

They reach the command line through the entry-point group ``sbsc.commands`` (see
``pyproject.toml``), so the library ``sbsc_core`` never imports the web layer. Without
installed metadata (a bare source tree), ``python -m app`` runs the same command line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sbsc_core.cli import Commands


def _cmd_serve(args: argparse.Namespace) -> int:
    from .server import serve

    serve(host=args.host, port=args.port, open_browser=args.open)
    return 0


def _cmd_user_add(args: argparse.Namespace) -> int:
    from .users import add_user_cli

    print(add_user_cli(args.name, args.role))
    return 0


def _cmd_import(args: argparse.Namespace) -> int:
    from .config import AppSettings
    from .sample import import_detect_output

    settings = AppSettings()
    pid, made = import_detect_output(Path(args.detect_out), scans=[Path(p) for p in args.scan],
                                     models=Path(args.models) if args.models else None,
                                     name=args.name or f"{Path(args.detect_out).resolve().name}",
                                     design=Path(args.design) if args.design else None,
                                     settings=settings, say=print)
    what = "made" if made else "already there (kept as it is)"
    print(f"project {pid} {what}: {args.name or Path(args.detect_out).resolve().name} "
          f"(data: {settings.data_dir}); sbsc serve shows it")
    return 0


def register_import(cmds: Commands) -> None:
    """``sbsc import DETECT_OUT [--scan SCAN ...] [--name NAME] [--models DIR] [--design IFC]``."""
    v = cmds.add("import", func=_cmd_import, help="make a review project from a detect output (in $SBSC_DATA_DIR)")
    v.add_argument("detect_out", metavar="DETECT_OUT", help="the output folder of sbsc detect")
    v.add_argument("--scan", nargs="+", default=[], metavar="SCAN",
                   help="the scan file(s) it was run on (for the 3D scene; prepared now)")
    v.add_argument("--name", help="the project's name (default: the folder's name); "
                                  "a project of that name with results is kept as it is")
    v.add_argument("--models", help="the model library it was run with (default: the bundled one)")
    v.add_argument("--design", help="as-designed IFC to compare with (default: as_designed.ifc beside the scan)")


def _cmd_member(args: argparse.Namespace) -> int:
    from .users import change_member_cli

    print(change_member_cli(args.name, args.project, getattr(args, "role", None)))
    return 0


def register_serve(cmds: Commands) -> None:
    """``sbsc serve [--host H] [--port P] [--open]``."""
    v = cmds.add("serve", func=_cmd_serve, help="run the review app (data in $SBSC_DATA_DIR)")
    v.add_argument("--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)")
    v.add_argument("--port", type=int, default=8000,
                   help="port to listen on; 0 picks a free one (default: 8000)")
    v.add_argument("--open", action="store_true", help="open the browser on the start page")


def register_user(cmds: Commands) -> None:
    """``sbsc user add NAME --role reviewer|manager|admin``; ``sbsc user add-member NAME PROJECT
    --role viewer|reviewer|manager`` and ``sbsc user remove-member NAME PROJECT``."""
    u = cmds.add("user", help="manage API users of the review app")
    usub = u.add_subparsers(dest="user_command", required=True, metavar="ACTION")
    ua = usub.add_parser("add", parents=[cmds.common], help="create a user and print its API token once",
                         description="create a user and print its API token once")
    ua.add_argument("name", metavar="NAME", help="the user's name")
    ua.add_argument("--role", required=True, choices=["reviewer", "manager", "admin"],
                    help="what the user may do: reviewer (review), manager (also sign off), admin (everything)")
    ua.set_defaults(func=_cmd_user_add)
    um = usub.add_parser("add-member", parents=[cmds.common], help="make a user a member of a project",
                         description="make a user a member of a project, or change its role there")
    um.add_argument("name", metavar="NAME", help="the user's name")
    um.add_argument("project", metavar="PROJECT", type=int, help="the project's id")
    um.add_argument("--role", required=True, choices=["viewer", "reviewer", "manager"],
                    help="the user's role in the project (at most its global role)")
    um.set_defaults(func=_cmd_member)
    ur = usub.add_parser("remove-member", parents=[cmds.common], help="end a user's membership of a project",
                         description="end a user's membership of a project")
    ur.add_argument("name", metavar="NAME", help="the user's name")
    ur.add_argument("project", metavar="PROJECT", type=int, help="the project's id")
    ur.set_defaults(func=_cmd_member)


REGISTRARS = (register_serve, register_user, register_import)
