"""Time a project's 3D scene in headless Chromium: seconds to ready, bytes sent.

    python -m app.viewer.bench [--out-dir DIR --scan SCAN ...] [--points N] [--runs 3]

Without ``--out-dir`` a synthetic floor the size of the paper's Scenario I is written
(22.8 m x 19.4 m, 6 rooms, 24 walls, 120 objects, ``--points`` scan points). The scene is
built first (scan level of detail cached), then each run opens a fresh browser page and
measures: ``ready`` (the scene's status, created after every other shared node, is on
screen), ``drawn`` (the red spots are in a screenshot), ``scan_in`` (the tab has received the
scan, which is sent after the rest) and the bytes the page received over the websocket. Needs Debian chromium and the ``playwright`` package (never ``playwright install``).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from .backend import InMemoryBackend
from .manager import ViewerManager
from .scene import SceneSettings
from .synthetic import write_synthetic_project

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--use-gl=swiftshader", "--enable-unsafe-swiftshader"]


def _red_pixels(png: bytes, right: int) -> int:
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :right].astype(int)
    b, g, r = img[..., 0], img[..., 1], img[..., 2]
    return int(((r > g + 90) & (r > b + 90)).sum())


def measure(url: str, chromium: str, runs: int, marker: str, expect_bytes: int = 0) -> list[dict]:
    from playwright.sync_api import sync_playwright

    out = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        for _ in range(runs):
            page = browser.new_page(viewport={"width": 1400, "height": 850})
            frames: list[tuple[float, int]] = []
            t0 = time.monotonic()
            page.on("websocket", lambda ws, frames=frames, t0=t0: ws.on(
                "framereceived", lambda data: frames.append((time.monotonic() - t0, len(data)))))
            page.goto(url)
            page.get_by_text(marker).wait_for(timeout=120_000)
            ready = time.monotonic() - t0
            drawn = None
            while time.monotonic() - t0 < 120:
                try:
                    shot = page.screenshot(timeout=60_000)
                except Exception:  # software rendering can take longer than that per frame
                    break
                if _red_pixels(shot, 990) > 30:
                    drawn = time.monotonic() - t0
                    break
            scan_in = None
            while time.monotonic() - t0 < 180:  # the scan follows: wait until frames stop
                last = max((t for t, _ in frames), default=0.0)
                if sum(n for _, n in frames) >= expect_bytes and time.monotonic() - t0 - last > 1.0:
                    scan_in = last
                    break
                time.sleep(0.2)
            out.append({"ready_s": round(ready, 2), "drawn_s": None if drawn is None else round(drawn, 2),
                        "scan_in_s": None if scan_in is None else round(scan_in, 2),
                        "bytes": sum(n for _, n in frames),
                        "load_avg": float(open("/proc/loadavg").read().split()[0])})
            page.close()
        browser.close()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m app.viewer.bench", description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", help="output directory of sbsc detect (default: synthetic floor)")
    ap.add_argument("--scan", nargs="*", default=[])
    ap.add_argument("--points", type=int, default=2_000_000, help="synthetic scan points")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--overview-points", type=int, default=SceneSettings.overview_points)
    ap.add_argument("--detail", choices=("overview", "full", "off"), default="overview")
    args = ap.parse_args(argv)
    if args.out_dir:
        out, scans = Path(args.out_dir), [Path(s) for s in args.scan]
    else:
        tmp = Path(tempfile.mkdtemp(prefix="sbsc_viewer_bench_"))
        t = time.perf_counter()
        sp = write_synthetic_project(tmp / "scenario_like", rooms=6, columns=3, walls_per_room=4,
                                     objects_per_wall=5, points=args.points,
                                     room_size=(7.6, 9.7), height_m=3.0)
        print(f"synthetic floor written in {time.perf_counter() - t:.1f} s: {sp.out_dir}")
        out, scans = sp.out_dir, [sp.scan]
    backend = InMemoryBackend()
    data = backend.add_detection_dir(1, out, scans=scans)
    settings = SceneSettings(overview_points=args.overview_points, scan_detail=args.detail)
    manager = ViewerManager(backend, settings=settings)
    try:
        t = time.perf_counter()
        manager.url_for(1)
        scene = manager.wait_ready(1, 600)
        build_s = time.perf_counter() - t
        n_walls, n_dets = len(scene.frames), len(scene.detections)
        t = time.perf_counter()
        scene.rebuild()  # a second build reads the level of detail from its cache
        rebuild_s = time.perf_counter() - t
        marker = f"{n_dets} objects on {n_walls} walls"
        points = sum(len(t.points) for t in scene.scan_tiles.get(f"scan_{args.detail}", []))
        runs = measure(manager.url_for(1), args.chromium, args.runs, marker, points * 9)
        report = {"walls": n_walls, "detections": n_dets, "scan_points": scene.lod.source_points
                  if scene.lod else 0, "lod_points": len(scene.lod) if scene.lod else 0,
                  "points_per_tab": points,
                  "detail": args.detail,
                  "first_build_s": round(build_s, 2), "cached_build_s": round(rebuild_s, 2),
                  "runs": runs, "data": str(data.cache_dir)}
        print(json.dumps(report, indent=1))
    finally:
        manager.stop_all()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
