"""What a real terrestrial laser scanner adds to a perfect ray cast (``sbsc simulate --realistic``).

Each effect is a small function with physical parameters (:class:`ScanEffects`); the
defaults are those published for phase-based scanners of the Faro Focus3D / Z+F Imager
5010 class, never values tuned to our detector:

* **range noise** (:func:`range_sigma`) growing with range, with the incidence angle and
  on dark surfaces: ``sigma = sqrt(s0^2 + (s10 r / 10 m)^2) * sqrt(rho_ref / rho) / cos(a)``
  (Soudarissanane et al. 2011 for the 1/cos term; Z+F 5010 data sheet: 0.4-1.6 mm rms at
  10 m for 80-14 % reflectance, so ``s10`` = 1.5 mm at ``rho_ref`` = 0.5 is mid-range);
* **mixed pixels** (:func:`mix_edges`): where the beam footprint (exit diameter 3.5 mm,
  divergence 0.3 mrad) straddles a depth edge, the phase-based range is a blend of the
  fore- and background ranges, so points float between the two surfaces;
* **dropouts** (:func:`return_probability`): the returned signal falls with reflectance,
  cos(incidence) and 1/r^2; glossy surfaces mirror the beam away at oblique incidence;
* **registration error** (:func:`station_pose_error`): every station but the first is
  off by a small rigid motion (target-based registration: ~2 mm, ~0.005 deg per axis);
* **per-station exposure and white balance** (:func:`camera_response`): an exposure
  offset in EV and a colour temperature in kelvin per panorama, applied in linear light;
* **specular highlights** (:func:`highlight`): a Phong lobe of the room light (a
  luminaire ``light_height_m`` above the station) on glossy surfaces (``tri_gloss``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

# Gloss (0 matte .. 1 mirror) of the classes' surfaces: painted steel, plastics, glass.
CLASS_GLOSS: dict[str, float] = {
    "electrical_panel": 0.3, "socket_x1": 0.2, "socket_x2": 0.2, "socket_x4": 0.2,
    "builtin_socket": 0.2, "switch": 0.2, "fire_extinguisher": 0.7, "radiator": 0.4,
    "fire_alarm_switch": 0.4, "smoke_detector": 0.15, "exit_light": 0.4,
    "extinguisher_sign": 0.35, "fire_alarm_switch_sign": 0.35,
}


@dataclass(frozen=True)
class ScanEffects:
    """Parameters of the realistic scanner, in physical units (see the module doc)."""

    range_noise_floor_m: float = 0.0005  # range noise at zero range
    range_noise_10m_m: float = 0.0015  # range-proportional part, 1 sigma at 10 m
    reference_reflectance: float = 0.5  # reflectance the two figures above are quoted for
    max_incidence_deg: float = 84.0  # 1/cos(a) is capped at this angle
    beam_exit_diameter_m: float = 0.0035
    beam_divergence_rad: float = 0.0003
    mixed_min_jump_m: float = 0.005  # range jumps smaller than this are no edge
    min_reflectance: float = 0.004  # signal (rho cos(a) (10 m / r)^2) giving 1/e return probability
    specular_dropout: float = 0.5  # glossy surfaces: drop probability gloss * this * (1 - cos(a))
    registration_translation_m: float = 0.002  # 1 sigma per axis, every station but the first
    registration_rotation_deg: float = 0.005  # 1 sigma per axis
    exposure_sigma_ev: float = 0.3  # per-station exposure offset
    white_balance_k: float = 5000.0  # mean colour temperature the camera assumes
    white_balance_sigma_k: float = 400.0  # per-station spread of the actual light's temperature
    highlight_strength: float = 0.6  # peak highlight (fraction of full scale) at gloss 1
    highlight_exponent: float = 30.0  # Phong exponent of the lobe
    light_height_m: float = 1.4  # the room light sits this far above the station

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"{f.name} must be a finite number >= 0, got {v}")
        if not 0 < self.reference_reflectance <= 1 or not 0 < self.max_incidence_deg < 90:
            raise ValueError("need 0 < reference_reflectance <= 1 and 0 < max_incidence_deg < 90")
        if self.white_balance_k < 1000:
            raise ValueError("white_balance_k must be at least 1000 K")

    @staticmethod
    def none() -> ScanEffects:
        """Every effect off (a perfect scanner apart from ``ScannerSettings`` noise)."""
        return ScanEffects(**{f.name: 0.0 for f in fields(ScanEffects)
                              if f.name not in ("reference_reflectance", "max_incidence_deg",
                                                "white_balance_k", "highlight_exponent")})


def srgb_to_linear(rgb: np.ndarray) -> np.ndarray:
    """8-bit sRGB to linear light 0..1 (IEC 61966-2-1)."""
    c = np.asarray(rgb, np.float32) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(lin: np.ndarray) -> np.ndarray:
    """Linear light (clipped to 0..1) to float sRGB levels 0..255."""
    c = np.clip(lin, 0.0, 1.0)
    return (255.0 * np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)).astype(np.float32)


def reflectance(rgb: np.ndarray) -> np.ndarray:
    """Diffuse reflectance of a surface from its colour: the linear luminance (Rec. 709)."""
    lin = srgb_to_linear(rgb)
    return lin @ np.array([0.2126, 0.7152, 0.0722], np.float32)


def range_sigma(r: np.ndarray, cos_inc: np.ndarray, rho: np.ndarray, e: ScanEffects) -> np.ndarray:
    """1-sigma range noise (m) at range ``r`` (m), |cos(incidence)| and reflectance ``rho``."""
    base = np.sqrt(e.range_noise_floor_m ** 2 + (e.range_noise_10m_m * np.asarray(r, np.float32) / 10.0) ** 2)
    dark = np.sqrt(e.reference_reflectance / np.clip(rho, 0.01, 1.0))
    c = np.maximum(np.abs(cos_inc), math.cos(math.radians(e.max_incidence_deg)))
    return (base * dark / c).astype(np.float32)


def return_probability(r: np.ndarray, cos_inc: np.ndarray, rho: np.ndarray, gloss: np.ndarray,
                       e: ScanEffects) -> np.ndarray:
    """Probability that a ray gives a point: weak signal on dark, far, oblique or glossy surfaces."""
    if e.min_reflectance <= 0 and e.specular_dropout <= 0:
        return np.ones(len(r), np.float32)
    c = np.abs(cos_inc)
    signal = rho * c * (10.0 / np.maximum(r, 0.1)) ** 2
    p = 1.0 - np.exp(-signal / e.min_reflectance) if e.min_reflectance > 0 else np.ones_like(signal)
    p = p * (1.0 - np.clip(gloss * e.specular_dropout * (1.0 - c), 0.0, 1.0))
    return p.astype(np.float32)


def mix_edges(t: np.ndarray, rgb: np.ndarray, dirs: np.ndarray, normals: np.ndarray, step_rad: float,
              *, e: ScanEffects, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mixed pixels on a sweep grid: ``t`` (n_az, n_el) ranges (inf = miss), ``rgb``, ``dirs``
    (unit ray directions) and ``normals`` (of the hit surfaces) (n_az, n_el, 3).

    A ray next to a depth edge (a grid neighbour whose point lies more than
    ``mixed_min_jump_m`` off the plane of this ray's surface, so a slanted wall is no edge)
    straddles the edge with probability ``D / (2 g)``: the footprint diameter
    ``D = exit + r * divergence`` over the grid spacing ``g = r * step``. Its footprint then
    covers a share ``w`` (0..0.5) of the other surface and the phase-based range and the
    colour are the blend ``(1 - w) own + w other``. Returns new ranges, colours and the mask
    of mixed rays.
    """
    t = np.asarray(t, np.float32)
    out_t, out_rgb = t.copy(), np.asarray(rgb, np.float32).copy()
    mixed = np.zeros(t.shape, bool)
    if e.beam_exit_diameter_m <= 0 and e.beam_divergence_rad <= 0:
        return out_t, out_rgb, mixed
    best = np.zeros(t.shape, np.float32)  # largest jump to a neighbour so far
    other_t = np.full(t.shape, np.inf, np.float32)
    other_rgb = np.zeros(out_rgb.shape, np.float32)
    finite = np.isfinite(t)
    pts = np.where(finite[..., None], np.where(finite, t, 0.0)[..., None] * dirs, 0.0).astype(np.float32)
    for axis in (0, 1):
        for shift in (1, -1):
            nb_t = np.roll(t, shift, axis=axis)
            nb_rgb = np.roll(out_rgb, shift, axis=axis)
            valid = finite & np.isfinite(nb_t)
            edge = [slice(None), slice(None)]
            edge[axis] = 0 if shift == 1 else -1  # np.roll wraps: the wrapped row is no neighbour
            valid[tuple(edge)] = False
            off_plane = np.abs(np.einsum("ijk,ijk->ij", np.roll(pts, shift, axis=axis) - pts, normals))
            jump = np.where(valid, off_plane, 0.0)
            take = jump > np.maximum(best, e.mixed_min_jump_m)
            best[take] = jump[take]
            other_t[take] = nb_t[take]
            other_rgb[take] = nb_rgb[take]
    cand = np.nonzero(best > 0)
    if not len(cand[0]):
        return out_t, out_rgb, mixed
    r = t[cand]
    footprint = e.beam_exit_diameter_m + r * e.beam_divergence_rad
    p = np.clip(footprint / (2.0 * np.maximum(r * step_rad, 1e-6)), 0.0, 1.0)
    x = rng.random(len(r), dtype=np.float32)
    hit = x < p  # the edge lies within D/2 of the beam axis
    w = 0.5 * (1.0 - x / np.maximum(p, 1e-9))  # footprint share on the other surface, 0..0.5
    sel = tuple(c[hit] for c in cand)
    w = w[hit].astype(np.float32)
    out_t[sel] = (1 - w) * t[sel] + w * other_t[sel]
    out_rgb[sel] = (1 - w)[:, None] * out_rgb[sel] + w[:, None] * other_rgb[sel]
    mixed[sel] = True
    return out_t, out_rgb, mixed


def _rotation_xyz(angles_rad: np.ndarray) -> np.ndarray:
    ax, ay, az = angles_rad
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def station_pose_error(seed: int, station: int, e: ScanEffects) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of station ``station``'s registration error; the first station is the reference.

    A scan point ``p`` of the station is written as ``o + R (p - o) + t`` (``o`` its origin).
    """
    if station == 0 or (e.registration_rotation_deg <= 0 and e.registration_translation_m <= 0):
        return np.eye(3), np.zeros(3)
    g = np.random.default_rng([int(seed), int(station), 0x5E61])
    angles = g.normal(0.0, math.radians(e.registration_rotation_deg), 3)
    shift = g.normal(0.0, e.registration_translation_m, 3)
    return _rotation_xyz(angles), shift


def pose_error_record(station: int, rotation: np.ndarray, shift: np.ndarray) -> dict:
    """The ground truth's record of a station's registration error (:func:`station_pose_error`):
    its translation (m) and the angle of its rotation (degrees), rounded to 6 decimals."""
    angle = math.degrees(math.acos(min(1.0, (float(np.trace(rotation)) - 1) / 2)))
    return {"station": station, "translation_m": [round(float(x), 6) for x in shift],
            "rotation_deg": round(angle, 6)}


def _blackbody_rgb(kelvin: float) -> np.ndarray:
    """Linear RGB of a black body at ``kelvin`` (Tanner Helland's fit of the CIE data), max 1."""
    t = kelvin / 100.0
    r = 255.0 if t <= 66 else 329.698727446 * (t - 60) ** -0.1332047592
    g = 99.4708025861 * math.log(t) - 161.1195681661 if t <= 66 else 288.1221695283 * (t - 60) ** -0.0755148492
    b = 255.0 if t >= 66 else (0.0 if t <= 19 else 138.5177312231 * math.log(t - 10) - 305.0447927307)
    c = srgb_to_linear(np.clip([r, g, b], 1, 255))
    return c / c.max()


def station_camera(seed: int, station: int, e: ScanEffects) -> tuple[float, np.ndarray]:
    """(exposure gain, per-channel white-balance gains) of one station's panorama."""
    g = np.random.default_rng([int(seed), int(station), 0xCA3E])
    ev = g.normal(0.0, e.exposure_sigma_ev) if e.exposure_sigma_ev > 0 else 0.0
    kelvin = e.white_balance_k + (g.normal(0.0, e.white_balance_sigma_k) if e.white_balance_sigma_k > 0 else 0.0)
    wb = _blackbody_rgb(max(1500.0, kelvin)) / _blackbody_rgb(e.white_balance_k)
    return float(2.0 ** ev), (wb / wb.mean()).astype(np.float32)


def camera_response(rgb: np.ndarray, exposure: float, wb: np.ndarray) -> np.ndarray:
    """Surface colour (8-bit sRGB) as the station's camera records it (float levels, clipped)."""
    return linear_to_srgb(srgb_to_linear(rgb) * np.float32(exposure) * wb[None, :].astype(np.float32))


def highlight(points: np.ndarray, normals: np.ndarray, origin: np.ndarray, gloss: np.ndarray,
              e: ScanEffects) -> np.ndarray:
    """Specular highlight (0..1 of full scale) seen from ``origin`` of a light above it (Phong)."""
    if e.highlight_strength <= 0 or not np.any(gloss > 0):
        return np.zeros(len(points), np.float32)
    light = np.asarray(origin, np.float32) + np.array([0, 0, e.light_height_m], np.float32)
    to_cam = np.asarray(origin, np.float32) - points
    to_cam /= np.maximum(np.linalg.norm(to_cam, axis=1, keepdims=True), 1e-6)
    to_light = light - points
    to_light /= np.maximum(np.linalg.norm(to_light, axis=1, keepdims=True), 1e-6)
    n = normals * np.sign(np.einsum("ij,ij->i", normals, to_cam))[:, None]  # the face the camera sees
    refl = 2.0 * np.einsum("ij,ij->i", n, to_light)[:, None] * n - to_light
    lobe = np.clip(np.einsum("ij,ij->i", refl, to_cam), 0.0, 1.0) ** e.highlight_exponent
    return (e.highlight_strength * gloss * lobe).astype(np.float32)
