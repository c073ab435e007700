"""The 3D review scene of one project, built into a ``viser.ViserServer`` from plain data.

What the reviewer sees (paper, section 5 and figures 18, 19 and 21):

``/scan``, ``/ceiling``
    the floor's scan at a browser level of detail (``app.viewer.lod``), recentred on
    :attr:`ProjectScene.centre`, in tiles of ``tile_m`` so float16 coordinates stay precise;
    the ceiling points (above the walls' tops) are a layer of their own, off at first.
``/walls/<W>/outline``, ``/walls/<W>/label``, ``/openings/<W>``
    each wall segment outlined and named; doors and windows outlined.
``/images/colour/<W>``, ``/images/depth/<W>``
    the wall's colour and depth orthoimage as a textured plane on the wall (colour, depth
    or off); depth planes are sent only when first asked for.
``/rois/depth/<W>`` (cyan), ``/rois/colour/<W>`` (magenta)
    the regions of interest of the depth and colour recognizers (figure 21 a).
``/ceilings/<C>``, ``/columns/<COL>``, ``/ceiling_images/<kind>/<C>`` (per tab)
    surfaces beyond walls (contract 4's ``surfaces``, ``sbsc detect --ceilings --columns``):
    each ceiling tile outlined, and its orthoimage seen from below: a tab shows it only while
    its camera is below the ceiling, so the floor stays visible from above; each column
    as a box (its four faces with their orthoimages) or a cylinder (a round column, its
    unrolled image wrapped back round it as a textured mesh).
``/spots/<D>``, ``/spot_labels/<D>``
    every recognized object as a spot at its ``position`` (the paper's red spots), coloured
    by review state; clicking one selects it. The labels of all objects are a layer that is
    off at first: each tab labels only its selection and the objects near its camera. The
    object under the pointer gets no label: viser (1.1.1, the newest release) tells the
    server of clicks, rectangle selections and drags only, never of the pointer moving;
    its browser client outlines the clickable spot under the pointer by itself.

Every browser tab gets its own review panel (:class:`ReviewSession`): the reviewer signed in
to the app (the viewer's cookie, see :mod:`app.viewer.gate`; an API token in the stand-alone
viewer), the selected object's values and crops, Accept / Reject / Relabel, Previous / Next
pending in order of confidence, least sure first; the camera flies to the selection.
Shift-click on a wall adds an object recognition missed, of the class chosen in the panel. Decisions go through the :class:`ReviewBackend`;
a background thread polls its change feed so that a decision made on the REST API shows in
every tab within ``poll_s``. After sign-off the scene is read-only and says so.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from sbsc_core.types import WallFrame

from ..review_rules import sort_score
from ..surfaces import is_round, kind_of
from .backend import (
    Changes,
    ProjectData,
    ProjectId,
    ReviewBackend,
    Reviewer,
)
from .geometry import (
    ScanTile,
    column_meshes,
    make_tiles,
    plane_wxyz,
    rect_segments,
    surface_hit,
    wrapped_cylinder,
)
from .images import WallImages, texture
from .labels import (
    CEILING_RGB,
    COLOUR_ROI_RGB,
    COLUMN_RGB,
    DEPTH_ROI_RGB,
    IMAGE_MODES,
    OPENING_RGB,
    STATUS_RGB,
    WALL_RGB,
    class_names,
    label_positions,
    log,
    readable_time,
    spot_label,
    spread_labels,
    wall_label,
)
from .lod import ScanLod, scan_lod
from .review_panel import ReviewSession


@dataclass
class SceneSettings:
    """Every size, colour-free threshold and timing of the scene."""

    max_points: int = 2_000_000  # scan points of the whole floor at the full level
    overview_points: int = 400_000  # ... at the overview level, the one shown first
    tile_m: float = 8.0  # side of a scan tile (float16 precision ~ tile_m / 2048)
    point_size_min_m: float = 0.012
    point_size_voxels: float = 1.3  # point side in voxels (gaps close at about 1.3)
    ceiling_margin_m: float = 0.08  # points this close below the walls' top count as ceiling
    texture_pixel_m: float = 0.01  # orthoimage textures: pixels at least this big
    texture_max_px: int = 2048  # ... and at most this many on a side
    jpeg_quality: int = 85
    image_offset_m: float = 0.004  # textured planes stand this far into the room
    depth_roi_offset_m: float = 0.008
    colour_roi_offset_m: float = 0.012
    roi_thickness_px: float = 3.0
    wall_thickness_px: float = 2.5
    spot_radius_m: float = 0.05  # at least; a big floor gets bigger spots (spot_extent_share)
    spot_extent_share: float = 0.004  # spot radius = this x the floor's larger side, when larger
    label_gap_m: float = 1.6  # wall names closer than this in plan are spread along their walls ...
    label_step_m: float = 0.35  # ... and those still that close stacked this much above each other
    label_lift_m: float = 0.06
    poll_s: float = 0.25  # change feed polling period
    scan_delay_s: float = 2.0  # a new tab gets the scan this long after it drew the rest of the scene
    first_frame_wait_s: float = 10.0  # ... or, when it answers no render request by then, this long after the build
    scan_batch_points: int = 60_000  # the scan goes out in batches of about this many points ...
    scan_batch_pause_s: float = 0.4  # ... this far apart, so the tab draws between them
    scan_detail: str = "overview"  # what a new tab shows first: overview, full or off
    fly_s: float = 0.6  # camera flight to a selected object
    fly_steps: int = 24
    view_distance_m: float = 1.6  # camera distance from a selected object
    crop_context: float = 2.5  # crop side = this x the object's larger side ...
    crop_min_m: float = 0.25  # ... and at least this
    crop_px: int = 160
    near_label_m: float = 3.0  # a tab labels the objects this close to its camera ...
    near_label_max: int = 12  # ... at most this many
    label_refresh_s: float = 0.3  # camera moves update the near labels at most this often


class ProjectScene:
    """The scene of one project in one viser server (the server shows nothing else)."""

    def __init__(self, server: viser.ViserServer, backend: ReviewBackend, pid: ProjectId,
                 settings: SceneSettings | None = None) -> None:
        self.server = server
        self.backend = backend
        self.pid = pid
        self.s = settings or SceneSettings()
        self.data: ProjectData | None = None
        self.centre = np.zeros(3)
        self.spot_radius = self.s.spot_radius_m
        self.label_at: dict[str, np.ndarray] = {}  # wall id -> its label's anchor (stacked near corners)
        self.class_names: dict[str, str] = {}  # class id -> the library's name (model.json)
        self.lod: ScanLod | None = None
        self.frames: dict[str, WallFrame] = {}  # the walls
        self.surfaces: dict[str, dict] = {}  # contract 4's surfaces (ceilings, column faces) by id
        self.surface_frames: dict[str, WallFrame] = {}
        self.storey_of: dict[str, str | None] = {}  # wall id -> its storey (several storeys)
        self.detections: dict[str, dict] = {}
        self.order: list[str] = []  # detection ids in review order
        self.locked = False
        self.signoff: dict | None = None
        self.images: WallImages | None = None
        self.groups: dict[str, Any] = {}  # layer name -> frame handle
        self.spots: dict[str, Any] = {}
        self.spot_labels: dict[str, Any] = {}
        self.nodes: dict[str, Any] = {}  # every other node by name
        self.sessions: dict[int, ReviewSession] = {}
        self.ready = threading.Event()
        self.error: str | None = None
        self.revision: Any = None
        self.scan_tiles: dict[str, list[ScanTile]] = {}  # layer -> tiles, sent per tab
        self._cursor: Any = None
        self.identify: Any = None  # client -> Reviewer | None (the app's login), set by the manager
        self.last_active = time.monotonic()  # last tab connected or left
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._poller: threading.Thread | None = None
        self._build_gui()
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)

    # ------------------------------------------------------------------ shared GUI
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.configure_theme(control_width="large", show_share_button=False, show_logo=False)
        self._status = gui.add_markdown("Loading the scene…", order=0)
        self._layers = gui.add_folder("Layers", order=30)
        with self._layers:
            self.ui_walls = gui.add_checkbox("Walls (outlines, names)", True)
            self.ui_surfaces = gui.add_checkbox("Ceilings and columns", True,
                                                hint="ceiling outlines, columns as boxes and cylinders")
            self.ui_openings = gui.add_checkbox("Openings", True)
            self.ui_images = gui.add_dropdown("Wall images", IMAGE_MODES, initial_value="colour")
            self.ui_depth_rois = gui.add_checkbox("Depth RoIs (cyan)", True)
            self.ui_colour_rois = gui.add_checkbox("Colour RoIs (magenta)", True)
            self.ui_spots = gui.add_checkbox("Objects (spots)", True)
            self.ui_labels = gui.add_checkbox("All object labels", False,
                                              hint="off: only the selection and what is near the camera")
        for box, layers in ((self.ui_walls, ("walls",)), (self.ui_openings, ("openings",)),
                            (self.ui_surfaces, ("ceilings", "columns")),
                            (self.ui_depth_rois, ("rois_depth",)),
                            (self.ui_colour_rois, ("rois_colour",)),
                            (self.ui_spots, ("spots",)), (self.ui_labels, ("spot_labels",))):
            box.on_update(lambda ev, layers=layers: self._set_layers(layers, ev.target.value))
        self.ui_images.on_update(lambda ev: self.set_image_mode(ev.target.value))

    def _set_layers(self, layers: Iterable[str], visible: bool) -> None:
        with self._lock:
            for name in layers:
                if name in self.groups:
                    self.groups[name].visible = bool(visible)

    def _layer_visible(self, name: str) -> bool:
        box = {"walls": self.ui_walls, "ceilings": self.ui_surfaces, "columns": self.ui_surfaces,
               "openings": self.ui_openings, "rois_depth": self.ui_depth_rois,
               "rois_colour": self.ui_colour_rois, "spots": self.ui_spots,
               "spot_labels": self.ui_labels}.get(name)
        if box is not None:
            return bool(box.value)
        if name.startswith("images_"):
            return self.ui_images.value == name.removeprefix("images_")
        return True

    def status_text(self) -> str:
        if self.error:
            return f"**{self.error}**"
        counts = {k: 0 for k in STATUS_RGB}
        for d in self.detections.values():
            counts[d["review"]["status"]] = counts.get(d["review"]["status"], 0) + 1
        name = self.data.name if self.data else str(self.pid)
        storeys = sorted({st for st in self.storey_of.values() if st})
        where = f" in {len(storeys)} storeys ({', '.join(storeys)})" if len(storeys) > 1 else ""
        lines = [f"### {name}",
                 f"{len(self.detections)} objects on {len(self.frames)} walls{self._surfaces_text()}{where}: "
                 f"**{counts['pending']} pending**, {counts['accepted']} accepted, "
                 f"{counts['rejected']} rejected."]
        if self.lod is not None:
            ov = len(self.lod.overview) if self.lod.overview is not None else len(self.lod)
            lines.append(f"Scan: {self.lod.source_points:,} points, shown as {ov:,} (overview) "
                         f"or {len(self.lod):,} (full).")
        if self.locked:
            so = self.signoff or {}
            lines.append(f"**Signed off** by {so.get('by', '?')} on {readable_time(so.get('at', '?'))}: "
                         "this scene is **read-only**.")
        return "\n\n".join(lines)

    def _surfaces_text(self) -> str:
        kinds = [kind_of(sf) for sf in self.surfaces.values()]
        cols = {str(sf.get("column") or sid) for sid, sf in self.surfaces.items() if kind_of(sf) == "column"}
        parts = ([f"{kinds.count('ceiling')} ceiling tile(s)"] if "ceiling" in kinds else []) + \
                ([f"{len(cols)} column(s)"] if cols else [])
        return f", {' and '.join(parts)}" if parts else ""

    def frame_of(self, wid: str | None) -> WallFrame | None:
        """The frame of a wall or of a surface (a round column's: its unrolled frame)."""
        return self.frames.get(wid) or self.surface_frames.get(wid)

    def normal_at(self, det: dict) -> np.ndarray | None:
        """The outward normal where an object sits (radial on a round column)."""
        sf = self.surfaces.get(det.get("wall"))
        if sf is not None and is_round(sf):
            radial = np.asarray(det["position"], float)[:2] - np.asarray(sf["centre"], float)
            n = float(np.linalg.norm(radial))
            return np.array([radial[0] / n, radial[1] / n, 0.0]) if n > 1e-9 else None
        f = self.frame_of(det.get("wall"))
        return None if f is None else f.normal

    def label_lift(self, det: dict) -> np.ndarray:
        """Where an object's label stands from its spot: above it, or below a ceiling object."""
        n = self.normal_at(det)
        if n is not None and n[2] < -0.7:  # on a ceiling: below the spot
            return n * (self.spot_radius + self.s.label_lift_m)
        lift = np.array([0.0, 0.0, self.s.label_lift_m])
        return lift if n is None else lift + n * self.spot_radius

    def planar_frames(self) -> dict[str, WallFrame]:
        """Walls, ceilings and the faces of rectangular columns: what a ray can hit as a plane."""
        return {**self.frames, **{sid: f for sid, f in self.surface_frames.items()
                                  if not is_round(self.surfaces[sid])}}

    def hit(self, origin: np.ndarray, direction: np.ndarray) -> tuple[str, float, float] | None:
        """The wall or surface (id, u, v) a ray (world coordinates) meets first."""
        rounds = {sid: sf for sid, sf in self.surfaces.items() if is_round(sf)}
        return surface_hit(self.planar_frames(), rounds, origin, direction)

    def _refresh_status(self) -> None:
        self._status.content = self.status_text()

    # ------------------------------------------------------------------ building
    def build(self, data: ProjectData | None = None, cursor: Any = None) -> None:
        """Build every layer, then start following the change feed.

        ``data`` and ``cursor`` are read from the backend unless given (the cursor must be
        taken before the data, so that no change falls between them).
        """
        try:
            if data is None:
                cursor = self.backend.changes_since(self.pid, None).cursor
                data = self.backend.project_data(self.pid)
            lod = None
            if data.scans:
                self._status.content = (f"Loading the scene of **{data.name}**: reading the scan "
                                        f"({len(data.scans)} file(s))…")
                lod = self._scan_lod(data)
                self._status.content = "Loading the scene: walls, images and objects…"
            with self._lock:
                self._build_from(data, lod)
                self._cursor = cursor
        except Exception as exc:  # shown in the browser rather than lost in a thread
            log.exception("viewer: building the scene of project %s failed", self.pid)
            self.error = f"Cannot build the scene: {exc}"
            self._status.content = self.status_text()
            raise
        finally:
            self.ready.set()
        self.start_sync()

    def _scan_lod(self, data: ProjectData) -> ScanLod:
        return scan_lod(data.scans, self.s.max_points, data.cache_dir, self.s.overview_points)

    def _build_from(self, data: ProjectData, lod: ScanLod | None) -> None:
        scene = self.server.scene
        for g in list(self.groups.values()):
            g.remove()
        self.groups.clear()
        self.spots.clear()
        self.spot_labels.clear()
        self.nodes.clear()
        self.data, self.lod, self.revision = data, lod, data.revision
        self.locked, self.signoff = bool(data.locked), data.signoff
        self.class_names = class_names(data.models_dir)
        doc = data.detections
        self.frames = {w["id"]: WallFrame.from_dict(w) for w in doc.get("walls", [])}
        self.surfaces = {sf["id"]: sf for sf in doc.get("surfaces") or []}  # contract 4: ceilings, columns
        self.surface_frames = {sid: WallFrame.from_dict(sf) for sid, sf in self.surfaces.items()}
        self.storey_of = {w["id"]: w.get("storey")  # contract 4, several storeys
                          for w in [*doc.get("walls", []), *self.surfaces.values()]}
        dets = doc.get("detections", [])
        self.detections = {d["id"]: d for d in dets}
        self.order = self.review_order()
        self.images = WallImages(data.ortho_dir, float(doc.get("pixel_m") or
                                                      (data.rois or {}).get("pixel_m") or 0.005))
        self.centre = lod.centre.copy() if lod is not None else self._walls_centre()

        for name in ("walls", "ceilings", "columns", "openings", "images_colour", "images_depth",
                     "rois_depth", "rois_colour", "spots", "spot_labels"):
            self.groups[name] = scene.add_frame(f"/{name}", show_axes=False,
                                                visible=self._layer_visible(name))
        self.scan_tiles = self._scan_layers(lod, ("overview",)) if lod is not None else {}
        ext = self._extent()
        self.spot_radius = max(self.s.spot_radius_m, self.s.spot_extent_share * ext)
        along = label_positions(self.frames, self.s.label_gap_m)
        tops = {wid: f.to_world(along[wid], f.height_m, 0.05) - self.centre for wid, f in self.frames.items()}
        self.label_at = spread_labels(tops, self.s.label_gap_m, self.s.label_step_m)
        for wid, frame in self.frames.items():
            self._add_wall(wid, frame)
        for sid, sf in self.surfaces.items():
            if kind_of(sf) == "ceiling":
                self._add_ceiling(sid, self.surface_frames[sid])
        self._add_columns()
        for o in doc.get("openings", []):
            self._add_opening(o)
        rois = (data.rois or {}).get("walls", {})
        for wid, r in rois.items():
            self._add_rois(wid, r)
        for d in dets:
            self._add_spot(d)
        self._set_initial_camera()
        # The status once the plan, walls and spots are there: a browser that shows it has them.
        self._status.remove()
        self._status = self.server.gui.add_markdown(self.status_text(), order=0)
        if self.ui_images.value != "off":  # the heaviest shared layer after them (the scan: per tab)
            self._add_images(self.ui_images.value)
        for session in self.sessions.values():
            session.reset()

    def review_order(self) -> list[str]:
        """Detection ids, least sure first (confidence, else alpha), then by id."""
        return sorted(self.detections, key=lambda did: (sort_score(self.detections[did]), did))

    def add_detection(self, det: dict) -> None:
        """Show a detection that was added (an object recognition missed); idempotent."""
        with self._lock:
            if det["id"] in self.detections:
                return
            self.detections[det["id"]] = det
            self.order = self.review_order()
            self._add_spot(det)
            self._refresh_status()

    def _walls_centre(self) -> np.ndarray:
        if not self.frames:
            return np.zeros(3)
        pts = np.concatenate([f.to_world(np.array([0.0, f.width_m]), np.array([0.0, f.height_m]))
                              for f in self.frames.values()])
        return np.round((pts.min(axis=0) + pts.max(axis=0)) / 2.0, 3)

    def local(self, world: Any) -> np.ndarray:
        """World coordinates to scene coordinates (recentred)."""
        return np.asarray(world, dtype=np.float64) - self.centre

    def scan_layer(self, name: str) -> list[ScanTile] | None:
        """The tiles of one scan layer (``scan_full``...), made the first time a tab asks for
        the full level (the build makes only the overview's, which every tab gets)."""
        with self._lock:
            if name not in self.scan_tiles and self.lod is not None and name.endswith("_full"):
                self.scan_tiles.update(self._scan_layers(self.lod, ("full",)))
            return self.scan_tiles.get(name)

    def _scan_layers(self, lod: ScanLod, levels: Iterable[str] = ("overview", "full")) -> dict[str, list[ScanTile]]:
        """The scan's layers (body / ceiling at the given levels), in tiles."""
        top = None
        if self.frames:
            top = float(np.median([f.origin[2] + f.height_m - self.centre[2]
                                   for f in self.frames.values()])) - self.s.ceiling_margin_m
        ov = lod.overview or lod
        full_size = max(lod.voxel_m * self.s.point_size_voxels, self.s.point_size_min_m)
        ov_size = max(ov.voxel_m * self.s.point_size_voxels, full_size)
        layers = {}
        for level, lv, size in (("full", lod, full_size), ("overview", ov, ov_size)):
            if level not in levels:
                continue
            ceiling = lv.xyz[:, 2] > top if top is not None else np.zeros(len(lv.xyz), bool)
            for part, mask in (("scan", ~ceiling), ("ceiling", ceiling)):
                layers[f"{part}_{level}"] = make_tiles(lv.xyz[mask], lv.rgb[mask], size,
                                                       self.s.tile_m)
        return layers

    def _add_wall(self, wid: str, f: WallFrame) -> None:
        scene = self.server.scene
        seg = rect_segments(f, 0.0, f.width_m, 0.0, f.height_m) - self.centre
        self.nodes[f"walls/{wid}/outline"] = scene.add_line_segments(
            f"/walls/{wid}/outline", seg, WALL_RGB, thickness=self.s.wall_thickness_px,
            thickness_units="screen")
        top = self.label_at.get(wid)
        if top is None:
            top = f.to_world(f.width_m / 2.0, f.height_m, 0.05) - self.centre
        self.nodes[f"walls/{wid}/label"] = scene.add_label(
            f"/walls/{wid}/label", wall_label(wid, f, self.storey_of.get(wid)), position=top,
            anchor="bottom-center", font_screen_scale=1.1)

    def _add_ceiling(self, sid: str, f: WallFrame) -> None:
        """A ceiling tile's outline (its image is sent per tab, seen from below)."""
        seg = rect_segments(f, 0.0, f.width_m, 0.0, f.height_m, self.s.image_offset_m) - self.centre
        self.nodes[f"ceilings/{sid}"] = self.server.scene.add_line_segments(
            f"/ceilings/{sid}", seg, CEILING_RGB, thickness=self.s.wall_thickness_px * 0.6,
            thickness_units="screen")

    def _add_columns(self) -> None:
        """Each column as a box or a cylinder, named at its top."""
        for cid, (verts, faces) in column_meshes(list(self.surfaces.values())).items():
            v = verts.astype(np.float64) - self.centre
            self.nodes[f"columns/{cid}"] = self.server.scene.add_mesh_simple(
                f"/columns/{cid}/body", v.astype(np.float32), faces, color=COLUMN_RGB, side="double",
                cast_shadow=False, receive_shadow=False)
            top = np.array([v[:, 0].mean(), v[:, 1].mean(), v[:, 2].max() - 0.15])
            self.nodes[f"columns/{cid}/label"] = self.server.scene.add_label(
                f"/columns/{cid}/label", cid, position=top, anchor="bottom-center", font_screen_scale=1.0)

    def ceiling_ids(self) -> list[str]:
        return [sid for sid, sf in self.surfaces.items() if kind_of(sf) == "ceiling"]

    def image_texture(self, wid: str, kind: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float] | None:
        """A wall's or planar surface's orthoimage as (texture, wxyz, position, width, height)."""
        f = self.frame_of(wid)
        if f is None or self.images is None:
            return None
        img = self.images.image(wid, kind)
        if img is None:
            return None
        tex = texture(img, self.images.pixel_m, self.s.texture_pixel_m, self.s.texture_max_px)
        # the image covers its pixels: cols * px by rows * px from the top-left (u = 0, v = height)
        w_m, h_m = img.shape[1] * self.images.pixel_m, img.shape[0] * self.images.pixel_m
        centre = f.to_world(w_m / 2.0, f.height_m - h_m / 2.0, self.s.image_offset_m)
        return tex, plane_wxyz(f), centre - self.centre, w_m, h_m

    def _add_opening(self, o: dict) -> None:
        f = self.frames.get(o.get("wall"))
        if f is None:
            return
        name = f"openings/{o['wall']}"
        seg = rect_segments(f, o["u_min"], o["u_max"], o["v_min"], o["v_max"],
                            self.s.image_offset_m * 2) - self.centre
        old = self.nodes.get(name)
        if old is not None:  # several openings on one wall: one node with all of them
            seg = np.concatenate([old.points.astype(np.float64), seg])
        self.nodes[name] = self.server.scene.add_line_segments(
            f"/{name}", seg, OPENING_RGB, thickness=self.s.wall_thickness_px,
            thickness_units="screen")

    def _add_rois(self, wid: str, rois: dict) -> None:
        f = self.frames.get(wid)
        if f is None:
            return
        for kind, rgb, d in (("depth", DEPTH_ROI_RGB, self.s.depth_roi_offset_m),
                             ("colour", COLOUR_ROI_RGB, self.s.colour_roi_offset_m)):
            boxes = rois.get(kind) or []
            if not boxes:
                continue
            seg = np.concatenate([rect_segments(f, b["u_min"], b["u_max"], b["v_min"], b["v_max"], d)
                                  for b in boxes]) - self.centre
            self.nodes[f"rois_{kind}/{wid}"] = self.server.scene.add_line_segments(
                f"/rois_{kind}/{wid}", seg, rgb, thickness=self.s.roi_thickness_px,
                thickness_units="screen")

    def _add_images(self, kind: str) -> None:
        """Textured planes of one kind on every wall and column face (once; later calls only show
        them). Ceilings are sent per tab (:meth:`ReviewSession.update_ceilings`)."""
        assert self.images is not None
        faces = [sid for sid, sf in self.surfaces.items() if kind_of(sf) == "column" and not is_round(sf)]
        for sid, sf in self.surfaces.items():
            if is_round(sf) and f"images_{kind}/{sid}" not in self.nodes:
                self._add_round_image(sid, sf, kind)
        for wid in [*self.frames, *faces]:
            name = f"images_{kind}/{wid}"
            if name in self.nodes:
                continue
            got = self.image_texture(wid, kind)
            if got is None:
                continue
            tex, wxyz, pos, w_m, h_m = got
            self.nodes[name] = self.server.scene.add_image(
                f"/{name}", tex, render_width=w_m, render_height=h_m, format="jpeg",
                jpeg_quality=self.s.jpeg_quality, cast_shadow=False, receive_shadow=False,
                wxyz=wxyz, position=pos)

    def _add_round_image(self, sid: str, sf: dict, kind: str) -> None:
        """A round column's unrolled image, wrapped round it (a textured mesh)."""
        assert self.images is not None
        img = self.images.image(sid, kind)
        if img is None:
            return
        tex = texture(img, self.images.pixel_m, self.s.texture_pixel_m, self.s.texture_max_px)
        px = self.images.pixel_m * img.shape[1] / tex.shape[1]
        try:
            mesh = wrapped_cylinder(tex, sf, px, self.s.image_offset_m)
        except Exception:  # no texture is no reason to lose the scene
            log.exception("viewer: the image of round column %s", sid)
            return
        mesh.apply_translation(-self.centre)
        self.nodes[f"images_{kind}/{sid}"] = self.server.scene.add_mesh_trimesh(f"/images_{kind}/{sid}", mesh)

    def set_image_mode(self, mode: str) -> None:
        """Show the colour or depth orthoimages on the walls, or none."""
        if mode not in IMAGE_MODES:
            raise ValueError(f"image mode: {mode!r} is not one of {IMAGE_MODES}")
        with self._lock:
            if self.ui_images.value != mode:
                self.ui_images.value = mode
            if mode != "off" and self.data is not None:
                self._add_images(mode)
            for kind in ("colour", "depth"):
                if f"images_{kind}" in self.groups:
                    self.groups[f"images_{kind}"].visible = mode == kind
            sessions = list(self.sessions.values())
        for session in sessions:
            session.update_ceilings()

    def _add_spot(self, d: dict) -> None:
        did = d["id"]
        pos = self.local(d["position"])
        spot = self.server.scene.add_icosphere(
            f"/spots/{did}", radius=self.spot_radius,
            color=STATUS_RGB.get(d["review"]["status"], STATUS_RGB["pending"]),
            subdivisions=2, cast_shadow=False, receive_shadow=False, position=pos)
        spot.on_click(lambda ev, did=did: self._on_spot_click(ev, did))
        self.spots[did] = spot
        self.spot_labels[did] = self.server.scene.add_label(
            f"/spot_labels/{did}", spot_label(d, self.class_names), position=pos + self.label_lift(d), anchor="bottom-center",
            font_screen_scale=0.8, depth_test=False)

    def _extent(self) -> float:
        """The floor's larger side in plan (metres; 10 without walls)."""
        if not self.frames:
            return 10.0
        pts = np.concatenate([rect_segments(f, 0, f.width_m, 0, f.height_m).reshape(-1, 3)
                              for f in self.frames.values()])
        return float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]), 1.0))

    def _set_initial_camera(self) -> None:
        """Look down on the whole floor from the south, slightly tilted."""
        lo, hi = np.array([-5.0, -5.0, 0.0]), np.array([5.0, 5.0, 3.0])
        if self.frames:
            pts = np.concatenate([rect_segments(f, 0, f.width_m, 0, f.height_m).reshape(-1, 3)
                                  for f in self.frames.values()]) - self.centre
            lo, hi = pts.min(axis=0), pts.max(axis=0)
        ext = float(max(hi[0] - lo[0], hi[1] - lo[1], 1.0))
        mid = (lo + hi) / 2.0
        # aim right of the middle and from high enough: the review panel covers the right of the page
        target = np.array([mid[0] + 0.2 * ext, mid[1], lo[2]])
        cam = self.server.initial_camera
        cam.look_at = tuple(target)
        cam.position = tuple(target + np.array([0.0, -0.4 * ext, 0.95 * ext]))
        cam.up = (0.0, 0.0, 1.0)

    # ------------------------------------------------------------------ review state
    def detection(self, did: str) -> dict | None:
        with self._lock:
            return self.detections.get(did)

    def apply_detection(self, det: dict) -> None:
        """Show a detection's new review state (or class) everywhere; idempotent."""
        with self._lock:
            did = det.get("id")
            old = self.detections.get(did)
            if old is None:
                return
            if (old["review"] == det["review"] and old.get("class") == det.get("class")):
                return
            if old["review"].get("version", 0) > det["review"].get("version", 0):
                return  # an older answer arriving late
            self.detections[did] = det
            spot = self.spots.get(did)
            if spot is not None:
                spot.color = STATUS_RGB.get(det["review"]["status"], STATUS_RGB["pending"])
            label = self.spot_labels.get(did)
            if label is not None:
                label.text = spot_label(det, self.class_names)
            self._refresh_status()
            sessions = list(self.sessions.values())
        for session in sessions:
            if session.selected == did:
                session.show()

    def apply_lock(self, locked: bool, signoff: dict | None) -> None:
        with self._lock:
            if locked == self.locked and signoff == self.signoff:
                return
            self.locked, self.signoff = locked, signoff
            self._refresh_status()
            sessions = list(self.sessions.values())
        for session in sessions:
            session.show()

    def apply_changes(self, ch: Changes) -> None:
        if ch.reload:
            self.rebuild()
            return
        for d in ch.detections:
            if d.get("id") not in self.detections:
                self.add_detection(d)
            self.apply_detection(d)
        self.apply_lock(ch.locked, ch.signoff)
        self._cursor = ch.cursor

    def rebuild(self) -> None:
        cursor = self.backend.changes_since(self.pid, None).cursor
        data = self.backend.project_data(self.pid)
        lod = self._scan_lod(data) if data.scans else None
        with self._lock:
            self._build_from(data, lod)
            self._cursor = cursor

    def poll_once(self) -> None:
        """Apply what changed in the backend since the last poll."""
        self.apply_changes(self.backend.changes_since(self.pid, self._cursor))

    def start_sync(self) -> None:
        if self._poller is not None or self.s.poll_s <= 0:
            return
        self._poller = threading.Thread(target=self._poll_loop, name=f"viewer-sync-{self.pid}",
                                        daemon=True)
        self._poller.start()

    def _poll_loop(self) -> None:
        while not self._stop.wait(self.s.poll_s):
            try:
                self.poll_once()
            except Exception:  # keep polling: the backend may come back
                log.exception("viewer: change feed of project %s", self.pid)
                self._stop.wait(2.0)

    def close(self) -> None:
        self._stop.set()
        if self._poller is not None:
            self._poller.join(timeout=2.0)

    def pending_after(self, did: str | None, step: int) -> str | None:
        """The next (step=+1) or previous (step=-1) pending detection after ``did``, cyclically."""
        with self._lock:
            ids = self.order
            if not ids:
                return None
            start = ids.index(did) if did in self.detections else (-1 if step > 0 else 0)
            for k in range(1, len(ids) + 1):
                cand = ids[(start + step * k) % len(ids)]
                if cand != did and self.detections[cand]["review"]["status"] == "pending":
                    return cand
            return None

    # ------------------------------------------------------------------ clients
    def _on_connect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self.last_active = time.monotonic()
            if client.client_id not in self.sessions:
                self.sessions[client.client_id] = ReviewSession(self, client, self.user_of(client))

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self.last_active = time.monotonic()
            self.sessions.pop(client.client_id, None)

    def user_of(self, client: viser.ClientHandle) -> Reviewer | None:
        """The reviewer the app signed in for this tab (its viewer cookie), if any."""
        if self.identify is None:
            return None
        try:
            return self.identify(client)
        except Exception:  # an unknown user: the tab can look, not decide
            log.exception("viewer: cannot tell who client %s is", client.client_id)
            return None

    def _on_spot_click(self, event: Any, did: str) -> None:
        session = self.sessions.get(event.client_id)
        if session is None and event.client is not None:
            self._on_connect(event.client)
            session = self.sessions.get(event.client_id)
        if session is not None:
            session.select(did)


