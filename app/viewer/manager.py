"""One viser server per project, started when first asked for, each on its own free port.

A viser server shows one scene to every browser that connects, so projects get separate
servers: a tab on project 7 never sees, nor disturbs, a tab on project 8. The scene is built
in a background thread, so asking for a project's address answers at once; the browser
shows "Loading the scene…" until the scan and the walls are there.
"""

from __future__ import annotations

import ctypes
import gc
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import viser

from .backend import ProjectId, ReviewBackend, Reviewer
from .gate import ViewerGate, connection_of
from .scene import ProjectScene, SceneSettings

log = logging.getLogger(__name__)
WILDCARD_HOSTS = ("", "0.0.0.0", "::", "[::]")
LOOPBACK_HOSTS = ("127.0.0.1", "::1", "[::1]", "localhost")


@dataclass
class _Viewer:
    server: viser.ViserServer
    scene: ProjectScene
    thread: threading.Thread
    port: int = 0
    error: list[BaseException] = field(default_factory=list)


class ViewerManager:
    """Starts, finds and stops the per-project 3D review scenes.

    ``host`` is the address the viser servers listen on (the app's host setting);
    ``public_host`` the host name put in the addresses handed to browsers (default: ``host``,
    or the host the browser used to reach the REST API when ``host`` is a wildcard).
    """

    def __init__(self, backend: ReviewBackend, host: str = "127.0.0.1",
                 public_host: str | None = None, settings: SceneSettings | None = None,
                 verbose: bool = False, gate: ViewerGate | None = None,
                 idle_s: float = 0.0, idle_check_s: float = 30.0) -> None:
        self.backend = backend
        self.host = host
        self.public_host = public_host
        self.settings = settings or SceneSettings()
        self.verbose = verbose
        self.gate = gate
        self.idle_s = idle_s  # 0: scenes stay until the server stops
        self.idle_check_s = idle_check_s
        self._viewers: dict[ProjectId, _Viewer] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._reaper: threading.Thread | None = None

    def viewer(self, pid: ProjectId) -> _Viewer:
        """The project's running viewer, started (and its scene build begun) if needed.

        Raises the backend's ``NotFound`` for an unknown project, before starting anything.
        """
        with self._lock:
            v = self._viewers.get(pid)
            if v is not None and v.error and not v.thread.is_alive():
                self._viewers.pop(pid)  # the last build failed: try again
                v.scene.close()
                v.server.stop()
                v = None
            if v is not None:
                return v
            # NotFound / NotReady before anything is started
            cursor = self.backend.changes_since(pid, None).cursor
            data = self.backend.project_data(pid)
            kw = {"host": self.host, "port": 0, "label": f"sbsc · project {pid}",
                  "verbose": self.verbose}
            server = self.gate.server(project=_ticket_project(pid), **kw) if self.gate is not None \
                else viser.ViserServer(**kw)
            scene = ProjectScene(server, self.backend, pid, self.settings)
            if self.gate is not None:
                scene.identify = lambda client, server=server: self._identify(server, client)
            v = _Viewer(server, scene, threading.Thread(), port=server.get_port())

            def build() -> None:
                try:
                    scene.build(data, cursor)
                except BaseException as exc:  # kept for wait_ready(); shown in the scene
                    v.error.append(exc)

            v.thread = threading.Thread(target=build, name=f"viewer-build-{pid}", daemon=True)
            self._viewers[pid] = v
            v.thread.start()
            self._start_reaper()
            return v

    def _identify(self, server: viser.ViserServer, client: Any) -> Reviewer | None:
        """The app user whose viewer ticket opened this client's websocket."""
        assert self.gate is not None
        ticket = self.gate.user_of(connection_of(server, client.client_id))
        if ticket is None:
            return None
        resolve = getattr(self.backend, "resolve_user", None)
        if resolve is None:
            return Reviewer(ticket.name, ticket.role, None)
        return resolve(ticket.user_id) if ticket.project is None else resolve(ticket.user_id, ticket.project)

    # -- idle scenes ----------------------------------------------------------------------
    def _start_reaper(self) -> None:
        if self.idle_s <= 0 or self._reaper is not None:
            return
        self._reaper = threading.Thread(target=self._reap_loop, name="viewer-idle", daemon=True)
        self._reaper.start()

    def _reap_loop(self) -> None:
        while not self._stop.wait(self.idle_check_s):
            try:
                self.stop_idle()
            except Exception:  # keep watching
                log.exception("viewer: stopping idle scenes failed")

    def stop_idle(self, now: float | None = None) -> list[ProjectId]:
        """Stop the scenes no tab has been on for ``idle_s``; answers their projects."""
        now = time.monotonic() if now is None else now
        with self._lock:
            idle = [pid for pid, v in self._viewers.items()
                    if v.scene.ready.is_set() and not v.scene.sessions
                    and now - v.scene.last_active >= self.idle_s]
        for pid in idle:
            log.info("viewer: project %s idle for %.0f s: scene stopped", pid, self.idle_s)
            self.stop(pid)
        if idle:
            release_memory()
        return idle

    def scene_for(self, pid: ProjectId) -> ProjectScene:
        return self.viewer(pid).scene

    def wait_ready(self, pid: ProjectId, timeout: float | None = None) -> ProjectScene:
        """The project's scene once built; re-raises a build error."""
        v = self.viewer(pid)
        if not v.scene.ready.wait(timeout):
            raise TimeoutError(f"project {pid}: scene not ready after {timeout} s")
        if v.error:
            raise v.error[0]
        return v.scene

    def url_for(self, pid: ProjectId, request_host: str | None = None) -> str:
        """The address of the project's scene, as a browser can open it."""
        v = self.viewer(pid)
        host = self.public_host or self.host
        if host in WILDCARD_HOSTS or (host in LOOPBACK_HOSTS and request_host in LOOPBACK_HOSTS):
            host = request_host or "localhost"  # the name the browser used: its cookie goes along
        if ":" in host and not host.startswith("["):
            host = f"[{host}]"  # IPv6 literal
        return f"http://{host}:{v.port}/"

    def running(self) -> list[ProjectId]:
        with self._lock:
            return list(self._viewers)

    def stop(self, pid: ProjectId) -> None:
        with self._lock:
            v = self._viewers.pop(pid, None)
        if v is not None:
            v.thread.join(timeout=30.0)  # let a build in progress finish before the server goes
            v.scene.close()
            v.server.stop()

    def stop_all(self) -> None:
        self._stop.set()
        for pid in self.running():
            self.stop(pid)


def release_memory() -> None:
    """Collect garbage and hand freed heap pages back to the system (glibc's malloc_trim)."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _ticket_project(pid: ProjectId) -> int | None:
    """The project a scene's tickets must name (an id that is not a number: none)."""
    try:
        return int(pid)
    except (TypeError, ValueError):
        return None
