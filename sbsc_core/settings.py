"""Every threshold of the method, named, in one settings object.

The paper's values are the defaults (mu_D = 0.75, mu_C = 0.2, 5 mm pixels, ...).
Each stage reads only its own section. ``DetectionSettings.from_dict`` accepts a nested
dict (e.g. loaded from JSON/YAML) and refuses unknown keys.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import yaml

from .errors import InputError


@dataclass
class SegmentationSettings:
    """Floor, ceiling and walls (paper, section 3.1)."""

    z_bin_m: float = 0.02  # Z histogram bin for the floor / ceiling maxima
    slab_margin_m: float = 0.08  # points this close to floor / ceiling are not wall points
    xy_cell_m: float = 0.02  # XY grid cell for the wall projection image
    wall_plane_tolerance_m: float = 0.04  # points within this of a wall plane belong to it
    min_wall_length_m: float = 0.5
    min_wall_height_fraction: float = 0.5  # of the floor-to-ceiling height
    object_depth_m: float = 0.30  # wall points include objects standing out this far


@dataclass
class OrthoimageSettings:
    """The 4D orthoimage J_CD (paper, section 3.2)."""

    pixel_m: float = 0.005
    depth_range_m: tuple[float, float] = (-0.06, 0.30)  # kept signed distances from the plane


@dataclass
class ColourPrepSettings:
    """Illumination equalisation and highlight restoration (paper, section 3.2)."""

    illumination_sigma_m: float = 0.25  # scale of the smooth illumination field
    highlight_value: float = 0.92  # HSV value above which a pixel may be a highlight
    highlight_saturation: float = 0.12


@dataclass
class WallAreaSettings:
    """Visible wall area and openings (paper, section 3.3)."""

    seed_window_px: int = 15
    colour_tolerance: float = 18.0  # Lab distance to the wall colour still counted as wall
    door_width_m: tuple[float, float] = (0.6, 2.2)
    door_height_m: tuple[float, float] = (1.8, 2.6)
    window_width_m: tuple[float, float] = (0.4, 3.5)
    window_height_m: tuple[float, float] = (0.4, 2.2)


@dataclass
class DepthRecognitionSettings:
    """Recognition with geometry (paper, section 4.2)."""

    mu_d: float = 0.75  # cross-correlation threshold
    min_relief_m: float = 0.004  # depth step treated as an edge
    roi_min_px: int = 6
    roi_merge_overlap: float = 0.0  # RoIs overlapping by more than this are clustered
    search_margin_px: int = 6  # extra pixels around a RoI searched by the correlation


@dataclass
class ColourRecognitionSettings:
    """Recognition with colour (paper, section 4.3)."""

    mu_c: float = 0.2  # minimum-distance classifier threshold (normalised descriptors)
    threshold_offset: float = 25.0  # intensity offset from the wall area's mean
    roi_min_px: int = 6
    glcm_levels: int = 8


@dataclass
class ConsensusSettings:
    """Consensus of depth and colour candidates (paper, section 4.4)."""

    exclusive_alpha: float = 0.5  # equation 15, case III
    min_alpha: float = 0.0  # cells at or below this are never selected
    suppress_overlap: float = 0.5  # cross-class suppression: max overlap of two accepted objects


@dataclass
class DetectionSettings:
    segmentation: SegmentationSettings = field(default_factory=SegmentationSettings)
    orthoimage: OrthoimageSettings = field(default_factory=OrthoimageSettings)
    colour_prep: ColourPrepSettings = field(default_factory=ColourPrepSettings)
    wall_area: WallAreaSettings = field(default_factory=WallAreaSettings)
    depth: DepthRecognitionSettings = field(default_factory=DepthRecognitionSettings)
    colour: ColourRecognitionSettings = field(default_factory=ColourRecognitionSettings)
    consensus: ConsensusSettings = field(default_factory=ConsensusSettings)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "settings") -> DetectionSettings:
        return _build(cls, data, where)


def _build(kind: type, data: dict[str, Any], where: str) -> Any:
    if not isinstance(data, dict):
        raise InputError(where, "expected a mapping")
    known = {f.name: f for f in fields(kind)}
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key not in known:
            raise InputError(f"{where}.{key}", "unknown setting")
        default = getattr(kind(), key)
        if is_dataclass(default):
            kwargs[key] = _build(type(default), value, f"{where}.{key}")
        elif isinstance(default, tuple):
            kwargs[key] = tuple(value)
        else:
            kwargs[key] = type(default)(value)
    return kind(**kwargs)


def load_settings(path: Path | None) -> DetectionSettings:
    """Read a JSON or YAML settings override file (nested like ``DetectionSettings``)."""
    if path is None:
        return DetectionSettings()
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise InputError(path, f"cannot read settings: {str(exc).splitlines()[0]}") from None
    return DetectionSettings.from_dict(data or {}, where=Path(path).name)
