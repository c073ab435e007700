"""The review panel of one browser tab in the 3D scene: its reviewer, selection and camera,
its decisions and added objects (through the scene's ReviewBackend)."""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from .backend import (
    Locked,
    Reviewer,
    ReviewError,
    StaleVersion,
)
from .images import read_rgb, thumbnail
from .labels import (
    SCAN_LEVELS,
    SELECTION_RGB,
    _fmt,
    class_choices,
    log,
    readable_time,
    spot_label,
    surface_text,
)

if TYPE_CHECKING:
    from .scene import ProjectScene


class ReviewSession:
    """The review panel of one browser tab: its reviewer, its selection, its camera."""

    def __init__(self, scene: ProjectScene, client: viser.ClientHandle,
                 user: Reviewer | None = None) -> None:
        self.scene = scene
        self.client = client
        self.user: Reviewer | None = user
        self.labels: dict[str, Any] = {}  # this tab's labels: its selection, what is near its camera
        self._labels_at = 0.0
        self.selected: str | None = None
        self._highlight: Any = None
        self._scan_lock = threading.RLock()
        self._panel_lock = threading.RLock()  # the selection and the panel showing it change together
        self.scan_groups: dict[str, Any] = {}  # layer -> this tab's frame holding its tiles
        self.scan_nodes: dict[str, list[Any]] = {}  # layer -> this tab's point cloud tiles
        self._model_cache: dict[str, np.ndarray | None] = {}
        self.class_ids: dict[str, str] = {}  # class dropdown option (display name) -> class id
        self.ceiling_nodes: dict[str, Any] = {}  # "kind/id" -> this tab's ceiling image
        gui = client.gui
        blank = np.zeros((scene.s.crop_px, scene.s.crop_px, 3), np.uint8)
        self.f_user = gui.add_folder("Reviewer", order=10)
        with self.f_user:
            signed = user is not None
            self.ui_token = gui.add_text("API token", "", hint="paste your API token to review",
                                         visible=not signed)
            self.ui_sign_in = gui.add_button("Sign in", visible=not signed)
            self.ui_who = gui.add_markdown(f"Signed in as **{user.name}** ({user.role})." if signed
                                           else "Not signed in: you can look, not decide.")
        self.f_sel = gui.add_folder("Selected object", order=20)
        with self.f_sel:
            self.ui_info = gui.add_markdown("Click a spot to select an object.")
            self.ui_colour = gui.add_image(blank, label="colour", format="jpeg", visible=False)
            self.ui_depth = gui.add_image(blank, label="depth", format="jpeg", visible=False)
            self.ui_model = gui.add_image(blank, label="model", format="png", visible=False)
            self.ui_accept = gui.add_button("Accept", color="green", disabled=True)
            self.ui_reject = gui.add_button("Reject", color="red", disabled=True)
            classes = list(self._class_choices()) or ["-"]
            self.ui_class = gui.add_dropdown("Class", classes, initial_value=classes[0],
                                             disabled=True)
            self.ui_relabel = gui.add_button("Relabel (accept as class)", disabled=True)
            self.ui_auto = gui.add_checkbox("Go to next pending after a decision", True)
            self.ui_prev = gui.add_button("◀ Previous pending")
            self.ui_next = gui.add_button("Next pending ▶",
                                          hint="least sure first (confidence, else alpha)")
        self.f_add = gui.add_folder("Add a missed object", order=22)
        with self.f_add:
            self.ui_add_class = gui.add_dropdown("Class to add", classes, initial_value=classes[0])
            self.ui_add_help = gui.add_markdown("**Shift-click on a wall** (or a ceiling from below, or a "
                                                "column) to add an object of this class there "
                                                "(accepted, source *reviewer*).")
        self.f_scan = gui.add_folder("Scan (this tab)", order=25)
        with self.f_scan:
            self.ui_scan = gui.add_dropdown(
                "Scan detail", SCAN_LEVELS, initial_value=scene.s.scan_detail,
                hint="overview: light for any computer; full: every point sent "
                     "(up to max_points), for a good graphics card; off: none")
            self.ui_ceiling = gui.add_checkbox("Ceiling", False)
            self.ui_ceiling_images = gui.add_checkbox(
                "Ceiling images (from below)", True,
                hint="the ceilings' orthoimages, shown while the camera is below the ceiling")
        self.ui_scan.on_update(lambda ev: self.update_scan())
        self.ui_ceiling_images.on_update(lambda ev: self.update_ceilings())
        self.ui_ceiling.on_update(lambda ev: self.update_scan())
        self.ui_sign_in.on_click(lambda ev: self.sign_in(self.ui_token.value))
        self.ui_accept.on_click(lambda ev: self.decide("accepted"))
        self.ui_reject.on_click(lambda ev: self.decide("rejected"))
        self.ui_relabel.on_click(lambda ev: self.decide("accepted", self.class_id(self.ui_class.value)))
        self.ui_prev.on_click(lambda ev: self.step(-1))
        self.ui_next.on_click(lambda ev: self.step(+1))
        client.scene.on_click(modifier="shift")(self._on_shift_click)
        client.camera.on_update(lambda cam: self._on_camera())
        self.show()
        self.stream_scan_later()

    def _classes(self) -> list[str]:
        data = self.scene.data
        if data is None:
            return []
        have = {d["class"] for d in self.scene.detections.values()}
        return sorted(set(data.classes) | have)

    def _class_choices(self) -> dict[str, str]:
        """The class dropdowns' options (display name -> class id), sorted by name."""
        names = self.scene.class_names
        ids = sorted(self._classes(), key=lambda cid: (names.get(cid, cid).casefold(), cid))
        self.class_ids = class_choices(ids, names)
        return self.class_ids

    def class_id(self, option: str) -> str:
        """The class id of a dropdown's option (an id passes through)."""
        return self.class_ids.get(option, option)

    def class_option(self, cid: str) -> str | None:
        """The dropdown option that shows class ``cid``."""
        return next((label for label, c in self.class_ids.items() if c == cid), None)

    def notify(self, title: str, body: str, colour: str | None = None) -> None:
        try:
            self.client.add_notification(title, body, auto_close_seconds=4.0, color=colour)
        except Exception:  # a tab that just closed
            log.debug("viewer: notification to a closed client dropped")

    def reset(self) -> None:
        """After a rebuild: forget the selection, refresh the class list, send the new scan."""
        self.selected = None
        if self._highlight is not None:
            self._highlight.remove()
            self._highlight = None
        classes = list(self._class_choices())
        if classes:
            self.ui_class.options = classes
            self.ui_add_class.options = classes
        for node in self.labels.values():
            node.remove()
        self.labels.clear()
        for node in self.ceiling_nodes.values():
            node.remove()
        self.ceiling_nodes.clear()
        self.update_ceilings()
        with self._scan_lock:
            for g in self.scan_groups.values():
                g.remove()
            self.scan_groups.clear()
            self.scan_nodes.clear()
        self.show()
        self.stream_scan_later()

    # -- ceilings, per tab: seen from below ----------------------------------------------
    def _on_camera(self) -> None:
        self.update_labels()
        self.update_ceilings()

    def camera_z(self) -> float | None:
        try:
            return float(np.asarray(self.client.camera.position, float)[2])
        except (AssertionError, AttributeError, IndexError):
            return None

    def update_ceilings(self) -> None:
        """Show each ceiling's orthoimage (of the scene's image mode) while this tab's camera is
        below it; an image seen from above would hide the floor."""
        sc = self.scene
        ids = sc.ceiling_ids()
        if not ids or sc.images is None:
            return
        mode = sc.ui_images.value
        cam_z = self.camera_z()
        with self._scan_lock:
            for sid in ids:
                f = sc.surface_frames[sid]
                below = cam_z is not None and cam_z < f.origin[2] - sc.centre[2] - sc.s.image_offset_m
                for kind in ("colour", "depth"):
                    key = f"{kind}/{sid}"
                    want = bool(self.ui_ceiling_images.value) and mode == kind and below
                    node = self.ceiling_nodes.get(key)
                    if node is None and want:
                        got = sc.image_texture(sid, kind)
                        if got is None:
                            continue
                        tex, wxyz, pos, w_m, h_m = got
                        node = self.client.scene.add_image(
                            f"/ceiling_images/{key}", tex, render_width=w_m, render_height=h_m,
                            format="jpeg", jpeg_quality=sc.s.jpeg_quality, cast_shadow=False,
                            receive_shadow=False, wxyz=wxyz, position=pos)
                        self.ceiling_nodes[key] = node
                    elif node is not None and node.visible != want:
                        node.visible = want

    def ceiling_images_shown(self) -> list[str]:
        """The ceiling images this tab shows now ("kind/id")."""
        with self._scan_lock:
            return sorted(k for k, n in self.ceiling_nodes.items() if n.visible)

    # -- the scan, per tab ----------------------------------------------------------------
    def stream_scan_later(self) -> None:
        """Send the scan once the tab has drawn the rest of the scene: the first frame at once.

        The scan is by far the heaviest layer to send and to draw (in a browser without a
        graphics card a frame with the overview's points takes seconds): a tab first draws the
        plan, walls, spots and panel; once it has shown a frame (:meth:`wait_drawn`) and
        ``scan_delay_s`` later, it gets the scan at the detail it asks for, progressively
        (:meth:`update_scan`).
        """
        def run() -> None:
            if self.scene.ready.wait(600):
                t = time.monotonic()
                drawn = self.wait_drawn(self.scene.s.first_frame_wait_s)
                log.info("viewer: tab %s %s after %.1f s; the scan follows", self.client.client_id,
                         "drew its first frame" if drawn else "showed no frame", time.monotonic() - t)
                time.sleep(self.scene.s.scan_delay_s)
                self.update_scan()

        threading.Thread(target=run, name=f"viewer-scan-{self.client.client_id}",
                         daemon=True).start()

    def wanted_scan_layers(self) -> set[str]:
        level = self.ui_scan.value
        if level not in ("overview", "full"):
            return set()
        return {f"scan_{level}"} | ({f"ceiling_{level}"} if self.ui_ceiling.value else set())

    def wait_drawn(self, timeout: float) -> bool:
        """Wait until this tab has drawn a frame of what it was sent (it answers a tiny render
        request after applying every message before it); False after ``timeout`` or when the
        tab cannot render (it has gone)."""
        try:
            self.client.get_render(8, 8, timeout=timeout)
            return True
        except Exception:  # TimeoutError, a closed tab, a client that cannot render
            return False

    def update_scan(self) -> None:
        """Show the scan layers this tab asks for, sending each one the first time: tile by
        tile, in batches of about ``scan_batch_points`` points ``scan_batch_pause_s`` apart,
        so the tab draws the scan as it comes instead of stalling on one large message."""
        s = self.scene.s
        want = self.wanted_scan_layers()
        # before the tab's scan lock: a rebuild holds the scene's lock while it resets the tabs
        tiles = {name: layer for name in want if (layer := self.scene.scan_layer(name)) is not None}
        with self._scan_lock:
            if self.scene.sessions.get(self.client.client_id) is not self:
                return  # the tab has gone
            todo = []
            for name in sorted(want - set(self.scan_nodes)):
                if name in tiles:
                    self.scan_groups[name] = self.client.scene.add_frame(f"/{name}", show_axes=False)
                    self.scan_nodes[name] = []
                    todo.append((name, self.scan_groups[name]))
            for name, group in self.scan_groups.items():
                group.visible = name in want
        batch = 0
        for name, group in todo:
            for i, t in enumerate(tiles[name]):
                if batch >= s.scan_batch_points:
                    time.sleep(s.scan_batch_pause_s)  # the scan lock is free meanwhile
                    batch = 0
                with self._scan_lock:
                    if self.scene.sessions.get(self.client.client_id) is not self:
                        return  # the tab has gone
                    if self.scan_groups.get(name) is not group:
                        break  # a rebuild: this layer's tiles are no longer wanted
                    self.scan_nodes[name].append(self.client.scene.add_point_cloud(
                        f"/{name}/t{i}", points=t.points, colors=t.colors,
                        point_size=t.point_size, point_shape="square", precision="float16",
                        point_shading="flat", position=t.position))
                batch += len(t.points)

    def scan_points_sent(self) -> int:
        with self._scan_lock:
            return sum(len(n.points) for nodes in self.scan_nodes.values() for n in nodes)

    # -- identity -----------------------------------------------------------------------
    def sign_in(self, token: str) -> Reviewer | None:
        token = (token or "").strip()
        user = self.scene.backend.resolve_token(token) if token else None
        self.user = user
        if user is None:
            self.ui_who.content = "**Unknown token.** Not signed in: you can look, not decide."
        else:
            self.ui_token.value = ""  # do not leave the token on screen
            self.ui_who.content = f"Signed in as **{user.name}** ({user.role})."
        self.show()
        return user

    # -- selection ----------------------------------------------------------------------
    def select(self, did: str, fly: bool = True) -> None:
        det = self.scene.detection(did)
        if det is None:
            return
        with self._panel_lock:  # a refresh from the scene's thread shows the old selection before, not after
            self.selected = did
            pos = self.scene.local(det["position"])
            if self._highlight is None:
                self._highlight = self.client.scene.add_icosphere(
                    "/selection", radius=self.scene.spot_radius * 1.9, color=SELECTION_RGB,
                    wireframe=True, subdivisions=1, cast_shadow=False, receive_shadow=False,
                    position=pos)
            else:
                self._highlight.position = pos
            option = self.class_option(det.get("class"))
            if option in (self.ui_class.options or ()):
                self.ui_class.value = option
            self.show()
        if fly:
            self.fly_to(det)
        self.update_labels(force=True)

    def step(self, direction: int) -> str | None:
        did = self.scene.pending_after(self.selected, direction)
        if did is None:
            self.notify("Nothing pending", "Every object has been reviewed.")
            return None
        self.select(did)
        return did

    def fly_to(self, det: dict) -> None:
        """Move this tab's camera in front of the object, looking at it (from below at a ceiling)."""
        target = self.scene.local(det["position"])
        eye = self.view_point(det)
        cam = self.client.camera
        try:
            p0, l0 = np.array(cam.position), np.array(cam.look_at)
        except AssertionError:  # no camera state from this tab yet
            p0, l0 = eye, target
        n = max(1, self.scene.s.fly_steps)
        for i in range(1, n + 1):
            t = i / n
            t = t * t * (3 - 2 * t)  # smoothstep
            with self.client.atomic():
                cam.position = p0 + (eye - p0) * t
                cam.look_at = l0 + (target - l0) * t
            if i < n:
                time.sleep(self.scene.s.fly_s / n)
        self.update_ceilings()

    def view_point(self, det: dict) -> np.ndarray:
        """Where the camera looks at an object from (scene coordinates): in front of it; under
        a ceiling object, below it and a little towards the middle of the floor."""
        target = self.scene.local(det["position"])
        normal = self.scene.normal_at(det)
        normal = np.array([0.0, -1.0, 0.0]) if normal is None else normal
        dist = self.scene.s.view_distance_m
        if normal[2] < -0.7:  # a ceiling: look up at it, not straight up (the camera keeps z up)
            towards = -target[:2]
            n = float(np.linalg.norm(towards))
            towards = towards / n if n > 1e-6 else np.array([0.0, -1.0])
            return target + normal * 0.8 * dist + np.array([*(0.55 * dist * towards), 0.0])
        return target + normal * dist + np.array([0.0, 0.0, 0.25 * dist])

    # -- labels: the selection and what is near the camera ------------------------------
    def wanted_labels(self) -> list[str]:
        sc = self.scene
        want = [self.selected] if self.selected in sc.detections else []
        try:
            cam = np.array(self.client.camera.position, float)
        except (AssertionError, AttributeError):
            return want
        near = []
        for did, spot in list(sc.spots.items()):
            dist = float(np.linalg.norm(np.asarray(spot.position, float) - cam))
            if dist <= sc.s.near_label_m and did != self.selected:
                near.append((dist, did))
        return want + [did for _, did in sorted(near)[:sc.s.near_label_max]]

    def update_labels(self, force: bool = False) -> None:
        """Label this tab's selection and the objects near its camera (throttled)."""
        now = time.monotonic()
        if not force and now - self._labels_at < self.scene.s.label_refresh_s:
            return
        self._labels_at = now
        sc = self.scene
        want = self.wanted_labels()
        for did in list(self.labels):
            if did not in want:
                self.labels.pop(did).remove()
        for did in want:
            det = sc.detection(did)
            spot = sc.spots.get(did)
            if det is None or spot is None:
                continue
            text = spot_label(det, sc.class_names) + (f" · {det['review']['status']}" if did == self.selected else "")
            node = self.labels.get(did)
            if node is not None:
                node.text = text
                continue
            self.labels[did] = self.client.scene.add_label(
                f"/tab_labels/{did}", text, position=np.asarray(spot.position, float) + sc.label_lift(det),
                anchor="bottom-center", font_screen_scale=0.9, depth_test=False)

    # -- adding a missed object ------------------------------------------------------------
    def _on_shift_click(self, event: Any) -> None:
        if event.ray_origin is None or event.ray_direction is None:
            return
        self.add_at_ray(np.asarray(event.ray_origin, float), np.asarray(event.ray_direction, float))

    def add_at_ray(self, origin: np.ndarray, direction: np.ndarray) -> dict | None:
        """Add an object of the chosen class where a ray (scene coordinates) meets a wall, a
        ceiling (from below) or a column."""
        sc = self.scene
        hit = sc.hit(origin + sc.centre, direction)
        if hit is None:
            self.notify("Not on a wall", "Shift-click on a wall, a ceiling or a column to add an "
                        "object there.", "yellow")
            return None
        wid, u, v = hit
        return self.add_object(wid, u, v, self.class_id(self.ui_add_class.value))

    def add_object(self, wall: str, u: float, v: float, class_id: str) -> dict | None:
        if self.user is None:
            self.notify("Not signed in", "Sign in to the review app to add objects.", "red")
            return None
        try:
            det = self.scene.backend.add_object(self.scene.pid, class_id, wall, round(u, 4), round(v, 4),
                                                self.user)
        except Locked:
            self.notify("Signed off", "The project is signed off: read-only.", "red")
            return None
        except ReviewError as exc:
            self.notify("Not added", str(exc), "red")
            return None
        self.scene.add_detection(det)
        self.notify(f"Added {self.scene.class_names.get(det['class'], det['class'])}", f"on {wall} at u {det['u']:.3f}, v {det['v']:.3f} m",
                    "green")
        self.select(det["id"], fly=False)
        return det

    # -- decisions ----------------------------------------------------------------------
    def decide(self, status: str, new_class: str | None = None) -> dict | None:
        """Record a decision on the selected object as the signed-in reviewer."""
        did, user = self.selected, self.user
        if did is None:
            self.notify("No object selected", "Click a spot first.")
            return None
        if user is None:
            self.notify("Not signed in", "Enter your API token to review.", "red")
            return None
        det = self.scene.detection(did)
        if det is None:
            return None
        if new_class is not None and new_class == det.get("class"):
            new_class = None
        try:
            updated = self.scene.backend.decide(self.scene.pid, did, status, new_class,
                                                int(det["review"]["version"]), user)
        except StaleVersion as exc:
            if exc.current:
                self.scene.apply_detection(exc.current)
            self.notify("Changed meanwhile", f"{did} was changed by someone else; "
                        "look again, then decide.", "yellow")
            return None
        except Locked:
            self.scene.poll_once()
            self.notify("Signed off", "The project is signed off: read-only.", "red")
            return None
        except ReviewError as exc:
            self.notify("Not recorded", str(exc), "red")
            return None
        self.scene.apply_detection(updated)
        self.notify(f"{did} {updated['review']['status']}",
                    f"{updated['class']} by {updated['review'].get('by')}", "green")
        if self.ui_auto.value:
            nxt = self.scene.pending_after(did, +1)
            if nxt is not None:
                self.select(nxt)
        return updated

    # -- panel ----------------------------------------------------------------------------
    def show(self) -> None:
        """Bring the panel in line with the selection, the reviewer and the lock."""
        with self._panel_lock:
            self._show()

    def _show(self) -> None:
        sc = self.scene
        det = sc.detection(self.selected) if self.selected else None
        can = det is not None and self.user is not None and self.user.may_decide and not sc.locked
        for b in (self.ui_accept, self.ui_reject, self.ui_relabel, self.ui_class):
            b.disabled = not can
        if sc.locked:
            self.ui_who.content = "**Signed off**: this scene is **read-only**." + (
                f" (signed in as {self.user.name})" if self.user else "")
        if det is None:
            self.ui_info.content = "Click a spot to select an object." if not sc.locked else \
                "**Signed off**: read-only. Click a spot to see an object."
            for img in (self.ui_colour, self.ui_depth, self.ui_model):
                img.visible = False
            return
        self.ui_info.content = self.info_text(det)
        for kind, ui in (("colour", self.ui_colour), ("depth", self.ui_depth)):
            crop = self._crop(det, kind)
            ui.visible = crop is not None
            if crop is not None:
                ui.image = crop
        model = self._model_image(det["class"])
        self.ui_model.visible = model is not None
        if model is not None:
            self.ui_model.image = model
            self.ui_model.label = f"model: {self.scene.class_names.get(det['class'], det['class'])}"

    def info_text(self, det: dict) -> str:
        r = det["review"]
        who = f" by {r['by']} on {readable_time(r['at'])}" if r.get("by") else ""
        storey = self.scene.storey_of.get(det.get("wall"))
        where = surface_text(det.get("wall"), self.scene.surfaces.get(det.get("wall")))
        name = self.scene.class_names.get(det["class"], det["class"])
        lines = [f"**{det.get('ref') or det['id']} · {name}** on {where}"
                 + (f", storey {storey}" if storey else ""),
                 f"u {_fmt(det.get('u'), 3)} m, v {_fmt(det.get('v'), 3)} m, "
                 f"{_fmt(det.get('width_m'), 3)} × {_fmt(det.get('height_m'), 3)} m",
                 f"α {_fmt(det.get('alpha'))} · ρ_D {_fmt(det.get('rho_depth'))} · "
                 f"ρ_C {_fmt(det.get('rho_colour'))} · found in {det.get('source')}",
                 f"Review: **{r['status']}**{who} (version {r.get('version')})"]
        if self.scene.locked:
            lines.append("**Signed off**: read-only.")
        return "\n\n".join(lines)

    def _crop(self, det: dict, kind: str) -> np.ndarray | None:
        sc = self.scene
        f = sc.frame_of(det.get("wall"))
        if f is None or sc.images is None:
            return None
        s = sc.s
        return sc.images.crop(det["wall"], kind, f.height_m, float(det["u"]), float(det["v"]),
                              float(det.get("width_m") or 0.05), float(det.get("height_m") or 0.05),
                              s.crop_context, s.crop_min_m, s.crop_px)

    def _model_image(self, cls: str) -> np.ndarray | None:
        data = self.scene.data
        if data is None or data.models_dir is None:
            return None
        if cls not in self._model_cache:
            img = read_rgb(data.models_dir / cls / "colour.png")
            self._model_cache[cls] = None if img is None else thumbnail(img, self.scene.s.crop_px)
        return self._model_cache[cls]
