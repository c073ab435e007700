"""A virtual terrestrial laser scanner (the paper scanned its virtual floor with Blensor).

Each station sweeps a regular spherical grid like a Riegl VZ-400: azimuth all around,
elevation from ``elevation_min_deg`` to ``elevation_max_deg`` (+60 / -40 degrees), one ray
per ``angular_step_deg`` in both directions. Rays are cast against the building mesh
(:class:`~sbsc_core.simulate.raycast.MeshRaycaster`), so occlusion comes for free. A return
is lost beyond ``max_range_m`` or nearer than ``min_range_m``, when the beam grazes the
surface (``grazing_cos``) and at random (``drop_fraction``). The range gets gaussian noise
along the ray; the colour (from the scanner's camera) gets a per-station gain, tint and
offset, a smooth brightness change around the panorama and gaussian noise. The stations
share one world frame, so merging is concatenation.

With ``effects`` (:class:`~sbsc_core.simulate.realism.ScanEffects`) the sweep also gets
what a real scanner adds: range noise growing with range, incidence and darkness (in place
of the constant ``range_sigma_m``), mixed pixels at depth edges, dropouts on dark or glossy
surfaces, a registration error per station, per-station exposure and white balance and
specular highlights. Without it the output is exactly that of the plain scanner.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields

import numpy as np

from .mesh import ColouredMesh
from .raycast import MeshRaycaster
from .realism import (
    ScanEffects,
    camera_response,
    highlight,
    mix_edges,
    range_sigma,
    reflectance,
    return_probability,
    station_camera,
    station_pose_error,
)

BLOCK_COLUMNS = 16  # azimuth columns sharing one noise generator


@dataclass(frozen=True)
class ScannerSettings:
    """Every parameter of the virtual scanner (all numbers, so a description can set them)."""

    angular_step_deg: float = 0.1  # a Riegl VZ-400 can go down to 0.0024 degrees
    elevation_min_deg: float = -40.0
    elevation_max_deg: float = 60.0
    height_m: float = 1.5  # default station height above the floor
    min_range_m: float = 0.5
    max_range_m: float = 100.0
    range_sigma_m: float = 0.0025  # gaussian range noise along the ray
    colour_sigma: float = 3.0  # gaussian colour noise, 8-bit levels per channel
    gain_sigma: float = 0.04  # per-station brightness gain ~ N(1, gain_sigma)
    tint_sigma: float = 0.015  # per-station, per-channel gain on top of it
    offset_sigma: float = 3.0  # per-station, per-channel offset in levels
    gradient_amplitude: float = 0.05  # smooth brightness change around each panorama
    drop_fraction: float = 0.002  # returns lost at random
    grazing_cos: float = 0.04  # returns with |cos(incidence)| below this are lost
    station_spacing_m: float = 4.5  # planner: about one station per this many metres of room
    chunk_rays: float = 400_000  # rays cast at once (small chunks stay in the CPU cache)

    def __post_init__(self) -> None:
        if not 0.005 <= self.angular_step_deg <= 5.0:
            raise ValueError(f"angular_step_deg {self.angular_step_deg} is outside 0.005..5")
        if not -90.0 <= self.elevation_min_deg < self.elevation_max_deg <= 90.0:
            raise ValueError("need -90 <= elevation_min_deg < elevation_max_deg <= 90")
        if not 0.0 <= self.min_range_m < self.max_range_m:
            raise ValueError("need 0 <= min_range_m < max_range_m")
        for f in fields(self):
            if getattr(self, f.name) < 0 and f.name not in ("elevation_min_deg", "elevation_max_deg"):
                raise ValueError(f"{f.name} must not be negative")
        if not 0.0 <= self.drop_fraction < 1.0:
            raise ValueError("drop_fraction must be in 0..1")
        if self.station_spacing_m <= 0.5 or self.chunk_rays < 1000:
            raise ValueError("station_spacing_m must exceed 0.5 and chunk_rays 1000")

    def replace(self, **changes: float) -> ScannerSettings:
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values.update(changes)
        return ScannerSettings(**values)


@dataclass
class Scan:
    """A merged scan: float32 world points, 8-bit colours, optionally what each ray hit."""

    xyz: np.ndarray  # (N, 3) float32
    rgb: np.ndarray  # (N, 3) uint8
    station: np.ndarray | None  # (N,) uint16 station of each point (``keep_station``)
    label: np.ndarray | None  # (N,) int32 mesh tri_label (object index, -1 building)
    stations: np.ndarray  # (S, 3) float64 station origins
    rays: int  # rays cast in all
    pose_errors: list[tuple[np.ndarray, np.ndarray]] | None = None  # per station (R, t), with effects

    def __len__(self) -> int:
        return int(len(self.xyz))


def angular_grid(settings: ScannerSettings, azimuth_offset: float = 0.0,
                 elevation_offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Azimuths (all around) and elevations (the vertical field) of one station, radians."""
    step = math.radians(settings.angular_step_deg)
    n_az = int(round(2 * math.pi / step))
    az = azimuth_offset + np.arange(n_az, dtype=np.float64) * (2 * math.pi / n_az)
    lo, hi = math.radians(settings.elevation_min_deg), math.radians(settings.elevation_max_deg)
    el = lo + elevation_offset * step + np.arange(int(math.floor((hi - lo) / step)) + 1) * step
    return az, el[el <= hi + 1e-12]


def scan_mesh(mesh: ColouredMesh, stations: Sequence[Sequence[float]], settings: ScannerSettings, *,
              seed: int = 0, keep_labels: bool = False, keep_station: bool = False,
              log: Callable[[str], None] | None = None,
              raycaster: MeshRaycaster | None = None, effects: ScanEffects | None = None) -> Scan:
    """Scan ``mesh`` from every station and merge the points (one world frame).

    Deterministic for a seed: station ``k`` draws its illumination from
    ``default_rng([seed, k])`` and the noise of each block of ``BLOCK_COLUMNS`` azimuth
    columns from ``default_rng([seed, k, block])``, so the chunk size does not matter.
    """
    rc = raycaster or MeshRaycaster(mesh, chunk=int(settings.chunk_rays))
    xyz_parts: list[np.ndarray] = []
    rgb_parts: list[np.ndarray] = []
    st_parts: list[np.ndarray] = []
    lab_parts: list[np.ndarray] = []
    rays = 0
    origins = np.asarray(stations, float).reshape(-1, 3)
    for k, origin in enumerate(origins):
        xyz, rgb, lab, n = scan_station(rc, origin, settings, seed, k, keep_labels=keep_labels, effects=effects)
        rays += n
        xyz_parts.append(xyz)
        rgb_parts.append(rgb)
        if keep_station:
            st_parts.append(np.full(len(xyz), k, np.uint16))
        if keep_labels:
            lab_parts.append(lab)
        if log:
            log(f"station {k + 1}/{len(origins)} at ({origin[0]:.2f}, {origin[1]:.2f}, {origin[2]:.2f}): "
                f"{len(xyz):,} points")
    xyz = np.concatenate(xyz_parts) if xyz_parts else np.zeros((0, 3), np.float32)
    del xyz_parts
    rgb = np.concatenate(rgb_parts) if rgb_parts else np.zeros((0, 3), np.uint8)
    del rgb_parts
    return Scan(xyz, rgb, (np.concatenate(st_parts) if st_parts else np.zeros(0, np.uint16)) if keep_station else None,
                (np.concatenate(lab_parts) if lab_parts else np.zeros(0, np.int32)) if keep_labels else None,
                origins, rays,
                [station_pose_error(seed, k, effects) for k in range(len(origins))] if effects else None)


def scan_station(rc: MeshRaycaster, origin: np.ndarray, settings: ScannerSettings,
                 seed: int = 0, station: int = 0, *, keep_labels: bool = False,
                 effects: ScanEffects | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, int]:
    """One station's sweep: (xyz float32, rgb uint8, labels or None, rays cast)."""
    s = settings
    e = effects
    rng = np.random.default_rng([int(seed), int(station)])
    az, el = angular_grid(s, azimuth_offset=rng.uniform(0, 2 * math.pi), elevation_offset=rng.uniform(0, 1))
    # per-station illumination of the colour camera
    gain = rng.normal(1.0, s.gain_sigma) * rng.normal(1.0, s.tint_sigma, 3)
    offset = rng.normal(0.0, s.offset_sigma, 3)
    light_dir = rng.uniform(0, 2 * math.pi)
    if e is not None:
        exposure, wb = station_camera(seed, station, e)
    gain32, offset32 = gain.astype(np.float32), offset.astype(np.float32)
    cos_el, sin_el = np.cos(el).astype(np.float32), np.sin(el).astype(np.float32)
    origin32 = np.asarray(origin, np.float32)
    per_chunk = max(1, int(s.chunk_rays) // (len(el) * BLOCK_COLUMNS)) * BLOCK_COLUMNS
    out_xyz, out_rgb, out_lab = [], [], []
    for a0 in range(0, len(az), per_chunk):
        a = az[a0:a0 + per_chunk]
        ca, sa = np.cos(a).astype(np.float32), np.sin(a).astype(np.float32)
        dirs = np.empty((len(a), len(el), 3), np.float32)
        dirs[..., 0] = ca[:, None] * cos_el[None, :]
        dirs[..., 1] = sa[:, None] * cos_el[None, :]
        dirs[..., 2] = sin_el[None, :]
        dirs = dirs.reshape(-1, 3)
        hits = rc.cast(origin32, dirs)
        t = hits.t
        cos_inc = np.einsum("ij,ij->i", dirs, hits.normal)
        surface = hits.rgb
        if e is not None:
            g_eff = np.random.default_rng([int(seed), int(station), a0, 0xE1])
            grid = (len(a), len(el))
            mt, mrgb, _ = mix_edges(t.reshape(grid), surface.reshape(*grid, 3), dirs.reshape(*grid, 3),
                                    hits.normal.reshape(*grid, 3), math.radians(s.angular_step_deg),
                                    e=e, rng=g_eff)
            t, surface = mt.ravel(), mrgb.reshape(-1, 3)
        keep = np.isfinite(t) & (t >= s.min_range_m) & (t <= s.max_range_m)
        keep &= np.abs(cos_inc) >= s.grazing_cos
        if e is not None:
            gloss = np.zeros(len(t), np.float32)
            gloss[hits.hit] = rc.mesh.tri_gloss[hits.triangle[hits.hit]]
            rho = reflectance(hits.rgb)
            k_idx = np.nonzero(keep)[0]
            p = return_probability(t[k_idx], cos_inc[k_idx], rho[k_idx], gloss[k_idx], e)
            keep[k_idx[g_eff.random(len(k_idx), dtype=np.float32) >= p]] = False
        idx, t_noise, c_noise = _block_noise(np.nonzero(keep)[0], a0, len(el), s.drop_fraction,
                                             (int(seed), int(station)))
        if e is None:
            t = t[idx] + np.float32(s.range_sigma_m) * t_noise
        else:
            t = t[idx] + range_sigma(t[idx], cos_inc[idx], rho[idx], e) * t_noise
        out_xyz.append(origin32 + t[:, None] * dirs[idx])
        # colour: per-station gain / offset, smooth brightness around the panorama, noise
        column_gain = (1.0 + s.gradient_amplitude * np.cos(a - light_dir)).astype(np.float32)
        shade = column_gain[idx // len(el)][:, None] * gain32[None, :]
        if e is None:
            col = surface[idx].astype(np.float32)
        else:
            col = camera_response(surface[idx], exposure, wb)
            col += 255.0 * highlight(out_xyz[-1], hits.normal[idx], origin32, gloss[idx], e)[:, None]
        col *= shade
        col += offset32
        col += np.float32(s.colour_sigma) * c_noise
        np.rint(col, out=col)
        np.clip(col, 0, 255, out=col)
        out_rgb.append(col.astype(np.uint8))
        if keep_labels:
            out_lab.append(hits.label[idx])
    xyz = np.concatenate(out_xyz) if out_xyz else np.zeros((0, 3), np.float32)
    if e is not None:
        rot, shift = station_pose_error(seed, station, e)
        xyz = (origin32 + (xyz - origin32) @ rot.T.astype(np.float32) + shift.astype(np.float32)).astype(np.float32)
    rgb = np.concatenate(out_rgb) if out_rgb else np.zeros((0, 3), np.uint8)
    lab = (np.concatenate(out_lab) if out_lab else np.zeros(0, np.int32)) if keep_labels else None
    return xyz, rgb, lab, len(az) * len(el)


def _block_noise(idx: np.ndarray, first_column: int, n_el: int, drop_fraction: float,
                 key: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random drops, unit range noise and unit colour noise for the hit rays ``idx``.

    Each block of ``BLOCK_COLUMNS`` azimuth columns has its own generator, so the values
    do not depend on how the sweep is cut into chunks.
    """
    if not len(idx):
        return idx, np.zeros(0, np.float32), np.zeros((0, 3), np.float32)
    block = (first_column + idx // n_el) // BLOCK_COLUMNS
    cuts = np.flatnonzero(np.diff(block)) + 1
    kept, t_noise, c_noise = [], [], []
    for sub, b in zip(np.split(idx, cuts), block[np.r_[0, cuts]], strict=True):
        g = np.random.default_rng([*key, int(b)])
        if drop_fraction > 0:
            sub = sub[g.random(len(sub), dtype=np.float32) >= drop_fraction]
        kept.append(sub)
        t_noise.append(g.standard_normal(len(sub), dtype=np.float32))
        c_noise.append(g.standard_normal((len(sub), 3), dtype=np.float32))
    return np.concatenate(kept), np.concatenate(t_noise), np.concatenate(c_noise)


@dataclass
class WallView:
    """A scan seen straight on through one wall frame: mean colour and depth per pixel."""

    colour: np.ndarray  # (H, W, 3) uint8, 0 where no point
    depth: np.ndarray  # (H, W) float32 metres from the wall plane (into the room), NaN where no point
    count: np.ndarray  # (H, W) int32 points per pixel
    pixel_m: float

    def uv_to_pixel(self, u: float, v: float) -> tuple[int, int]:
        """(row, col) of the pixel holding wall coordinates (u, v); row 0 is the top."""
        h = self.depth.shape[0]
        return int(h - 1 - math.floor(v / self.pixel_m)), int(math.floor(u / self.pixel_m))


def wall_view(xyz: np.ndarray, rgb: np.ndarray, frame, *, pixel_m: float = 0.005,
              depth_range_m: tuple[float, float] = (-0.05, 0.3), chunk: int = 5_000_000) -> WallView:
    """Bin the points within ``depth_range_m`` of a wall's plane into an orthographic view.

    Row 0 is the top of the wall (contract of :class:`~sbsc_core.types.Orthoimage`); a
    pixel's value is the mean of its points. Works through the cloud in chunks, so it is
    usable on a whole floor.
    """
    h = int(math.ceil(frame.height_m / pixel_m - 1e-9))
    w = int(math.ceil(frame.width_m / pixel_m - 1e-9))
    basis = np.stack([frame.axis_u, frame.axis_v, frame.normal], axis=1).astype(np.float32)
    origin = np.asarray(frame.origin, np.float32)
    count = np.zeros(h * w, np.int64)
    sums = np.zeros((h * w, 4), np.float64)
    normal = basis[:, 2]
    for s in range(0, len(xyz), chunk):
        rel = np.asarray(xyz[s:s + chunk], np.float32) - origin
        d = rel @ normal
        sel = np.nonzero((d >= depth_range_m[0]) & (d <= depth_range_m[1]))[0]
        uv = rel[sel] @ basis[:, :2]
        c = np.floor(uv[:, 0] / pixel_m).astype(np.int64)
        r = h - 1 - np.floor(uv[:, 1] / pixel_m).astype(np.int64)
        ok = (c >= 0) & (c < w) & (r >= 0) & (r < h)
        if not ok.any():
            continue
        flat = r[ok] * w + c[ok]
        count += np.bincount(flat, minlength=h * w)
        pts = sel[ok]
        for k in range(3):
            sums[:, k] += np.bincount(flat, weights=np.asarray(rgb[s:s + chunk])[pts, k], minlength=h * w)
        sums[:, 3] += np.bincount(flat, weights=d[pts], minlength=h * w)
    has = count > 0
    mean = np.zeros_like(sums)
    mean[has] = sums[has] / count[has, None]
    colour = np.clip(np.rint(mean[:, :3]), 0, 255).astype(np.uint8).reshape(h, w, 3)
    depth = np.where(has, mean[:, 3], np.nan).astype(np.float32).reshape(h, w)
    return WallView(colour, depth, count.reshape(h, w).astype(np.int32), float(pixel_m))
