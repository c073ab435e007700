"""Helpers of the 3D viewer tests: fast scene settings, a fake browser tab, waiting for a condition."""

from __future__ import annotations

import threading
import time

import cv2
import msgspec
import numpy as np
import viser
import zstandard
from viser import _messages as vm
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from app.viewer.scene import SceneSettings

FAST = SceneSettings(poll_s=0.05, fly_s=0.02, fly_steps=2, scan_delay_s=0.2, overview_points=3000)


def wait_for(cond, timeout: float = 5.0, what: str = "condition"):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        v = cond()
        if v:
            return v
        time.sleep(0.01)
    raise AssertionError(f"timed out waiting for {what}")


class FakeTab:
    """A browser tab as viser's server sees it: one websocket speaking viser's messages."""

    def __init__(self, port: int) -> None:
        self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"],
                          max_size=None)
        self.received: list[tuple[float, dict]] = []
        self._dctx = zstandard.ZstdDecompressor()
        self.frame = cv2.imencode(".jpg", np.full((8, 8, 3), 255, np.uint8))[1].tobytes()
        self._stop = False
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.send(vm.ViewerCameraMessage(
            wxyz=(1.0, 0.0, 0.0, 0.0), position=(0.0, -10.0, 10.0), fov=1.0, near=0.01,
            far=1000.0, image_height=600, image_width=800, look_at=(0.0, 0.0, 0.0),
            up_direction=(0.0, 0.0, 1.0)))

    def _read(self) -> None:
        while not self._stop:
            try:
                raw = self.ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:
                return
            n = int.from_bytes(raw[8:16], "little")
            inner = msgspec.msgpack.decode(self._dctx.decompress(raw[16:16 + n]))
            for m in inner["messages"]:
                self.received.append((time.monotonic(), m))
                if m.get("type") == "GetRenderRequestMessage" and self.frame is not None:  # a browser answers
                    try:
                        self.send(vm.GetRenderResponseMessage(payload=self.frame, render_uuid=m["render_uuid"]))
                    except ConnectionClosed:  # the server closed the scene meanwhile (the test's end)
                        return

    def send(self, message: vm.Message) -> None:
        self.ws.send(msgspec.msgpack.encode(message.as_serializable_dict()))

    def click_node(self, name: str) -> None:
        self.send(vm.SceneNodeClickMessage(name=name, instance_index=None, ray_origin=(0, 0, 0),
                                           ray_direction=(0, 0, 1), screen_pos=(0.5, 0.5),
                                           modifier=None))

    def set_gui(self, handle, value) -> None:
        self.send(vm.GuiUpdateMessage(uuid=handle._impl.uuid, updates={"value": value}))

    def press(self, button) -> None:
        self.set_gui(button, True)

    def close(self) -> None:
        self._stop = True
        self.ws.close()
