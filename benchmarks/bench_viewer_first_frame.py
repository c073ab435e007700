"""The 3D scene after an import: preparing it (time, peak memory), first frame in headless Chromium.

Runs ``sbsc import DETECT_OUT --scan SCAN`` into a fresh data dir as its own process (which
prepares the scene's scan level of detail, reading the scan in chunks, as a job does when it
ends) and samples the resident memory of that process tree every 0.1 s: ``prepare_peak_mib``.
Then starts ``sbsc serve`` with a short idle time, signs in on the app's page in headless
Chromium (software rendering), opens the 3D view from the project page and measures the
time until the scene's status and its first drawn frame are there. Then closes the tab and
measures the server's resident memory before opening, with the scene open, and after the
idle scene was stopped. Run it under the heavy lock (Scenario I reads ~100 M points).

    flock /tmp/sbsc-heavy.lock .venv/bin/python benchmarks/bench_viewer_first_frame.py DETECT_OUT SCAN
    flock /tmp/sbsc-heavy.lock .venv/bin/python benchmarks/bench_viewer_first_frame.py --synthetic 100000000

``--synthetic N`` writes a floor the size of Scenario I (6 rooms, 24 walls, 120 objects,
``app.viewer.synthetic``) whose scan holds N points (written in chunks: a 2 M point floor
repeated with 3 mm of noise), keeps it under ``--keep DIR`` for the next run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from app.config import AppSettings  # noqa: E402
from app.sample import find_sample_project  # noqa: E402
from app.users import add_user  # noqa: E402
from tests.app_support import ServerProcess  # noqa: E402

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--use-gl=swiftshader",
        "--enable-unsafe-swiftshader"]


def rss_mib(srv: ServerProcess) -> float:
    return srv.rss_kib() / 1024.0


def tree_rss_kib(pid: int) -> int:
    """Resident memory of a process and all its descendants (from /proc)."""
    children: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = Path(f"/proc/{d}/stat").read_text()
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            status = Path(f"/proc/{d}/status").read_text()
        except (OSError, ValueError, IndexError):
            continue
        children.setdefault(ppid, []).append(int(d))
        rss[int(d)] = next((int(x.split()[1]) for x in status.splitlines() if x.startswith("VmRSS:")), 0)
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        total += rss.get(p, 0)
        todo.extend(children.get(p, []))
    return total


def run_measured(cmd: list[str], env: dict) -> tuple[int, float, float, str]:
    """Run ``cmd``; returns (exit code, seconds, peak tree RSS in MiB, output)."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    peak = [0]
    done = threading.Event()

    def sample() -> None:
        while not done.wait(0.1):
            peak[0] = max(peak[0], tree_rss_kib(proc.pid))

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    out = proc.communicate()[0]
    done.set()
    th.join()
    return proc.returncode, time.perf_counter() - t, peak[0] / 1024.0, out


def synthetic_floor(where: Path, points: int) -> tuple[Path, Path]:
    """A Scenario-I-size floor (detect output + scan of ``points`` points), kept for reuse."""
    from app.viewer.synthetic import write_synthetic_project
    from sbsc_core.io.scans import iter_scan

    out, big = where / "scenario_like", where / f"scan_{points}.ply"
    if not (out / "detections.json").is_file():
        write_synthetic_project(where / "scenario_like", rooms=6, columns=3, walls_per_room=4,
                                objects_per_wall=5, points=2_000_000, room_size=(7.6, 9.7), height_m=3.0)
    if big.is_file():
        return out, big
    base = where / "scenario_like" / "scan.ply"
    rng = np.random.default_rng(0)
    dtype = [("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    tmp = big.with_suffix(".part")
    with open(tmp, "wb") as fh:
        fh.write((f"ply\nformat binary_little_endian 1.0\nelement vertex {points}\nproperty double x\n"
                  "property double y\nproperty double z\nproperty uchar red\nproperty uchar green\n"
                  "property uchar blue\nend_header\n").encode())
        left = points
        while left:
            for chunk in iter_scan(base):
                k = min(left, len(chunk))
                rec = np.empty(k, dtype)
                xyz = chunk.xyz[:k].astype(np.float64) + chunk.origin + rng.normal(0, 0.003, (k, 3))
                rec["x"], rec["y"], rec["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
                rec["red"], rec["green"], rec["blue"] = chunk.rgb[:k, 0], chunk.rgb[:k, 1], chunk.rgb[:k, 2]
                rec.tofile(fh)
                left -= k
                if not left:
                    break
    os.replace(tmp, big)
    return out, big


def drawn(png: bytes) -> bool:
    import cv2

    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[:, :900]
    return float(img.std()) > 8.0  # more than a blank canvas


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("detect_out", type=Path, nargs="?")
    ap.add_argument("scan", type=Path, nargs="?")
    ap.add_argument("--synthetic", type=int, default=0, metavar="N",
                    help="instead: a Scenario-I-size synthetic floor whose scan has N points")
    ap.add_argument("--keep", type=Path, default=Path(tempfile.gettempdir()) / "sbsc-bench-viewer",
                    help="where the synthetic floor is kept between runs")
    ap.add_argument("--idle-s", type=float, default=20.0)
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    res: dict = {"date": time.strftime("%Y-%m-%d"), "load_avg_start": os.getloadavg()[0]}
    if args.synthetic:
        args.keep.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        args.detect_out, args.scan = synthetic_floor(args.keep, args.synthetic)
        res["synthetic_written_s"] = round(time.perf_counter() - t, 1)
    elif args.detect_out is None or args.scan is None:
        ap.error("give DETECT_OUT SCAN, or --synthetic N")
    with tempfile.TemporaryDirectory(prefix="sbsc-viewer-") as tmp:
        data = Path(tmp) / "data"
        settings = AppSettings(data_dir=data)
        env = {**os.environ, "SBSC_DATA_DIR": str(data), "PYTHONPATH": str(ROOT)}
        code, secs, peak, out = run_measured(
            [sys.executable, "-m", "app", "import", str(args.detect_out), "--scan", str(args.scan),
             "--name", "first frame"], env)
        print(out, flush=True)
        if code != 0:
            raise SystemExit(f"sbsc import failed ({code})")
        res["import_s"], res["prepare_peak_mib"] = round(secs, 1), round(peak)
        res["scan_bytes"] = args.scan.stat().st_size
        pid = find_sample_project(settings, "first frame")
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
