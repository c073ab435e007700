"""Stand-alone viewer of one ``sbsc detect`` output directory (no database).

    python -m app.viewer OUT_DIR [--scan SCAN ...] [--models DIR] [--port P]

Decisions are kept in memory only; the token to enter in the scene is printed.
"""

from __future__ import annotations

import argparse
import secrets
import time
from pathlib import Path

import viser

from .backend import InMemoryBackend
from .scene import ProjectScene


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m app.viewer", description=__doc__.splitlines()[0])
    p.add_argument("out_dir", help="output directory of sbsc detect")
    p.add_argument("--scan", nargs="*", default=[], help="scan file(s) of the floor")
    p.add_argument("--models", help="model library directory (class thumbnails)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8080)
    args = p.parse_args(argv)
    backend = InMemoryBackend()
    token = secrets.token_urlsafe(16)
    backend.add_user(token, "reviewer", "reviewer")
    out = Path(args.out_dir)
    backend.add_detection_dir("local", out, scans=[Path(s) for s in args.scan],
                              models_dir=Path(args.models) if args.models else None)
    server = viser.ViserServer(host=args.host, port=args.port, label=f"sbsc · {out.name}")
    scene = ProjectScene(server, backend, "local")
    scene.build()
    print(f"scene ready at http://{args.host}:{server.get_port()}/  (token: {token})", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        scene.close()
        server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
