"""The 3D scene after an import and after a job: preparing it (time, peak memory), first frame in headless Chromium.

After an import: runs ``sbsc import DETECT_OUT --scan SCAN`` into a fresh data dir as its
own process (which prepares the scene's scan level of detail, reading the scan in chunks)
and samples the resident memory of that process tree every 0.1 s: ``prepare_peak_mib``.
After a job: starts ``sbsc serve``, makes a project through the REST API, uploads SCAN and
runs a job whose recognition step hands back DETECT_OUT (:func:`replay_detect_output`; the
rest is the app's own: the scene's level of detail prepared when the job ends, the results
imported), sampling the server's process tree (workers included) meanwhile.

Each time a reviewer who is a member of the project (issue 30) signs in on the app's page in
headless Chromium (software rendering), opens the 3D view from the project page, and the
bench measures the time until the scene's status and its first drawn frame are there, and
the websocket bytes by then. Then it closes the tab and measures the server's resident
memory before opening, with the scene open, and after the idle scene was stopped. Run it
under the heavy lock (Scenario I reads ~100 M points).

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


def replay_detect_output(scans, models, *, expected=None, out: Path, settings_file=None,  # noqa: ANN001
                         log=None, progress=None) -> dict:  # noqa: ANN001
    """A job runner (``SBSC_JOB_RUNNER``) that hands back the detect output named by
    ``$SBSC_BENCH_DETECT_OUT`` instead of running recognition again: the job then ends as
    any job does (the scene's level of detail prepared from the uploaded scan, results imported)."""
    import shutil

    src = Path(os.environ["SBSC_BENCH_DETECT_OUT"])
    shutil.copytree(src, out, dirs_exist_ok=True)
    if log:
        log(f"replayed the detect output {src.name}")
    doc = json.loads((Path(out) / "detections.json").read_text())
    return {"detections": len(doc.get("detections", []))}


class TreePeak:
    """The peak resident memory (MiB) of a process tree, sampled every 0.1 s while in a ``with``."""

    def __init__(self, pid: int) -> None:
        self.pid, self.peak_kib = pid, 0
        self._done = threading.Event()
        self._th = threading.Thread(target=self._sample, daemon=True)

    def _sample(self) -> None:
        while not self._done.wait(0.1):
            self.peak_kib = max(self.peak_kib, tree_rss_kib(self.pid))

    def __enter__(self) -> TreePeak:
        self._th.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._done.set()
        self._th.join()

    @property
    def mib(self) -> float:
        return self.peak_kib / 1024.0


def open_scene(srv: ServerProcess, token: str, pid: int, title: str, user: str = "rita") -> dict:
    """Sign in, open the project's 3D view in headless Chromium; seconds to its status and to
    its first drawn frame, then the server's memory with the scene open."""
    from playwright.sync_api import sync_playwright

    res: dict = {"load_avg_open": os.getloadavg()[0]}
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
        page = b.new_page(viewport={"width": 1400, "height": 850})
        page.goto(srv.url + "/")
        page.fill("#token", token)
        page.click("#login-form button[type=submit]")
        page.wait_for_selector("#new-name")
        page.goto(f"{srv.url}/project.html?id={pid}")
        page.wait_for_selector(f"#title:has-text('{title}')")
        t0 = time.perf_counter()
        with page.expect_popup() as pop:
            page.click("#open-3d")
        scene = pop.value
        scene.bring_to_front()  # the tab a click opens is in front (a background tab's frames are throttled)
        drew: list[float] = []  # when the server heard that the tab drew its first frame (its log)
        seen = threading.Event()

        def watch_log() -> None:
            start = len(srv.log_path.read_bytes())
            while not seen.wait(0.1):
                if b"drew its first frame" in srv.log_path.read_bytes()[start:]:
                    drew.append(time.perf_counter() - t0)
                    return

        threading.Thread(target=watch_log, daemon=True).start()
        frames: list[tuple[float, int]] = []
        scene.on("websocket", lambda ws: ws.on(
            "framereceived", lambda data: frames.append((time.perf_counter() - t0, len(data)))))
        scene.get_by_text("objects on").wait_for(timeout=120_000)
        res["status_s"] = round(time.perf_counter() - t0, 2)
        while not drawn(scene.screenshot()) and time.perf_counter() - t0 < 120:
            time.sleep(0.2)
        res["first_frame_s"] = round(time.perf_counter() - t0, 2)
        res["bytes_by_first_frame"] = sum(n for t, n in frames if t <= res["first_frame_s"])
        scene.get_by_text(f"Signed in as {user}").wait_for(timeout=60_000)
        time.sleep(8.0)  # the scan tiles arrive after the first frame
        res["bytes_after_8s"] = sum(n for _, n in frames)
        seen.set()
        # when the tab answered the render request after which its scan is sent (viser's
        # get_render: a frame captured once every earlier message is applied)
        res["tab_answered_s"] = round(drew[0], 2) if drew else None
        res["rss_scene_open_mib"] = round(rss_mib(srv))
        scene.screenshot(path=str(Path(tempfile.gettempdir()) / f"sbsc-first-frame-{pid}.png"))
        scene.close()
        b.close()
    return res


def idle_release(srv: ServerProcess, idle_s: float, res: dict) -> None:
    """Wait until the idle scene is stopped; the server's memory after it."""
    t1 = time.perf_counter()
    start = srv.log_path.stat().st_size
    while time.perf_counter() - t1 < idle_s * 3:
        time.sleep(1.0)
        if b"idle for" in srv.log_path.read_bytes()[start:]:
            break
    time.sleep(2.0)
    res["idle_stopped_after_s"] = round(time.perf_counter() - t1, 1)
    res["rss_after_idle_mib"] = round(rss_mib(srv))
    res["freed_mib"] = res["rss_scene_open_mib"] - res["rss_after_idle_mib"]



def scene_figures(srv: ServerProcess, token: str, pid: int, title: str, idle_s: float, user: str = "rita") -> dict:
    """The server's memory before the scene opens, the scene's first frame (:func:`open_scene`)
    and the memory after its idle stop (:func:`idle_release`)."""
    res = {"rss_before_mib": round(rss_mib(srv))}
    res.update(open_scene(srv, token, pid, title, user))
    idle_release(srv, idle_s, res)
    return res


def reviewer_member(settings: AppSettings, env: dict, name: str, pid: int) -> str:
    """A reviewer ``name`` made a member of project ``pid`` as an admin does (``sbsc user
    add-member``; an imported project has only the admins as members); their token."""
    token = add_user(settings, name, "reviewer")
    subprocess.run([sys.executable, "-m", "app", "user", "add-member", name, str(pid), "--role", "reviewer"],
                   env=env, check=True)
    return token

def after_import(detect_out: Path, scan: Path, tmp: Path, idle_s: float) -> dict:
    """``sbsc import`` (its process tree's peak while preparing), then the first frame."""
    data = tmp / "import"
    settings = AppSettings(data_dir=data)
    env = {**os.environ, "SBSC_DATA_DIR": str(data), "PYTHONPATH": str(ROOT)}
    code, secs, peak, out = run_measured(
        [sys.executable, "-m", "app", "import", str(detect_out), "--scan", str(scan),
         "--name", "first frame"], env)
    print(out, flush=True)
    if code != 0:
        raise SystemExit(f"sbsc import failed ({code})")
    res: dict = {"import_s": round(secs, 1), "prepare_peak_mib": round(peak)}
    pid = find_sample_project(settings, "first frame")
    token = reviewer_member(settings, env, "rita", pid)
    srv = ServerProcess(data, {"SBSC_VIEWER_IDLE_S": str(idle_s)}).start()
    try:
        time.sleep(2.0)
        res.update(scene_figures(srv, token, pid, "first frame", idle_s))
    finally:
        srv.stop()
    return res


def after_job(detect_out: Path, scan: Path, tmp: Path, idle_s: float) -> dict:
    """A project made in the app: the scan uploaded, a job run (recognition replayed from
    ``detect_out``, the rest as any job: scene prepared, results imported) while the server's
    process tree is sampled; then the first frame."""
    import httpx

    data = tmp / "job"
    settings = AppSettings(data_dir=data)
    manager = add_user(settings, "mia", "manager")
    token = add_user(settings, "rita", "reviewer")
    srv = ServerProcess(data, {"SBSC_VIEWER_IDLE_S": str(idle_s),
                               "SBSC_JOB_RUNNER": "benchmarks.bench_viewer_first_frame:replay_detect_output",
                               "SBSC_BENCH_DETECT_OUT": str(detect_out)}).start()
    res: dict = {}
    try:
        h = {"Authorization": f"Bearer {manager}"}
        with httpx.Client(base_url=srv.url, timeout=900.0) as c:
            pid = c.post("/api/projects", json={"name": "after a job"}, headers=h).raise_for_status().json()["id"]
            c.post(f"/api/projects/{pid}/members", json={"user": "rita", "role": "reviewer"},
                   headers=h).raise_for_status()
            t = time.perf_counter()
            with open(scan, "rb") as fh:
                c.post(f"/api/projects/{pid}/scans", files={"file": (scan.name, fh)},
                       headers=h).raise_for_status()
            res["upload_s"] = round(time.perf_counter() - t, 1)
            time.sleep(2.0)
            t = time.perf_counter()
            with TreePeak(srv.proc.pid) as peak:
                jid = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h).raise_for_status().json()["id"]
                while (job := c.get(f"/api/jobs/{jid}", headers=h).json())["status"] not in \
                        ("succeeded", "failed", "cancelled"):
                    time.sleep(0.5)
            if job["status"] != "succeeded":
                raise SystemExit(f"job failed: {job}")
            res["job_s"], res["prepare_peak_mib"] = round(time.perf_counter() - t, 1), round(peak.mib)
        res.update(scene_figures(srv, token, pid, "after a job", idle_s))
    finally:
        srv.stop()
    return res


def open_only(data: Path, tmp: Path, idle_s: float) -> dict:
    """The first frame of the project "first frame" that an earlier ``sbsc import`` made in
    ``data`` (its scene prepared): nothing read or prepared again (``--open-only DATA``)."""
    del tmp
    settings = AppSettings(data_dir=data)
    pid = find_sample_project(settings, "first frame")
    if pid is None:
        raise SystemExit(f"{data}: no project 'first frame' (sbsc import ... --name 'first frame' makes it)")
    name = f"rita{int(time.time())}"
    token = reviewer_member(settings, {**os.environ, "SBSC_DATA_DIR": str(data), "PYTHONPATH": str(ROOT)}, name, pid)
    srv = ServerProcess(data, {"SBSC_VIEWER_IDLE_S": str(idle_s)}).start()
    try:
        time.sleep(2.0)
        return scene_figures(srv, token, pid, "first frame", idle_s, name)
    finally:
        srv.stop()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("detect_out", type=Path, nargs="?")
    ap.add_argument("scan", type=Path, nargs="?")
    ap.add_argument("--synthetic", type=int, default=0, metavar="N",
                    help="instead: a Scenario-I-size synthetic floor whose scan has N points")
    ap.add_argument("--keep", type=Path, default=Path(tempfile.gettempdir()) / "sbsc-bench-viewer",
                    help="where the synthetic floor is kept between runs")
    ap.add_argument("--idle-s", type=float, default=20.0)
    ap.add_argument("--only", choices=("import", "job"), help="measure one way only (default: both)")
    ap.add_argument("--open-only", type=Path, metavar="DATA",
                    help="only open the scene of project 'first frame' in this data dir (made by an earlier import)")
    args = ap.parse_args()
    if args.open_only:
        res = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_avg_start": os.getloadavg()[0],
               "open_only": open_only(args.open_only.resolve(), Path(tempfile.gettempdir()), args.idle_s),
               "load_avg_end": os.getloadavg()[0]}
        print(json.dumps(res, indent=1))
        return 0
    res: dict = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_avg_start": os.getloadavg()[0]}
    if args.synthetic:
        args.keep.mkdir(parents=True, exist_ok=True)
        t = time.perf_counter()
        args.detect_out, args.scan = synthetic_floor(args.keep, args.synthetic)
        res["synthetic_written_s"] = round(time.perf_counter() - t, 1)
    elif args.detect_out is None or args.scan is None:
        ap.error("give DETECT_OUT SCAN, or --synthetic N")
    res["scan_bytes"] = args.scan.stat().st_size
    with tempfile.TemporaryDirectory(prefix="sbsc-viewer-") as tmp:
        for way, run in (("import", after_import), ("job", after_job)):
            if args.only in (None, way):
                res[f"after_{way}"] = run(args.detect_out.resolve(), args.scan.resolve(), Path(tmp), args.idle_s)
                print(json.dumps({way: res[f"after_{way}"]}), flush=True)
    res["load_avg_end"] = os.getloadavg()[0]
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
