"""The 3D scene's door: the app's login by cookie, no foreign origin, idle scenes stopped."""

from __future__ import annotations

import threading
import time

import httpx
import msgspec
import numpy as np
import pytest
import viser
from viser import _messages as vm
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from app.viewer.backend import InMemoryBackend, Reviewer
from app.viewer.gate import COOKIE, ViewerGate, cookie_name
from app.viewer.geometry import wall_hit
from app.viewer.manager import ViewerManager
from app.viewer.scene import SceneSettings
from app.viewer.synthetic import write_synthetic_project


def test_tickets_are_signed_and_expire():
    g = ViewerGate(ttl_s=60)
    t = g.issue(3, "rita", "reviewer", now=1000.0)
    assert g.verify(t, now=1010.0).name == "rita"
    assert g.verify(t, now=1061.0) is None  # expired
    body, sig = t.rsplit(".", 1)
    assert g.verify(body + "." + "0" * len(sig), now=1010.0) is None  # forged
    assert ViewerGate().verify(t, now=1010.0) is None  # another server's secret
    assert g.ticket_of(f"a=b; {COOKIE}={t}") is None  # (real time: long expired)


@pytest.fixture()
def gated(tmp_path):
    sp = write_synthetic_project(tmp_path / "out", rooms=1, walls_per_room=2, objects_per_wall=2,
                                 points=2000)
    backend = InMemoryBackend()
    backend.add_user("tok", "alice", "reviewer")
    backend.add_detection_dir(1, sp.out_dir, scans=[sp.scan])
    gate = ViewerGate()
    manager = ViewerManager(backend, settings=SceneSettings(poll_s=0.05, scan_delay_s=0.0), gate=gate,
                            idle_s=60.0, idle_check_s=3600)
    try:
        yield manager, gate
    finally:
        manager.stop_all()


def _ws(port: int, origin: str, cookie: str | None):
    headers = {"Cookie": f"{cookie_name(1)}={cookie}"} if cookie else {}
    return connect(f"ws://127.0.0.1:{port}/", origin=origin, additional_headers=headers,
                   subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10)


@pytest.mark.slow
def test_scene_refuses_without_login_or_from_a_foreign_origin(gated):
    manager, gate = gated
    url = manager.url_for(1)
    scene = manager.wait_ready(1, 30)
    port = manager.viewer(1).port
    refused = httpx.get(url)
    assert refused.status_code == 403
    ticket = gate.issue(1, "alice", "reviewer", project=1)
    page = httpx.get(url, cookies={cookie_name(1): ticket})
    assert page.status_code == 200
    for answer in (refused, page):  # the scene's own answers carry the security headers too
        assert "frame-ancestors 'none'" in answer.headers["content-security-policy"]
        assert answer.headers["x-content-type-options"] == "nosniff"
        assert answer.headers["x-frame-options"] == "DENY" and answer.headers["referrer-policy"] == "no-referrer"
    # a ticket of another project (or of none) does not open this scene, under any cookie name
    other, unbound = gate.issue(1, "alice", "reviewer", project=2), gate.issue(1, "alice", "reviewer")
    for name, t in ((cookie_name(1), other), (cookie_name(2), other), (cookie_name(1), unbound),
                    (COOKIE, unbound)):
        assert httpx.get(url, cookies={name: t}).status_code == 403, name
    own = f"http://127.0.0.1:{port}"
    for origin, cookie in ((own, None), ("http://evil.example", ticket), (own, "forged.0000"), (own, other)):
        with pytest.raises(InvalidStatus) as exc:
            _ws(port, origin, cookie)
        assert exc.value.response.status_code == 403
    assert not scene.sessions
    with _ws(port, own, ticket) as ws:
        assert len(ws.recv(timeout=10)) > 0
        ws.send(msgspec.msgpack.encode(vm.ViewerCameraMessage(
            wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, -10.0, 10.0), fov=1.0, near=0.01, far=1000.0,
            image_height=600, image_width=800, look_at=(0.0, 0.0, 0.0),
            up_direction=(0.0, 0.0, 1.0)).as_serializable_dict()))
        stop = threading.Event()

        def drain() -> None:
            while not stop.is_set():
                try:
                    ws.recv(timeout=0.2)
                except TimeoutError:
                    continue
                except Exception:
                    return

        reader = threading.Thread(target=drain, daemon=True)
        reader.start()
        deadline = time.monotonic() + 10
        while not scene.sessions and time.monotonic() < deadline:
            time.sleep(0.05)
        session = next(iter(scene.sessions.values()))
        assert session.user is not None and session.user.name == "alice"  # no token pasted
        assert not session.ui_token.visible
        # a reviewer adds a missed object where a ray meets a wall (a shift-click)
        wid, f = next(iter(scene.frames.items()))
        target = f.to_world(f.width_m / 3, 1.1)
        eye = target + f.normal * 1.5
        det = session.add_at_ray(eye - scene.centre, target - eye)
        assert det is not None and det["wall"] == wid and det["source"] == "reviewer"
        assert (det["u"], det["v"]) == pytest.approx((f.width_m / 3, 1.1), abs=1e-3)
        assert det["id"] in scene.spots and det["review"]["by"] == "alice"
        # labels: the selection (the added object), not every object
        assert det["id"] in session.labels and len(session.labels) < len(scene.detections)
        stop.set()
    # idle: once no tab has been on it for idle_s the scene is stopped
    deadline = time.monotonic() + 10
    while scene.sessions and time.monotonic() < deadline:
        time.sleep(0.05)
    assert manager.stop_idle(now=time.monotonic() + 1.0) == []
    assert manager.stop_idle(now=time.monotonic() + 61.0) == [1]
    assert manager.running() == []


@pytest.mark.slow
def test_ray_from_behind_a_wall_misses_it(gated):
    manager, _ = gated
    scene = manager.wait_ready(1, 30)
    wid, f = next(iter(scene.frames.items()))
    target = f.to_world(f.width_m / 2, 1.0)
    assert wall_hit({wid: f}, target + f.normal, -f.normal)[0] == wid
    assert wall_hit({wid: f}, target - f.normal, f.normal) is None
    assert wall_hit({wid: f}, target + f.normal, np.array(f.axis_u)) is None
    assert Reviewer("a", "reviewer").may_decide
