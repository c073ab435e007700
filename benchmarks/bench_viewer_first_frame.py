"""The 3D scene after a job: first frame in headless Chromium, and the memory an idle scene frees.

Imports a finished ``sbsc detect`` output into a fresh data dir, prepares the scene's scan
level of detail as a job does when it ends (``app.jobs._prepare_viewer``), starts
``sbsc serve`` with a short idle time, signs in on the app's page in headless Chromium
(software rendering), opens the 3D view from the project page and measures the time until
the scene's status and its first drawn frame are there. Then closes the tab and measures the
server's resident memory before opening, with the scene open, and after the idle scene was
stopped. Run it under the heavy lock (Scenario I reads ~100 M points to prepare).

    flock /tmp/sbsc-heavy.lock .venv/bin/python benchmarks/bench_viewer_first_frame.py DETECT_OUT SCAN
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from app.config import AppSettings  # noqa: E402
from app.jobs import _prepare_viewer  # noqa: E402
from app.sample import ensure_sample_project  # noqa: E402
from app.users import add_user  # noqa: E402
from tests.test_app_support import ServerProcess  # noqa: E402

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--use-gl=swiftshader",
        "--enable-unsafe-swiftshader"]


def rss_mib(srv: ServerProcess) -> float:
    return srv.rss_kib() / 1024.0


def drawn(png: bytes) -> bool:
    import cv2

    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :900]
    return float(img.std()) > 8.0  # more than a blank canvas


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("detect_out", type=Path)
    ap.add_argument("scan", type=Path)
    ap.add_argument("--idle-s", type=float, default=20.0)
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    res: dict = {}
    with tempfile.TemporaryDirectory(prefix="sbsc-viewer-") as tmp:
        data = Path(tmp) / "data"
        settings = AppSettings(data_dir=data)
        pid = ensure_sample_project(args.scan, args.detect_out, settings=settings, name="first frame",
                                    points=1)
        from sqlalchemy import select

        from app.db import Database
        from app.models import Scan

        db = Database(settings.db_url)
        with db.read() as s:  # the project's own copy of the scan, as a job reads it
            scans = [settings.data_dir / p for p in s.scalars(select(Scan.path).where(Scan.project_id == pid))]
        db.dispose()
        t = time.perf_counter()
        _prepare_viewer(settings, pid, scans, lambda m: print(m, flush=True))
        res["prepare_at_job_end_s"] = round(time.perf_counter() - t, 1)
        token = add_user(settings, "rita", "reviewer")
        srv = ServerProcess(data, {"SBSC_VIEWER_IDLE_S": str(args.idle_s)}).start()
        try:
            time.sleep(2.0)
            res["rss_before_mib"] = round(rss_mib(srv))
            with sync_playwright() as pw:
                b = pw.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
                page = b.new_page(viewport={"width": 1400, "height": 850})
                page.goto(srv.url + "/")
                page.fill("#token", token)
                page.click("#login-form button[type=submit]")
                page.wait_for_selector("#new-name")
                page.goto(f"{srv.url}/project.html?id={pid}")
                page.wait_for_selector("#title:has-text('first frame')")
                t0 = time.perf_counter()
                with page.expect_popup() as pop:
                    page.click("#open-3d")
                scene = pop.value
                scene.get_by_text("objects on").wait_for(timeout=120_000)
                res["status_s"] = round(time.perf_counter() - t0, 2)
                while not drawn(scene.screenshot()) and time.perf_counter() - t0 < 120:
                    time.sleep(0.2)
                res["first_frame_s"] = round(time.perf_counter() - t0, 2)
                scene.get_by_text("Signed in as rita").wait_for(timeout=10_000)
                time.sleep(8.0)  # the scan tiles arrive after the first frame
                res["rss_scene_open_mib"] = round(rss_mib(srv))
                scene.screenshot(path=str(Path(tempfile.gettempdir()) / "sbsc-first-frame.png"))
                scene.close()
                b.close()
            t1 = time.perf_counter()
            while time.perf_counter() - t1 < args.idle_s * 3:
                time.sleep(1.0)
                if "idle for" in srv.log():
                    break
            time.sleep(2.0)
            res["idle_stopped_after_s"] = round(time.perf_counter() - t1, 1)
            res["rss_after_idle_mib"] = round(rss_mib(srv))
            res["freed_mib"] = res["rss_scene_open_mib"] - res["rss_after_idle_mib"]
        finally:
            srv.stop()
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
