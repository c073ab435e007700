"""Memory of an idle 3D scene: built, looked at by one tab, then stopped by the idle timer.

A synthetic floor (``app.viewer.synthetic``: 4 rooms, 64 objects, 3 M scan points) in a
gated :class:`~app.viewer.manager.ViewerManager` with a 5 s idle time; one websocket tab
signed in with a viewer ticket. Prints the process's resident memory before the scene,
with it open, and after the idle scene was stopped (``release_memory``: gc + malloc_trim).
``--cycles N`` opens and lets the scene go idle N times: what stays after the first stop
and does not grow over the next ones is the process's one-time cost (libraries, caches),
not memory an idle scene keeps.

    .venv/bin/python benchmarks/bench_viewer_idle.py [--cycles 3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import msgspec  # noqa: E402
import viser  # noqa: E402
from viser import _messages as vm  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

from app.viewer.backend import InMemoryBackend  # noqa: E402
from app.viewer.gate import COOKIE, ViewerGate  # noqa: E402
from app.viewer.manager import ViewerManager  # noqa: E402
from app.viewer.scene import SceneSettings  # noqa: E402
from app.viewer.synthetic import write_synthetic_project  # noqa: E402


def rss_mib() -> float:
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
    return 0.0


def one_cycle(m: ViewerManager, gate: ViewerGate) -> tuple[float, float, float]:
    """Open the scene, look at it from one tab, leave it idle until stopped: (build s, open MiB, after MiB)."""
    t = time.perf_counter()
    m.url_for(1)
    m.wait_ready(1, 300)
    build_s = time.perf_counter() - t
    port = m.viewer(1).port
    ws = connect(f"ws://127.0.0.1:{port}/", origin=f"http://127.0.0.1:{port}",
                 additional_headers={"Cookie": f"{COOKIE}={gate.issue(1, 'a', 'reviewer')}"},
                 subprotocols=[f"viser-v{viser.__version__}"], max_size=None)
    ws.send(msgspec.msgpack.encode(vm.ViewerCameraMessage(
        wxyz=(1.0, 0, 0, 0), position=(0.0, -10.0, 10.0), fov=1.0, near=0.01, far=1000.0,
        image_height=600, image_width=800, look_at=(0.0, 0, 0), up_direction=(0.0, 0, 1.0)
    ).as_serializable_dict()))
    t = time.monotonic()
    while time.monotonic() - t < 8:
        try:
            ws.recv(timeout=0.5)
        except TimeoutError:
            pass
    r1 = rss_mib()
    ws.close()
    t = time.monotonic()
    while m.running() and time.monotonic() - t < 60:
        time.sleep(0.5)
    time.sleep(1)
    return build_s, r1, rss_mib()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=1, help="times the scene is opened and left idle")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="sbsc-idle-") as tmp:
        sp = write_synthetic_project(Path(tmp) / "p", rooms=4, walls_per_room=4, objects_per_wall=4,
                                     points=3_000_000)
        backend = InMemoryBackend()
        backend.add_detection_dir(1, sp.out_dir, scans=[sp.scan])
        gate = ViewerGate()
        m = ViewerManager(backend, settings=SceneSettings(scan_delay_s=0.0), gate=gate, idle_s=5,
                          idle_check_s=1)
        time.sleep(1)
        r0 = rss_mib()
        print(f"RSS before any scene {r0:.0f} MiB")
        for k in range(1, args.cycles + 1):
            build_s, r1, r2 = one_cycle(m, gate)
            print(f"cycle {k}: scene built in {build_s:.1f} s; open {r1:.0f} MiB, after the idle stop "
                  f"{r2:.0f} MiB: freed {r1 - r2:.0f} of the scene's {r1 - r0:.0f} MiB; "
                  f"{r2 - r0:+.0f} MiB over the start")
        m.stop_all()
    return 0

if __name__ == "__main__":
    sys.exit(main())
