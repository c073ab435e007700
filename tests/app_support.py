"""Helpers of the review-app tests (no tests here): a real server process, inputs, fake runners.

The fake runners have the signature of ``sbsc_core.pipeline.detect.detect_to_dir`` and write a
complete, valid output directory (contract 4 document, orthoimages), so the app can be
tested without depending on recognition quality; the end-to-end test uses the real one.
They are selected with ``SBSC_JOB_RUNNER=tests.app_support:NAME``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import httpx
import numpy as np

from sbsc_core.errors import InputError
from sbsc_core.io.atomic import atomic_output_dir
from sbsc_core.io.ply import write_ply
from sbsc_core.paths import sample_projects_dir

ROOT = Path(__file__).resolve().parent.parent
PIXEL_M = 0.005
FAKE_CLASSES = ("socket_x1", "switch", "socket_x2", "fire_alarm_switch")
FAKE_SIZES = {"socket_x1": (0.08, 0.08), "switch": (0.08, 0.08), "socket_x2": (0.15, 0.08),
              "fire_alarm_switch": (0.10, 0.10)}
COLOURS = {"socket_x1": (240, 240, 235), "switch": (30, 30, 30), "socket_x2": (200, 60, 60),
           "fire_alarm_switch": (220, 30, 30)}


# --------------------------------------------------------------------------- fake runners


def _fake_output(out: Path, n: int, progress: Callable[[str, float], None], delay_s: float) -> dict:
    walls = [("W01", [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 4.0, 2.5),
             ("W02", [4.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], 3.0, 2.5)]
    rng = np.random.default_rng(0)
    dets = []
    per_wall: dict[str, list] = {w[0]: [] for w in walls}
    for i in range(n):
        wid, origin, au, _, wm, hm = walls[i % 2]
        cls = FAKE_CLASSES[i % len(FAKE_CLASSES)]
        w, h = FAKE_SIZES[cls]
        u = 0.3 + (i // 2) * 0.35 % (wm - 0.6)
        v = 0.3 + 0.8 * (i % 3)
        pos = [round(origin[k] + u * au[k] + v * (1.0 if k == 2 else 0.0), 5) for k in range(3)]
        d = {"id": f"D{i + 1:04d}", "class": cls, "wall": wid, "position": pos, "u": round(u, 4),
             "v": round(v, 4), "width_m": w, "height_m": h, "alpha": round(float(rng.uniform(0.5, 1)), 3),
             "rho_depth": 0.8, "rho_colour": 0.1, "source": "both"}
        dets.append(d)
        per_wall[wid].append(d)
    steps = ["reading", "segmentation", "walls", "walls", "consensus", "writing"]
    for k, stage in enumerate(steps):
        progress(stage, 0.5 if stage == "walls" and k == 3 else 0.0)
        time.sleep(delay_s / len(steps))
    with atomic_output_dir(out) as tmp:
        (tmp / "orthoimages").mkdir()
        for wid, _, _, _, wm, hm in walls:
            H, W = int(round(hm / PIXEL_M)), int(round(wm / PIXEL_M))
            colour = np.empty((H, W, 3), np.uint8)
            colour[...] = (205, 200, 185)
            depth = np.zeros((H, W), np.float32)
            depth[:, :8] = np.nan
            for d in per_wall[wid]:
                c0 = int((d["u"] - d["width_m"] / 2) / PIXEL_M)
                c1 = int((d["u"] + d["width_m"] / 2) / PIXEL_M)
                r0 = int((hm - d["v"] - d["height_m"] / 2) / PIXEL_M)
                r1 = int((hm - d["v"] + d["height_m"] / 2) / PIXEL_M)
                colour[r0:r1, c0:c1] = COLOURS[d["class"]]
                depth[r0:r1, c0:c1] = 0.012
            cv2.imwrite(str(tmp / "orthoimages" / f"{wid}_colour.png"), colour[:, :, ::-1])
            np.save(tmp / "orthoimages" / f"{wid}_depth.npy", depth)
            vis = np.where(np.isfinite(depth), 128 - np.nan_to_num(depth) * 1270, 255).astype(np.uint8)
            cv2.imwrite(str(tmp / "orthoimages" / f"{wid}_depth.png"), vis)
            cv2.imwrite(str(tmp / "orthoimages" / f"{wid}_overlay.png"), colour[:, :, ::-1])
        doc = {"schema": "sbsc.detections/1", "pixel_m": PIXEL_M,
               "walls": [{"id": wid, "origin": o, "axis_u": au, "axis_v": [0.0, 0.0, 1.0], "normal": nn,
                          "width_m": wm, "height_m": hm} for wid, o, au, nn, wm, hm in walls],
               "openings": [{"wall": "W01", "kind": "door", "u_min": 3.0, "u_max": 3.9,
                             "v_min": 0.0, "v_max": 2.05}],
               "detections": dets}
        (tmp / "detections.json").write_text(json.dumps(doc, indent=1))
        (tmp / "rois.json").write_text(json.dumps({"schema": "sbsc.rois/1", "pixel_m": PIXEL_M,
                                                   "walls": {}}))
    progress("done", 1.0)
    return {"detections": n}


def served_fake_sample(tmp_path: Path, points: int, **sample) -> dict:
    """The detections document the app serves for a sample project made from a fake 4-wall
    detect output (``tmp_path/out``) and a small scan of ``points`` points."""
    from app.config import AppSettings
    from app.db import Database
    from app.models import Project
    from app.results import project_document
    from app.sample import ensure_sample_project

    settings = AppSettings(data_dir=tmp_path / "data", viewer=False)
    _fake_output(tmp_path / "out", 4, lambda stage, f: None, 0.0)
    pid = ensure_sample_project(write_small_ply(tmp_path / "scan.ply", n=points), tmp_path / "out",
                                settings=settings, points=points, **sample)
    db = Database(settings.db_url)
    try:
        with db.read() as s:
            return project_document(s, s.get(Project, pid))
    finally:
        db.dispose()


def fake_control(data_dir: Path, **control) -> None:
    """Tell the fake runner of a server with this data dir how to behave for the next jobs."""
    (data_dir / "fake_control.json").write_text(json.dumps(control))


def fake_detect_to_dir(scans: Sequence[Path], models: Path, *, expected=None, out: Path,  # noqa: ANN001
                       settings_file=None, log=None, progress=None) -> dict:  # noqa: ANN001
    """A stand-in for ``detect_to_dir``, steered by ``$SBSC_DATA_DIR/fake_control.json``.

    ``{"mode": "ok" | "fail", "delay_s": 0.3, "detections": 6}``: "fail" raises InputError
    like the library on bad input; "ok" writes ``detections`` objects after ``delay_s``.
    """
    control = {"mode": "ok", "delay_s": 0.3, "detections": 6}
    path = Path(os.environ.get("SBSC_DATA_DIR", ".")) / "fake_control.json"
    if path.is_file():
        control.update(json.loads(path.read_text()))
    progress = progress or (lambda s, f: None)
    for p in scans:
        if not Path(p).is_file():
            raise InputError(p, "no such file")
    if control["mode"] == "fail":
        progress("reading", 0.0)
        raise InputError("scan.ply", "no walls found (fake runner)")
    if log:
        log(f"fake runner: {control}")
    return _fake_output(Path(out), int(control["detections"]), progress, float(control["delay_s"]))


# --------------------------------------------------------------------------- inputs


def write_small_ply(path: Path, n: int = 2000, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    write_ply(path, rng.uniform(0, 3, (n, 3)).astype(np.float32), rng.integers(0, 255, (n, 3), dtype=np.uint8))
    return path


def write_library_zip(path: Path, classes: Sequence[str] = ("socket_x1", "switch"),
                      extra: dict[str, bytes] | None = None) -> Path:
    """A valid zipped model library (contract 2) with plain coloured front views."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for cls in classes:
            w, h = FAKE_SIZES.get(cls, (0.1, 0.1))
            zf.writestr(f"models/{cls}/model.json", json.dumps(
                {"name": cls, "ifc_class": "IfcOutlet", "predefined_type": "POWEROUTLET",
                 "width_m": w, "height_m": h}))
            img = np.full((32, 32, 3), COLOURS.get(cls, (100, 100, 100)), np.uint8)
            img[8:24, 8:24] = 255 - img[8:24, 8:24]
            ok, buf = cv2.imencode(".png", img)
            zf.writestr(f"models/{cls}/colour.png", buf.tobytes())
        for name, data in (extra or {}).items():
            zf.writestr(name, data)
    return path


# --------------------------------------------------------------------------- simulated scans


def simulate_boxes(scene_file: Path, out: Path, step_deg: float = 0.3) -> None:
    """The scene with every object as a plain coloured box, and a library to match.

    A stand-in used only while the simulator's object models (``sbsc_core.simulate.objects``
    and ``.library``) are not there: the same room, scanner and pipeline, simpler objects.
    """
    from sbsc_core.io.ply import write_ply
    from sbsc_core.simulate import mesh as M
    from sbsc_core.simulate.building import build_building
    from sbsc_core.simulate.catalogue import CATALOGUE
    from sbsc_core.simulate.scanner import scan_mesh
    from sbsc_core.simulate.scene import load_scene

    rng = np.random.default_rng(3)
    colours = {c: tuple(int(x) for x in rng.integers(20, 235, 3)) for c in CATALOGUE}
    scene = load_scene(scene_file)
    scene.scanner = scene.scanner.replace(angular_step_deg=step_deg)
    building = build_building(scene, lambda c: M.box(
        (CATALOGUE[c].width_m, CATALOGUE[c].height_m, CATALOGUE[c].depth_m), colours[c],
        centre=(0, 0, CATALOGUE[c].depth_m / 2)))
    scan = scan_mesh(building.mesh, building.stations, scene.scanner, seed=0)
    out.mkdir(parents=True)
    write_ply(out / "scan.ply", scan.xyz, scan.rgb)
    (out / "expected.json").write_text(json.dumps(building.expected_document()))
    for cls, spec in CATALOGUE.items():
        d = out / "models" / cls
        d.mkdir(parents=True)
        (d / "model.json").write_text(json.dumps({
            "name": spec.name, "ifc_class": spec.ifc_class, "predefined_type": spec.predefined_type,
            "width_m": spec.width_m, "height_m": spec.height_m}))
        h, w = max(4, round(spec.height_m / 0.005)), max(4, round(spec.width_m / 0.005))
        cv2.imwrite(str(d / "colour.png"), np.full((h, w, 3), colours[cls][::-1], np.uint8))
        np.save(d / "depth.npy", np.full((h, w), spec.depth_m, np.float32))


def simulate_one_room(out: Path, step_deg: float = 0.3) -> Path:
    """the bundled ``one_room.yaml`` scanned: the simulator's, or plain boxes while it is incomplete."""
    scene = sample_projects_dir() / "one_room.yaml"
    try:
        from sbsc_core.simulate.scenarios import simulate_scene

        simulate_scene(scene, out, seed=0, angular_step_deg=step_deg)
    except ImportError as exc:
        print(f"\nsimulator incomplete ({exc}): objects simulated as plain boxes")
        shutil.rmtree(out, ignore_errors=True)
        simulate_boxes(scene, out, step_deg)
    return out


# --------------------------------------------------------------------------- server process


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def server_with_users(base: Path, users: Sequence[tuple[str, str]], env: dict[str, str] | None = None
                      ) -> ServerProcess:
    """A started server on ``base/data`` with each (name, role) of ``users`` added first.

    The server carries ``tokens`` (name -> API token), ``base`` and ``data``; the caller
    stops it.
    """
    from app.config import AppSettings
    from app.users import add_user

    data = base / "data"
    settings = AppSettings(data_dir=data)
    tokens = {name: add_user(settings, name, role) for name, role in users}
    server = ServerProcess(data, env).start()
    server.tokens, server.base, server.data = tokens, base, data
    return server


class ServerProcess:
    """``sbsc serve`` in a child process on a free port, with ``SBSC_*`` settings in its env."""

    def __init__(self, data_dir: Path, env: dict[str, str] | None = None) -> None:
        self.data_dir = data_dir
        self.env = {**os.environ, "SBSC_DATA_DIR": str(data_dir), "PYTHONUNBUFFERED": "1",
                    **(env or {})}
        self.env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
        self.proc: subprocess.Popen | None = None
        self.port = 0
        self.log_path = data_dir.parent / f"server-{data_dir.name}.log"

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout_s: float = 90.0) -> ServerProcess:
        """Start on port 0 (uvicorn binds a free port, no race with other servers) and wait."""
        self.data_dir.mkdir(parents=True, exist_ok=True)
        offset = self.log_path.stat().st_size if self.log_path.exists() else 0
        logf = open(self.log_path, "ab")  # noqa: SIM115 - the child holds it
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "app", "serve", "--host", "127.0.0.1", "--port", "0"],
            env=self.env, stdout=logf, stderr=subprocess.STDOUT, cwd=str(ROOT))
        logf.close()
        deadline = time.monotonic() + timeout_s
        self.port = 0
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited early:\n{self.log()}")
            if not self.port:
                with open(self.log_path, "rb") as fh:
                    fh.seek(offset)
                    m = re.search(rb"Uvicorn running on http://127\.0\.0\.1:(\d+)", fh.read())
                self.port = int(m.group(1)) if m else 0
            if self.port:
                try:
                    if httpx.get(self.url + "/api/health", timeout=2).status_code == 200:
                        return self
                except httpx.HTTPError:
                    pass
            time.sleep(0.2)
        raise RuntimeError(f"server did not come up:\n{self.log()}")

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")[-5000:] if self.log_path.exists() else ""

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = 20.0) -> int | None:
        if self.proc is None or self.proc.poll() is not None:
            return None if self.proc is None else self.proc.returncode
        self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(timeout_s)

    def rss_kib(self) -> int:
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        return 0


def join(settings, pid: int, name: str, role: str) -> None:  # noqa: ANN001
    """Make user ``name`` a member of project ``pid`` (projects belong to their members)."""
    from app.db import Database
    from app.membership import set_member

    db = Database(settings.db_url)
    try:
        with db.write() as s:
            set_member(s, pid, name, role, None)
    finally:
        db.dispose()


def auth(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def wait_job(client: httpx.Client, jid: int, token: str, timeout_s: float = 60.0,
             until: Sequence[str] = ("succeeded", "failed")) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        job = client.get(f"/api/jobs/{jid}", headers=auth(token)).json()
        if job["status"] in until:
            return job
        if time.monotonic() > deadline:
            raise TimeoutError(f"job {jid} still {job}")
        time.sleep(0.2)


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is dead for our purpose
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except (FileNotFoundError, ProcessLookupError):  # gone while /proc was read (ESRCH)
        return False


def worker_pid(data: Path, jid: int) -> int | None:
    """The process id of a job's worker, from the database (the API does not show it)."""
    return db_rows_at(data, f"SELECT worker_pid FROM jobs WHERE id = {int(jid)}")[0][0]


def db_rows_at(data: Path, sql: str) -> list:
    with sqlite3.connect(data / "sbsc.db") as con:
        return con.execute(sql).fetchall()


def fake_with_suggestions(scans: Sequence[Path], models: Path, *, expected=None, out: Path,  # noqa: ANN001
                          settings_file=None, log=None, progress=None) -> dict:  # noqa: ANN001
    """The fake runner of ``app_support`` plus a ``suggestions.json`` of two possible misses."""
    control = {"delay_s": 0.2, "detections": 6}
    path = Path(os.environ.get("SBSC_DATA_DIR", ".")) / "fake_control.json"
    if path.is_file():
        control.update(json.loads(path.read_text()))
    summary = _fake_output(Path(out), int(control["detections"]), progress or (lambda s, f: None),
                           float(control["delay_s"]))
    sugg = [{"class": "switch", "wall": "W01", "u": 3.5, "v": 1.1, "width_m": 0.08, "height_m": 0.08,
             "source": "depth", "score": 0.81, "reason": "not_kept_by_consensus"},
            {"class": "socket_x1", "wall": "W02", "u": 2.5, "v": 0.4, "width_m": 0.08, "height_m": 0.08,
             "source": "colour", "score": 0.2, "reason": "not_kept_by_consensus"}]
    (Path(out) / "suggestions.json").write_text(json.dumps({"schema": "sbsc.suggestions/1",
                                                            "suggestions": sugg}))
    return summary


def project_with_job(c: httpx.Client, srv, name: str) -> int:  # noqa: ANN001
    """A project of rita's (max its manager; ``srv.tokens`` of rita, max and ada) with one
    finished job of the server's runner."""
    h = auth(srv.tokens["rita"])
    pid = c.post("/api/projects", json={"name": name}, headers=h).json()["id"]
    assert c.post(f"/api/projects/{pid}/members", json={"user": "max", "role": "manager"},
                  headers=auth(srv.tokens["ada"])).status_code == 201
    ply = write_small_ply(srv.base / f"{name}.ply")
    with open(ply, "rb") as fh:
        assert c.post(f"/api/projects/{pid}/scans", files={"file": (ply.name, fh)}, headers=h).status_code == 201
    r = c.post(f"/api/projects/{pid}/jobs", json={}, headers=h)
    assert r.status_code == 202, r.text
    assert wait_job(c, r.json()["id"], srv.tokens["rita"])["status"] == "succeeded"
    return pid
