"""The 3D review scene in headless Chromium: it loads, draws the layers, and shows a selection.

Saves ``docs/images/viewer_scene.png`` (the floor) and ``docs/images/viewer_selected.png``
(an object selected, the review panel filled in).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.slow, pytest.mark.browser]

CHROMIUM = os.environ.get("SBSC_CHROMIUM", "/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run",
        "--use-gl=swiftshader", "--enable-unsafe-swiftshader"]
# Screenshots go to docs/images only when asked (SBSC_SAVE_SCREENSHOTS=1), so a test run
# never changes the work tree; otherwise to a temporary folder.
DOCS = (Path(__file__).resolve().parent.parent / "docs" / "images"
        if os.environ.get("SBSC_SAVE_SCREENSHOTS") == "1"
        else Path(tempfile.gettempdir()) / "sbsc-screenshots")
VIEW = {"width": 1400, "height": 850}
CANVAS_RIGHT = 990  # the review panel covers the right of the page


def _chromium_or_skip():
    if not shutil.which(CHROMIUM) and not Path(CHROMIUM).exists():
        pytest.skip("Debian chromium is not installed")
    return pytest.importorskip("playwright.sync_api")


def _colour_counts(png: bytes) -> dict[str, int]:
    import cv2

    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :CANVAS_RIGHT, ::-1]
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return {"red": int(((r > g + 90) & (r > b + 90)).sum()),
            "cyan": int(((g > r + 50) & (b > r + 50)).sum()),
            "magenta": int(((r > g + 60) & (b > g + 60)).sum()),
            "yellow": int(((r > b + 100) & (g > b + 80)).sum())}


def test_scene_loads_in_chromium(tmp_path):
    pw = _chromium_or_skip()
    from app.viewer.backend import InMemoryBackend
    from app.viewer.manager import ViewerManager
    from app.viewer.synthetic import write_synthetic_project

    sp = write_synthetic_project(tmp_path / "out", rooms=2, objects_per_wall=3, points=40_000)
    backend = InMemoryBackend()
    backend.add_user("tok", "alice", "reviewer")
    backend.add_detection_dir(1, sp.out_dir, scans=[sp.scan], name="Sample: two rooms")
    manager = ViewerManager(backend)
    try:
        url = manager.url_for(1)
        scene = manager.wait_ready(1, 30)
        with pw.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            page = browser.new_page(viewport=VIEW)
            received = []
            page.on("websocket", lambda ws: ws.on("framereceived",
                                                  lambda data: received.append(len(data))))
            t0 = time.monotonic()
            page.goto(url)
            page.get_by_text("objects on 8 walls").wait_for(timeout=30_000)
            ready_s = time.monotonic() - t0
            page.add_style_tag(content=".mantine-Notifications-root{display:none}")
            session = next(iter(scene.sessions.values()))
            t1 = time.monotonic()
            while session.scan_points_sent() == 0 and time.monotonic() - t1 < 20:
                time.sleep(0.1)  # the scan follows the rest of the scene
            counts: dict[str, int] = {}
            for _ in range(20):  # the scene fades in; wait until the layers are drawn
                png = page.screenshot()
                counts = _colour_counts(png)
                if counts["red"] > 30 and counts["cyan"] > 30 and counts["yellow"] > 200:
                    break
                time.sleep(0.5)
            DOCS.mkdir(parents=True, exist_ok=True)
            (DOCS / "viewer_scene.png").write_bytes(png)
            print(f"ready in {ready_s:.2f} s, {sum(received):,} bytes, colours {counts}")
            assert counts["red"] > 30, counts  # the pending spots
            assert counts["cyan"] > 30 and counts["magenta"] > 30, counts  # the RoIs
            assert counts["yellow"] > 200, counts  # the wall outlines
            assert session.scan_points_sent() > 20_000
            assert sum(received) > session.scan_points_sent() * 9  # the scan's points arrived

            session.sign_in("tok")
            did = scene.order[4]
            session.select(did)
            page.get_by_text(f"{did} · {scene.detections[did]['class']}").wait_for(timeout=10_000)
            page.get_by_text("Signed in as").wait_for(timeout=10_000)
            time.sleep(1.5)
            page.screenshot(path=str(DOCS / "viewer_selected.png"))
            browser.close()
    finally:
        manager.stop_all()
