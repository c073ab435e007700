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

import logging
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import viser
import viser.transforms as vtf

from sbsc_core.types import WallFrame

from ..review_rules import sort_score
from ..surfaces import is_round, kind_of
from .backend import (
    Changes,
    Locked,
    ProjectData,
    ProjectId,
    ReviewBackend,
    Reviewer,
    ReviewError,
    StaleVersion,
)
from .images import WallImages, read_rgb, texture, thumbnail
from .lod import ScanLod, scan_lod

log = logging.getLogger(__name__)

STATUS_RGB: dict[str, tuple[int, int, int]] = {
    "pending": (230, 30, 30),  # the paper's red spots
    "accepted": (40, 190, 70),
    "rejected": (120, 120, 120),
}
DEPTH_ROI_RGB = (0, 255, 255)  # cyan, figure 21 a
COLOUR_ROI_RGB = (255, 0, 255)  # magenta, figure 21 a
WALL_RGB = (255, 210, 0)
OPENING_RGB = (255, 130, 0)
SELECTION_RGB = (255, 240, 0)
COLUMN_RGB = (190, 190, 196)
CEILING_RGB = (120, 200, 255)
IMAGE_MODES: tuple[str, ...] = ("colour", "depth", "off")
SCAN_LEVELS: tuple[str, ...] = ("overview", "full", "off")


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


def rect_segments(frame: WallFrame, u0: float, u1: float, v0: float, v1: float,
                  d: float = 0.0) -> np.ndarray:
    """The four sides of a (u, v) rectangle on a wall as (4, 2, 3) world segments."""
    c = frame.to_world(np.array([u0, u1, u1, u0]), np.array([v0, v0, v1, v1]), d)
    return np.stack([c, np.roll(c, -1, axis=0)], axis=1)


def plane_wxyz(frame: WallFrame) -> np.ndarray:
    """Orientation of a viser image on a wall: image x along u, image rows downwards.

    viser draws an image in its node's x-y plane with the top row towards -y (the OpenCV
    camera convention), so the node's axes are (axis_u, -axis_v, -normal).
    """
    rot = np.stack([frame.axis_u, -frame.axis_v, -frame.normal], axis=1)
    return vtf.SO3.from_matrix(rot).wxyz


@dataclass
class ScanTile:
    """Scan points of one ``tile_m`` square: float16 offsets from ``position``."""

    points: np.ndarray  # (n, 3) float16
    colors: np.ndarray  # (n, 3) uint8
    position: np.ndarray  # (3,) float64, scene coordinates
    point_size: float


def make_tiles(p: np.ndarray, c: np.ndarray, size: float, tile_m: float) -> list[ScanTile]:
    """Split points into square tiles in plan, each centred on its bounding box."""
    if len(p) == 0:
        return []
    lo = p[:, :2].min(axis=0)
    key = np.floor((p[:, :2] - lo) / tile_m).astype(np.int64)
    tile_id = key[:, 0] * 1_000_003 + key[:, 1]
    order = np.argsort(tile_id, kind="stable")
    bounds = np.flatnonzero(np.diff(tile_id[order])) + 1
    tiles = []
    for idx in np.split(order, bounds):
        tp = p[idx].astype(np.float64)
        mid = (tp.min(axis=0) + tp.max(axis=0)) / 2.0
        tiles.append(ScanTile((tp - mid).astype(np.float16), c[idx], mid, size))
    return tiles


def _fmt(x: Any, nd: int = 2) -> str:
    return "–" if x is None else f"{float(x):.{nd}f}"


def wall_label(wid: str, f: WallFrame, storey: str | None = None) -> str:
    """A wall's name in the scene: its id and width, and its storey when the id does not carry it."""
    named = f" ({storey})" if storey and not wid.startswith(f"{storey}-") else ""
    return f"{wid}{named}  {f.width_m:.2f} m"


def readable_time(iso: Any) -> str:
    """An ISO time as people read it: ``2026-11-28 12:34 UTC`` (unchanged when not ISO)."""
    import datetime as _dt

    try:
        t = _dt.datetime.fromisoformat(str(iso).replace("Z", "+00:00"))
    except ValueError:
        return str(iso)
    if t.tzinfo is not None:
        t = t.astimezone(_dt.UTC)
    return t.strftime("%Y-%m-%d %H:%M") + (" UTC" if t.tzinfo is not None else "")


def label_positions(frames: dict[str, WallFrame], gap_m: float) -> dict[str, float]:
    """Where along each wall (u, metres) its name goes: the middle, except for walls whose
    middles are closer than ``gap_m`` in plan (the two faces of a partition, walls meeting
    at a corner): each of such a group of n goes to (k + 1) / (n + 1) of its own width, in
    the order of the ids and measured the same way round on walls facing each other, so that
    seen from above the names stand apart (raising them would not separate them in a view
    from above)."""
    ids = list(frames)
    mids = {w: frames[w].to_world(frames[w].width_m / 2.0, frames[w].height_m)[:2] for w in ids}
    group = {w: w for w in ids}

    def root(w: str) -> str:
        while group[w] != w:
            w = group[w]
        return w

    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            if np.hypot(*(mids[a] - mids[b])) < gap_m:
                group[root(b)] = root(a)
    members: dict[str, list[str]] = {}
    for w in ids:
        members.setdefault(root(w), []).append(w)
    out = {}
    for ws in members.values():
        ref = frames[min(ws)].axis_u
        for k, w in enumerate(sorted(ws)):
            share = (k + 1) / (len(ws) + 1)
            if float(np.dot(frames[w].axis_u, ref)) < -0.5:  # the other face of a partition runs the other way
                share = 1.0 - share
            out[w] = frames[w].width_m * share
    return out


def spread_labels(points: dict[str, np.ndarray], gap_m: float, step_m: float) -> dict[str, np.ndarray]:
    """Label anchors lifted so that no two closer than ``gap_m`` in plan share a height:
    each one, in order, rises by ``step_m`` until no label placed before it is within
    ``gap_m`` in plan and ``step_m`` in height (short walls at a corner stack their names)."""
    placed: dict[str, np.ndarray] = {}
    for key, p in points.items():
        q = np.asarray(p, float).copy()
        while any(np.hypot(*(q[:2] - o[:2])) < gap_m and abs(q[2] - o[2]) < step_m * 0.99
                  for o in placed.values()):
            q[2] += step_m
        placed[key] = q
    return placed


def spot_label(det: dict, names: dict[str, str] | None = None) -> str:
    """An object's label: the library's name of its class (``names``, from model.json) and its score."""
    name = (names or {}).get(det["class"], det["class"])
    if det.get("confidence") is not None:
        return f"{name} {_fmt(det['confidence'])}"
    return f"{name} α {_fmt(det.get('alpha'))}"


def class_names(models_dir: Path | None) -> dict[str, str]:
    """Class id -> display name from the library's model.json files ({} when unreadable)."""
    if models_dir is None:
        return {}
    from sbsc_core.errors import SbscError
    from sbsc_core.io.models import read_library_metadata

    try:
        return {cid: str(m.get("name") or cid) for cid, m in read_library_metadata(models_dir).items()}
    except (SbscError, OSError, ValueError):
        return {}


def class_choices(ids: Iterable[str], names: dict[str, str]) -> dict[str, str]:
    """A class dropdown's options: the library's display name -> class id, in the order of ``ids``.

    A name that two classes share, or that is another class's id, gets its id in brackets,
    so every option names one class.
    """
    ids = list(ids)
    shown = [names.get(cid, cid) for cid in ids]
    taken = set(ids)
    out: dict[str, str] = {}
    for cid, label in zip(ids, shown, strict=True):
        if shown.count(label) > 1 or (label != cid and label in taken):
            label = f"{label} ({cid})"
        out[label] = cid
    return out


def wall_hit(frames: dict[str, WallFrame], origin: np.ndarray, direction: np.ndarray
             ) -> tuple[str, float, float] | None:
    """The first wall (id, u, v) a ray meets from its room side, or None."""
    best = None
    d = np.asarray(direction, float)
    for wid, f in frames.items():
        den = float(np.dot(d, f.normal))
        if den >= -1e-9:  # parallel, or seen from behind
            continue
        t = float(np.dot(f.origin - origin, f.normal)) / den
        if t <= 0 or (best is not None and t >= best[0]):
            continue
        p = origin + t * d - f.origin
        u, v = float(np.dot(p, f.axis_u)), float(np.dot(p, f.axis_v))
        if 0.0 <= u <= f.width_m and 0.0 <= v <= f.height_m:
            best = (t, wid, u, v)
    return None if best is None else best[1:]


def _ray_cylinder(centre: np.ndarray, r: float, z0: float, z1: float, origin: np.ndarray,
                  direction: np.ndarray) -> tuple[float, float, float] | None:
    """Where a ray first meets a vertical cylinder from outside: (t, u, v), u the arc length
    counter-clockwise from +x, v the height above ``z0``; None when it misses."""
    ox, oy = origin[0] - centre[0], origin[1] - centre[1]
    dx, dy = direction[0], direction[1]
    a = dx * dx + dy * dy
    if a < 1e-12:
        return None
    b = 2.0 * (ox * dx + oy * dy)
    c = ox * ox + oy * oy - r * r
    disc = b * b - 4 * a * c
    if c <= 0 or disc < 0:  # the ray starts inside, or misses
        return None
    t = (-b - np.sqrt(disc)) / (2 * a)
    if t <= 0:
        return None
    p = origin + t * direction
    if not z0 <= p[2] <= z1:
        return None
    ang = float(np.arctan2(p[1] - centre[1], p[0] - centre[0])) % (2 * np.pi)
    return float(t), ang * r, float(p[2] - z0)


def surface_hit(frames: dict[str, WallFrame], rounds: dict[str, dict], origin: np.ndarray,
                direction: np.ndarray) -> tuple[str, float, float] | None:
    """The first wall or surface (id, u, v) a ray meets from its room side, or None.

    ``frames`` are planar (walls, ceilings seen from below, a rectangular column's faces);
    ``rounds`` the round columns' surfaces (contract 4: ``radius_m``, ``centre``).
    """
    d = np.asarray(direction, float)
    o = np.asarray(origin, float)
    best: tuple[float, str, float, float] | None = None
    hit = wall_hit(frames, o, d)
    if hit is not None:
        f = frames[hit[0]]
        t = float(np.dot(f.to_world(hit[1], hit[2]) - o, d) / max(float(np.dot(d, d)), 1e-12))
        best = (t, *hit)
    for sid, sf in rounds.items():
        z0 = float(sf["origin"][2])
        got = _ray_cylinder(np.asarray(sf["centre"], float), float(sf["radius_m"]), z0,
                            z0 + float(sf["height_m"]), o, d)
        if got is not None and (best is None or got[0] < best[0]):
            best = (got[0], sid, got[1], got[2])
    return None if best is None else best[1:]


def cylinder_mesh(centre: Any, r: float, z0: float, z1: float, segments: int = 32
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A closed vertical cylinder as (vertices, triangles), faces outwards."""
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.column_stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a)])
    return prism_mesh(ring, z0, z1)


def prism_mesh(ring: np.ndarray, z0: float, z1: float) -> tuple[np.ndarray, np.ndarray]:
    """A vertical prism over a convex plan polygon (counter-clockwise) as (vertices, triangles)."""
    n = len(ring)
    v = np.concatenate([np.column_stack([ring, np.full(n, z0)]), np.column_stack([ring, np.full(n, z1)]),
                        [[*ring.mean(axis=0), z0], [*ring.mean(axis=0), z1]]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i],  # side
                  [2 * n, j, i], [2 * n + 1, n + i, n + j]]  # bottom, top
    return v.astype(np.float32), np.asarray(faces, np.uint32)


def column_meshes(surfaces: list[dict], inset_m: float = 0.003) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each column of contract 4's ``surfaces`` (kind ``column``) as a mesh: a round one as its
    cylinder, a rectangular one as the box its faces span (``inset_m`` inside them)."""
    faces: dict[str, list[dict]] = {}
    for sf in surfaces:
        if kind_of(sf) == "column":
            cid = str(sf.get("column") or sf["id"].rsplit("-", 1)[0])
            faces.setdefault(cid, []).append(sf)
    out = {}
    for cid, fs in faces.items():
        z0 = min(float(f["origin"][2]) for f in fs)
        z1 = max(float(f["origin"][2]) + float(f["height_m"]) for f in fs)
        rnd = next((f for f in fs if is_round(f)), None)
        if rnd is not None:
            out[cid] = cylinder_mesh(rnd["centre"], float(rnd["radius_m"]) - inset_m, z0, z1)
            continue
        pts = np.concatenate([[np.asarray(f["origin"], float)[:2],
                               (np.asarray(f["origin"], float) + float(f["width_m"]) * np.asarray(f["axis_u"], float))[:2]]
                              for f in fs])
        mid = pts.mean(axis=0)
        ang = np.arctan2(pts[:, 1] - mid[1], pts[:, 0] - mid[0])
        ring = pts[np.argsort(ang)]
        keep = np.concatenate([[True], np.linalg.norm(np.diff(ring, axis=0), axis=1) > 1e-3])
        ring = ring[keep]
        if len(ring) > 1 and np.linalg.norm(ring[0] - ring[-1]) <= 1e-3:
            ring = ring[:-1]
        if len(ring) < 3:
            continue
        ring = mid + (ring - mid) * (1.0 - inset_m / max(float(np.linalg.norm(ring - mid, axis=1).min()), 1e-3))
        out[cid] = prism_mesh(ring, z0, z1)
    return out


def wrapped_cylinder(img: np.ndarray, sf: dict, pixel_m: float, offset_m: float, segments: int = 64) -> Any:
    """A round column's unrolled orthoimage wrapped back round it: a textured ``trimesh.Trimesh``
    (seen from outside only), in world coordinates. The image's column c is at the arc length
    ``(c + 0.5) * pixel_m`` counter-clockwise from +x, its rows from the top (contract 4)."""
    import trimesh
    from PIL import Image

    r = float(sf["radius_m"]) + offset_m
    cx, cy = (float(c) for c in sf["centre"])
    z0 = float(sf["origin"][2])
    circ = 2 * np.pi * float(sf["radius_m"])
    w_m, h_m = img.shape[1] * pixel_m, img.shape[0] * pixel_m
    top = z0 + float(sf["height_m"])
    a = np.linspace(0.0, 2 * np.pi, segments + 1)
    ring = np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a)])
    n = segments + 1
    verts = np.concatenate([np.column_stack([ring, np.full(n, top - h_m)]), np.column_stack([ring, np.full(n, top)])])
    u = (a / (2 * np.pi)) * circ / w_m  # the image may be longer than the circumference (its seam repeated)
    uv = np.concatenate([np.column_stack([u, np.zeros(n)]), np.column_stack([u, np.ones(n)])])
    faces = []
    for k in range(segments):
        faces += [[k, k + 1, n + k + 1], [k, n + k + 1, n + k]]  # outwards
    material = trimesh.visual.material.PBRMaterial(  # matte, not metallic (glTF's default is metallic)
        baseColorTexture=Image.fromarray(np.ascontiguousarray(img)), metallicFactor=0.0, roughnessFactor=1.0)
    visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    return trimesh.Trimesh(verts, np.asarray(faces), visual=visual, process=False)


def surface_text(wid: str | None, sf: dict | None) -> str:
    """Where an object is, in words: on a wall, a ceiling seen from below, a column's face."""
    if sf is None or kind_of(sf) == "wall":
        return f"wall {wid}"
    if kind_of(sf) == "ceiling":
        return f"ceiling {wid} (seen from below)"
    col = sf.get("column") or wid
    if is_round(sf):
        return f"round column {col} (unrolled)"
    return f"column {col}, face {wid}"


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
