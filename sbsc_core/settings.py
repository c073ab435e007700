"""Every threshold of the method, named, in one settings object.

The paper's values are the defaults (mu_D = 0.75, mu_C = 0.2, 5 mm pixels, ...).
Each stage reads only its own section. ``DetectionSettings.from_dict`` accepts a nested
dict (e.g. loaded from JSON/YAML) and refuses unknown keys.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import yaml

from .errors import InputError


@dataclass
class SegmentationSettings:
    """Floor, ceiling and walls (paper, section 3.1)."""

    # floor and ceiling: the lowest and highest levels (maxima) of the Z histogram
    z_bin_m: float = 0.02  # Z histogram bin for the floor / ceiling maxima
    min_room_height_m: float = 1.8  # the ceiling is at least this far above the floor
    min_level_fraction: float = 0.05  # a level stands out by at least this x the largest one
    min_level_area: float = 0.25  # ... and covers at least this x the plan area of the widest level
    level_cell_m: float = 0.1  # plan cells for that area
    min_ceiling_area_m2: float = 2.0  # a smaller level above the wide ceiling is a higher room's ceiling
    level_dominance: float = 2.0  # a cell is level there with this x the points of the slabs beside
    top_quantile: float = 0.999  # without a ceiling level the walls end at this quantile of Z
    histogram_max_points: int = 2_000_000  # the histogram uses a regular subsample of this size
    slab_margin_m: float = 0.08  # points this close to floor / ceiling are not used to fit walls
    slab_tolerance_m: float = 0.015  # points this close to floor / ceiling belong to them, not to walls
    # wall planes, fitted on a subsample of the points between floor and ceiling
    fit_max_points: int = 6_000_000  # regular subsample of the wall band used for fitting
    fit_cell_m: float = 0.10  # voxel in which a local plane (normal) is estimated
    min_cell_points: int = 6  # voxels with fewer points give no normal
    cell_planarity: float = 0.08  # smallest / middle eigenvalue of a planar voxel at most this
    max_normal_z: float = 0.2  # |n_z| of a vertical surface at most this
    angle_bin_deg: float = 0.5  # histogram of normal directions
    angle_tolerance_deg: float = 4.0  # voxels within this of a dominant direction belong to it
    offset_bin_m: float = 0.01  # histogram of plane offsets in one direction
    wall_plane_tolerance_m: float = 0.03  # voxels / points within this of a wall plane belong to it
    wall_gap_m: float = 1.2  # a plane with no points over a longer stretch is two walls
    junction_tolerance_m: float = 0.15  # a wall ending this close to another splits it (T-junction)
    xy_cell_m: float = 0.02  # XY grid of floor / ceiling points that tells the room side
    facing_probe_m: tuple[float, float] = (0.025, 0.05)  # probed distances in front of / behind a wall
    min_room_evidence: float = 0.05  # share of a wall's length with floor / ceiling points in front
    min_wall_length_m: float = 0.5
    min_wall_height_fraction: float = 0.5  # of the floor-to-ceiling height, covered by the wall's points
    # points of a wall
    object_depth_m: float = 0.30  # wall points include objects standing out this far
    behind_depth_m: float = 0.05  # ... and points this far behind the wall plane
    extent_margin_m: float = 0.6  # points this far beyond a free wall end are still looked at (< wall_gap_m / 2)
    extent_gap_m: float = 0.3  # a free end is where the wall's points stop for longer than this
    assign_cell_m: float = 0.25  # XY bucket used to find the points of each wall quickly
    refit_max_points: int = 50_000  # points used for the final least-squares plane of each wall
    wall_top_quantile: float = 0.998  # a wall's top (its own room's ceiling) is this quantile of its plane's z
    recess_max_m: float = 0.3  # a plane this far behind a wall, inside it and not reaching its top is no wall
    furniture_depth_m: float = 1.0  # a plane this far in front of a wall, inside it and lower is no wall (furniture)
    # stray points and the dense extent (see stray_points.py)
    stray_sample_points: int = 2_000_000  # the dense part is found on a regular subsample of this size
    stray_cell_m: float = 1.0  # voxel of the occupancy grid
    stray_min_fraction: float = 0.02  # a voxel is dense with this x the points of a typical point's voxel
    stray_min_points: int = 3  # ... and at least this many
    stray_margin_m: float = 1.0  # the dense box is grown by this
    max_extent_m: float = 2000.0  # a dense part wider than this is not a building
    # storeys: parts of the Z range separated by slabs (Z bins with almost no points)
    storey_bin_m: float = 0.02  # Z histogram bin of the storey profile
    slab_gap_fraction: float = 0.25  # a bin is in a slab with less than this x the median bin count (3 bins smoothed)
    min_slab_m: float = 0.08  # a slab between two storeys is at least this thick
    slab_level_factor: float = 5.0  # ... and has a level (a bin of this x the median) below and above it
    slab_level_reach_m: float = 0.1  # ... this close


@dataclass
class OrthoimageSettings:
    """The 4D orthoimage J_CD (paper, section 3.2)."""

    pixel_m: float = 0.005
    depth_range_m: tuple[float, float] = (-0.06, 0.30)  # kept signed distances from the plane
    depth_quantum_m: float = 0.0001  # depth resolution of the per-pixel median
    fill_gaps_px: int = 3  # no-data pixels with data on every side within this radius are sampling gaps (0: off)
    fill_min_fraction: float = 0.15  # ... filled when at least this fraction of the window has data
    layer_gap_m: float | None = None  # a pixel's points this far apart in depth are two layers (None: one median; 0.02 tried)
    furniture_depth_m: float | None = 0.25  # a layer reaching farther out is furniture, not used (None: none is)
    min_layer_share: float = 0.5  # the layer nearest the wall with this share of the pixel's points is kept (else the largest)
    occlusion_gap_m: float | None = 0.02  # a coherent surface this far in front of a pixel hides it (None: off)


@dataclass
class ColourPrepSettings:
    """Illumination equalisation and highlight restoration (paper, section 3.2)."""

    cell_m: float = 0.05  # the illumination field is estimated on cells of this size
    illumination_window_m: float = 0.25  # median window of the field (keeps station steps sharp)
    wall_depth_tolerance_m: float = 0.006  # cells standing out more than this are objects, not wall
    chroma_tolerance: float = 0.035  # rg-chromaticity distance of a cell still taken as lit wall
    min_cell_fraction: float = 0.3  # cells with less data than this fraction are not used
    highlight_value: float = 0.92  # HSV value above which a pixel may be a specular highlight
    highlight_saturation: float = 0.12  # ... when its saturation is below this
    snap_tolerance: float = 0.1  # a pixel within this relative colour error of a nearby cell field takes it
    mixed_fraction: float = 0.05  # cells with more pixels of another chromaticity / depth hold an object's edge
    mixed_noise_factor: float = 3.0  # ... or more than this x the wall cells' median share (noisy walls)


@dataclass
class WallAreaSettings:
    """Visible wall area and openings (paper, section 3.3)."""

    # visible wall area: coherent colour seeds, then segmentation by colour
    seed_window_px: int = 15
    seed_min_valid: float = 0.8  # share of a seed window that has data
    seed_colour_std: float = 4.0  # Lab standard deviation inside a coherent seed window at most
    seed_depth_std_m: float = 0.004  # depth standard deviation inside a seed window at most
    min_cluster_fraction: float = 0.2  # a seed colour cluster is wall if it holds this share of seeds
    colour_tolerance: float = 12.0  # Lab distance (CIE76) to the wall colour still counted as wall
    wall_depth_tolerance_m: float = 0.008  # |depth| of plain wall at most this
    depth_median_px: int = 5  # median filter of the depth before the wall test
    # openings: straight lines in colour and depth, rectangles, consistency checks
    canny_low: float = 40.0  # Canny thresholds on the L channel (0-255 scale)
    canny_high: float = 100.0
    depth_step_m: float = 0.01  # depth discontinuity treated as an edge
    min_line_m: float = 0.25  # shortest straight line used for rectangles
    line_tolerance_px: int = 2  # an edge this close to a rectangle side supports it
    min_side_support: float = 0.5  # fraction of each side covered by edges
    recess_m: float = 0.02  # interior deeper than this behind the wall is "open" (hole, glass)
    min_open_fraction: float = 0.6  # openings: interior share that is no data or recessed ...
    min_door_other_fraction: float = 0.85  # ... or, for a closed door, of other colour than the wall
    max_protruding_fraction: float = 0.15  # interior standing out of the wall (an object) at most
    ring_m: float = 0.05  # band around a rectangle that must be wall (location consistency)
    max_ring_open_fraction: float = 0.35
    door_floor_tolerance_m: float = 0.12  # a door's bottom is at most this above the floor
    door_width_m: tuple[float, float] = (0.6, 2.2)
    door_height_m: tuple[float, float] = (1.8, 2.6)
    window_width_m: tuple[float, float] = (0.4, 3.5)
    window_height_m: tuple[float, float] = (0.4, 2.2)
    window_min_sill_m: float = 0.15  # a window's bottom is at least this above the floor


@dataclass
class DepthRecognitionSettings:
    """Recognition with geometry (paper, section 4.2)."""

    mu_d: float = 0.75  # cross-correlation threshold
    min_relief_m: float = 0.0025  # relief region: stands out by this (a flush socket, a 3 mm sign)
    canny_sigma_px: float = 1.0  # Gaussian smoothing of J_D before Canny
    canny_high_fraction: float = 0.48  # Canny high threshold = this x min_relief_m per pixel (1.2 mm/px)
    canny_low_ratio: float = 0.5  # Canny low threshold = this x the high one
    noise_k: float = 4.0  # thresholds are at least this many robust sigmas of the wall's depth noise
    noise_window_m: float = 0.01  # pixels this close to the plane are plain wall for the noise estimate
    roi_min_px: int = 6  # RoIs whose longer side is shorter than this are noise
    roi_merge_overlap: float = 0.0  # RoIs overlapping by more than this are clustered
    roi_merge_gap_px: int = 2  # ... and so are RoIs closer than this
    border_margin_m: float = 0.03  # relief this close to the wall's ends, floor or ceiling is no object
    max_roi_factor: float = 1.6  # thin relief longer than this x the largest model is no object
    search_margin_px: int = 6  # a match's centre may lie this far outside its RoI
    template_pad_px: int = 4  # wall-plane border added around each depth model
    match_sigma_px: float = 1.0  # J_D and the models are both smoothed by this before correlating
    min_template_relief_m: float = 0.002  # models flatter than this are not matched in depth
    gain_range: tuple[float, float] = (0.5, 2.0)  # accepted scene / model relief amplitude ratio
    examples_limit: bool = True  # a hit (depth or colour) of a class taught from examples (model.json
    # example_relief_m) where the relief stands out further than its examples, their spread and the wall's
    # noise relief is refused (amplitude.as_far_as_examples); a library without examples is not affected
    rotations: tuple[float, ...] = (0, 90, 180, 270)  # in-plane model rotations always tried (degrees)
    rotation_margin: float = 0.05  # a rotated match must correlate this much better than upright
    free_rotation: bool = True  # RoIs whose relief is turned are also searched with turned models
    min_turn_deg: float = 3.0  # ... when turned by at least this from the image axes
    turn_refine_deg: tuple[float, ...] = (-2.0, -1.0, 1.0, 2.0)  # ... refined around the best turn
    turn_steps_deg: tuple[float, ...] = (10.0, 5.0, 2.0, 1.0)  # every match's turn: local search steps
    min_turn_gain: float = 0.005  # ... a turn is taken when it raises rho_D by more than this
    max_peaks_per_roi: int = 4  # instances of one class one RoI may hold
    see_through_fraction: float = 0.1  # gaps below this x a model's relief that it encloses are see-through (0: off)
    part_gap_fraction: float = 0.25  # RoIs this close (x the model's shorter side) and fitting it: one object's parts (0: off)
    isolation_gap_px: int = 2  # side strips checked for relief start this far outside a match
    isolation_width_px: int = 3  # ... and are this wide
    isolation_relief_fraction: float = 0.5  # relief above this x the model's (median) counts
    isolation_max_occupancy: float = 0.5  # a side strip with more relief: part of something larger
    isolation_trails: bool = True  # ... unless it falls at every pixel to the wall: a mixed-pixel trail
    min_relief_iou: float = 0.5  # where model and scene stand out must overlap this much (IoU)
    face_edge_px: int = 2  # a match's face amplitude (Candidate.face_gain) leaves this much of its outline out
    foreground_factor: float = 3.0  # relief beyond this x a model's peak is another object in front of the wall
    # (a desk panel, a bin): unknown to that model, like an unseen pixel (0: off); above gain_range's top
    foreground_edge_px: int = 8  # ... with its edge (falling by min_relief_m per pixel) up to this wide
    foreground_mu_d: float = 0.9  # a match whose window or side strips reach such an object must correlate this
    # (that side's isolation is unverified); its footprint must be seen (full_known_share), not behind it
    min_seen_share: float = 0.8  # a match whose window (with its side strips) is seen on less than this x the
    # wall's share (seen_share: points or an object's own shadow) lies in furniture's shadow: must correlate
    # foreground_mu_d (0: off)
    nms_overlap: float = 0.3  # same-class matches overlapping more than this are one match
    refit_plane: bool = True  # remove a residual plane fitted to the visible wall
    gap_fill_sigma_px: float = 1.0  # sampling gaps are filled by a normalised Gaussian of this size
    gap_fill_min_weight: float = 0.3  # ... where known neighbours weigh at least this much
    median_px: int = 3  # median filter of J_D against speckle (3 or 5; other values: off)
    min_known_share: float = 0.6  # a match needs depth data on this share of its footprint
    full_known_share: float = 0.95  # footprints with less data are also correlated on their data only
    masked_pre_threshold: float = 0.3  # ... where their plain correlation reaches this (speed)
    level_cell_m: float = 0.05  # local wall level: mean of the plain-wall pixels per cell of this size
    level_window_m: float = 0.25  # ... then the median of the cells within this window
    level_plain_m: float = 0.006  # ... plain-wall pixels are this close to the plane (a step, not an object)
    level_min_share: float = 0.3  # ... a cell needs this share of plain-wall pixels
    level_dead_m: float = 0.0005  # ... levels within this of the plane are 0 (the rest shrunk by it)
    level_max_m: float = 0.006  # ... and it is clamped to this (misregistration steps are a few mm)
    level_min_extent_m: float = 0.5  # ... non-zero only in regions at least this long (no flat sign)
    sharp_edge_position: bool = True  # a match is placed by its relief's sharp edges (edge_position)


@dataclass
class ColourRecognitionSettings:
    """Recognition with colour (paper, section 4.3)."""

    mu_c: float = 0.2  # minimum-distance classifier threshold (normalised descriptors)
    threshold_offset: float = 12.0  # minimum colour distance (CIE76 delta E) from the wall colour
    noise_k: float = 4.0  # ... raised to this many robust sigmas of the wall's own colour noise
    background_window_m: float = 0.6  # window of the local wall-colour estimate
    flat_wall_m: float = 0.004  # without a usable wall area, pixels this flat count as wall
    median_px: int = 3  # median filter of the colour image before thresholding
    gap_fill_sigma_px: float = 1.0  # sampling gaps are filled by a normalised Gaussian of this size
    gap_fill_min_weight: float = 0.3  # ... where known neighbours weigh at least this much
    roi_min_px: int = 6  # RoIs whose longer side is shorter than this are noise
    roi_min_area_px: int = 12  # ... and so are RoIs with fewer foreground pixels
    roi_merge_gap_px: int = 2  # RoIs closer than this are clustered
    max_roi_factor: float = 1.6  # RoIs larger than this x the largest footprint are refused
    casing_max_m: float = 0.15  # a door / window frame hugging an opening is at most this wide (0: kept)
    casing_fill: float = 0.7  # ... its lines parallel to the opening's side are foreground over this share
    casing_gap_px: int = 3  # ... and it may start this many lines off the opening's rectangle
    glcm_levels: int = 8  # grey levels of the co-occurrence matrix (equation 14)
    cluster_merge_s: float = 0.05  # three-class clustering: S classes closer than this are one
    cluster_merge_ab: float = 4.0  # ... and a / b classes closer than this (Lab units)
    segment_cap: int = 10  # v5 (number of s2 segments in s1) normalised by this count
    ab_scale: float = 100.0  # Lab a / b units mapped to 1 in the normalised descriptors
    size_tolerance: float = 0.3  # relative difference allowed between RoI and model sizes
    nearest_only: bool = False  # True: a RoI is a candidate of its nearest prototype only
    depth_check_gain: float = 0.3  # a class with relief needs this much of it in the scan (0: off)
    depth_check_min_relief_m: float = 0.008  # ... checked only for models with this much relief
    depth_check_coverage: float = 0.5  # ... whose footprint must have depth data in this share
    train_blurs_px: tuple[float, ...] = (0.5, 1.0)  # blurs of the library views when learning
    train_noise_samples: int = 2  # noisy copies per view and blur (noise measured on the wall)
    train_threshold_factors: tuple[float, ...] = (0.8, 1.0, 1.25)  # foreground-threshold jitter
    nearest_sample: bool = True  # rho_C to the nearest training pattern, not only to the mean
    prototype_colour_step: float = 4.0  # walls whose colours round alike share learnt prototypes
    refine_position: bool = True  # place the footprint by colour cross-correlation in the RoI
    search_margin_px: int = 6  # a match's centre may lie this far outside its RoI
    rotations: tuple[float, ...] = (0, 90, 180, 270)  # in-plane rotations always tried when placing
    rotation_margin: float = 0.05  # a rotated placement must correlate this much better
    free_rotation: bool = True  # a RoI whose foreground is turned is also placed with turned views
    relief_must_allow: bool = True  # a colour match where the relief stands out less than gain_range's low end
    # times its class's depth model is refused (amplitude.colour_where_relief_allows)
    min_turn_deg: float = 3.0  # ... when turned by at least this from the image axes
    turn_refine_deg: tuple[float, ...] = (-2.0, -1.0, 1.0, 2.0)  # ... refined around the best turn


@dataclass
class LookalikeSettings:
    """Look-alike classes found in the library and told apart by their print (issue 13)."""

    enabled: bool = True
    size_tolerance: float = 0.15  # footprints whose sides differ by at most this share are the same size
    min_depth_ncc: float = 0.9  # ... whose depth models correlate at least this much
    max_colour_delta_e: float = 25.0  # ... and whose mean colours differ by at most this (CIE76)
    depth_alike_any_colour: bool = True  # same size and depth NCC >= min_depth_ncc: look-alikes whatever their colours
    search_px: int = 3  # the print is compared within this many pixels of the candidate's centre
    learnt_print_pad_px: int = 4  # a learnt design's print (sbsc learn) is compared with this ring of its surface
    # around it, as depth models are padded with wall plane (depth.template_pad_px): the examples showed the
    # object alone on its surface, and a plate of one colour filling its box has no print but noise without it;
    # with learnt designs in the library every class's print gets the same ring (none is favoured by it)
    min_margin: float = 0.05  # another look-alike's print must correlate this much better to relabel
    min_print_ncc: float = 0.5  # ... and at least this much
    min_margin_relief: float = 0.0  # with the fine relief compared too (mean of print and relief): this margin
    min_evidence_relief: float = 0.3  # ... and this level
    relief_decides: bool = True  # same size and colour with reliefs to compare: look-alikes whatever their depth NCC
    colour_confusable: bool = True  # same-size classes the colour classifier cannot tell apart on a wall too
    amplitude_decides: bool = True  # a look-alike whose model stands out more or less than the scene there, beyond
    # the depth recognizer's gain_range, is not a class the candidate may be (lookalikes.amplitude_compatible)


@dataclass
class ConsensusSettings:
    """Consensus of depth and colour candidates (paper, section 4.4)."""

    exclusive_alpha: float = 0.5  # equation 15, case III
    min_alpha: float = 0.0  # cells at or below this are never selected
    suppress_overlap: float = 0.25  # cross-class suppression: max overlap of two accepted objects
    prefer_depth: bool = True  # at equal alpha: both > depth only > colour only, then goodness
    alpha_tolerance: float = 0.05  # alphas this close count as equal (the tie-break decides)
    max_disagreement_px: float = 1.5  # equation 16 for centres this close, else depth's (.inf: always)
    depth_outscored_margin: float = 0.1  # a depth match beaten by this at its place confirms no colour match
    mount_margin_m: float = 0.03  # a footprint passing its wall's floor or top by more than this is not on it


@dataclass
class ConfidenceSettings:
    """Calibrated confidence per detection and the "none of these" rule (issue 13)."""

    enabled: bool = True
    calibration: str = ""  # a calibration JSON (empty: the one shipped in sbsc_core/recognition/calibration/)
    min_confidence: float = 0.5  # hits less likely right than this give no detection ...
    report_unknown: bool = False  # ... or, with this, a detection of class "unknown" for review
    fill_by_confidence: bool = True  # expected counts are filled with each class's most probable hits


@dataclass
class CeilingSettings:
    """Objects on ceilings (issue 11; :mod:`sbsc_core.scene.ceilings`): searched by default when a
    searched class may be mounted there (:func:`~sbsc_core.pipeline.detect.searched_surfaces`)."""

    enabled: bool = True  # ceilings may be searched (``sbsc detect --no-ceilings``: not)
    tile_m: float = 6.0  # a storey's ceiling is cut into tiles at most this big each way
    overlap_m: float = 0.3  # ... each grown by this on every side (more than half an object)
    wall_clear_m: float = 0.05  # points this close to a wall's plane are the wall's, not the ceiling's
    # stepped ceilings: rooms whose ceiling is lower than the storey's get a level of their own
    level_cell_m: float = 0.25  # plan cells whose top (the ceiling above them) is measured
    level_max_drop_m: float = 1.0  # a lower ceiling is at most this far below the storey's
    level_tolerance_m: float = 0.03  # a cell whose top is this close to a level is under it
    level_min_area_m2: float = 2.0  # a lower ceiling covers at least this much of the plan


@dataclass
class ColumnSettings:
    """Objects on free-standing columns (issue 11; :mod:`sbsc_core.scene.columns`): searched by
    default when a searched class may be mounted there (:func:`~sbsc_core.pipeline.detect.searched_surfaces`)."""

    enabled: bool = True  # columns may be found and searched (``sbsc detect --no-columns``: not)
    cell_m: float = 0.05  # plan cells of the column search
    band_m: float = 0.2  # height bands: a cell is tall when its points fill ...
    min_cover: float = 0.8  # ... at least this share of the bands between floor and ceiling (0.3 m off each)
    min_side_m: float = 0.15  # a column is at least this thick ...
    max_side_m: float = 1.5  # ... and at most this wide
    round_rms_m: float = 0.012  # round when a circle fits its points within this (RMS)
    wall_clear_m: float = 0.15  # points this close to a wall's plane are the wall's
    wrap_m: float = 0.4  # a round column's unrolled image repeats this much of its start at its end (the seam)


@dataclass
class PendantSettings:
    """Objects hanging from the ceiling (issue 27; :mod:`sbsc_core.scene.pendants`): searched with
    the ceilings (``sbsc detect --no-ceilings``: not), for the classes that may be on a ceiling."""

    enabled: bool = True
    cell_m: float = 0.02  # plan cells of the search
    min_cell_points: int = 2  # a cell with fewer points is noise (stray returns of the ceiling)
    reach_m: float = 1.0  # a panel hangs at most this far below the ceiling ...
    gap_m: float = 0.03  # ... and at least this far (the ceiling's own points and what is on it)
    wall_clear_m: float = 0.15  # points this close to a wall's plane or a column are theirs
    max_thickness_m: float = 0.12  # a panel is at most this thick ...
    upright_ratio: float = 1.5  # ... and this many times taller than thick (a thing on the ceiling is flat)
    size_slack: float = 1.5  # as wide and tall as the classes mounted on ceilings, within this factor
    below_m: float = 0.3  # under a panel, down to this above the floor, ...
    max_under_share: float = 0.05  # ... at most this share of its points (it hangs: furniture stands)
    min_points: int = 30  # a panel has at least this many points in the sample
    margin_m: float = 0.1  # its surface reaches this far beyond it on each side


@dataclass
class RegistrationSettings:
    """Fine registration of the stations when they come as several files (:mod:`sbsc_core.scene.registration`)."""

    enabled: bool = True  # several scan files: refine how they fit together before anything is measured
    sample_points: int = 320_000  # each station's share of the sample kept for it (fewer than 1/4 of it seen
    # far away, e.g. through a door, would be lost: the voxels below thin what is near first) ...
    voxel_m: float = 0.03  # ... thinned to one point per voxel of this size ...
    max_points: int = 20_000  # ... and to at most this many points (more change nothing measurable) ...
    max_total_points: int = 4_000_000  # ... and all stations together to this many (4x that of their shares)
    max_distance_m: float = 0.10  # partners are searched this far (a few thinned points per 10 cm) ...
    plane_tolerance_m: float = 0.015  # ... and count when this close to each other's plane (the errors are mm)
    min_overlap: float = 0.05  # two files are paired when this share of the smaller one's points have a partner (a door
    # between two rooms is enough: the pairs are weighed by their information, so few points count little)
    max_shift_m: float = 0.05  # a refined pose that moves a file's points more than this is refused
    min_disagreement_m: float = 0.001  # overlapping pairs whose ICP moves their points this little (median of
    # their mean moves) already agree: kept as registered (perfectly registered stations: 0.38 mm; 2 mm errors: 3.8)


@dataclass
class DetectionSettings:
    registration: RegistrationSettings = field(default_factory=RegistrationSettings)
    segmentation: SegmentationSettings = field(default_factory=SegmentationSettings)
    orthoimage: OrthoimageSettings = field(default_factory=OrthoimageSettings)
    colour_prep: ColourPrepSettings = field(default_factory=ColourPrepSettings)
    wall_area: WallAreaSettings = field(default_factory=WallAreaSettings)
    depth: DepthRecognitionSettings = field(default_factory=DepthRecognitionSettings)
    colour: ColourRecognitionSettings = field(default_factory=ColourRecognitionSettings)
    consensus: ConsensusSettings = field(default_factory=ConsensusSettings)
    lookalikes: LookalikeSettings = field(default_factory=LookalikeSettings)
    confidence: ConfidenceSettings = field(default_factory=ConfidenceSettings)
    ceilings: CeilingSettings = field(default_factory=CeilingSettings)
    columns: ColumnSettings = field(default_factory=ColumnSettings)
    pendants: PendantSettings = field(default_factory=PendantSettings)
    workers: int = 0  # processes for the per-wall stages; 0 = up to 2, by the CPU count

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
            any_length = "..." in str(known[key].type)  # tuple[float, ...]
            if not isinstance(value, (list, tuple)) or not (any_length or len(value) == len(default)):
                raise InputError(f"{where}.{key}", f"expected a list like {list(default)}")
            kwargs[key] = tuple(_scalar(0.0, v, f"{where}.{key}") for v in value)
        elif str(known[key].type) == "float | None" and (value is None or default is None):  # either
            kwargs[key] = None if value is None else _scalar(0.0, value, f"{where}.{key}")
        else:
            kwargs[key] = _scalar(default, value, f"{where}.{key}")
    return kind(**kwargs)


def _scalar(default: Any, value: Any, where: str) -> Any:
    """Check one setting's value against its default's type, without converting what it is not.

    ``bool("false")`` is True and ``int("3x")`` raises a bare ValueError: a settings file's
    value is taken only if it already is of the setting's kind (an integer is a float too).
    """
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    elif isinstance(default, str):
        ok = isinstance(value, str)
    else:
        ok = isinstance(value, type(default))
    if not ok:
        raise InputError(where, f"expected {type(default).__name__}, got {value!r}")
    return float(value) if isinstance(default, float) else value


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
