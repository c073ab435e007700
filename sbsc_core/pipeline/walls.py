"""One surface's recognition: a wall's (or a tile's, a face's) orthoimage through
colour preparation, visible area, depth and colour recognition; the classes searched;
the surface's images, drawn and parked on disk by the worker that made them."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..errors import InputError, SbscError
from ..imaging.colour_prep import prepare_colour
from ..imaging.orthoimage import build_orthoimage
from ..imaging.partition import (
    wall_orthoimage,
)
from ..imaging.wall_area import find_wall_area
from ..recognition.amplitude import (
    as_far_as_examples,
    colour_where_relief_allows,
    taught_amplitudes,
)
from ..recognition.colour_recognition import (
    ColourPrototypes,
    colour_image,
    colour_rois,
    learn_prototypes,
    match_colour,
)
from ..recognition.depth_recognition import depth_images, depth_rois, match_depth, noise_relief
from ..recognition.lookalikes import library_relief_models, prepare_library, resolve_on_wall
from ..recognition.templates import ModelTemplate, make_templates
from ..settings import DetectionSettings
from ..types import (
    Box,
    Candidate,
    Detection,
    ModelLibrary,
    Orthoimage,
    PointCloud,
    Wall,
    WallArea,
    WallFrame,
)

if TYPE_CHECKING:  # the documents (and pydantic) are imported where used: the wall workers never need them
    from ..io.documents import ExpectedCounts

    Expected = dict[str, int] | ExpectedCounts  # contract 3: counts, or counts with per-storey counts


@dataclass
class WallResult:
    """Everything the method computed for one wall."""

    ortho: Orthoimage
    area: WallArea
    depth_rois: list[Box]
    colour_rois: list[Box]
    depth_candidates: list[Candidate]
    colour_candidates: list[Candidate]


WALL_STAGES = ("orthoimage", "colour_prep", "wall_area", "depth", "colour")


def process_wall(cloud: PointCloud, wall: Wall, templates: dict[str, ModelTemplate],
                 prototypes: ColourPrototypes, s: DetectionSettings) -> tuple[WallResult, dict[str, float]]:
    """Sections 3.2-4.3 on one wall: orthoimage, colour preparation, wall area and openings,
    RoIs and candidates in depth and in colour. Returns the result and seconds per stage."""
    t = time.perf_counter()
    ortho = build_orthoimage(cloud, wall, s.orthoimage)
    return process_orthoimage(ortho, templates, prototypes, s, {"orthoimage": time.perf_counter() - t})


def process_orthoimage(ortho: Orthoimage, templates: dict[str, ModelTemplate], prototypes: ColourPrototypes,
                       s: DetectionSettings, t_stage: dict[str, float] | None = None
                       ) -> tuple[WallResult, dict[str, float]]:
    """Sections 3.2 (colour) to 4.3 on one wall's orthoimage; seconds per stage added to ``t_stage``."""
    t_stage = dict(t_stage or {})
    t = time.perf_counter()
    ortho = prepare_colour(ortho, s.colour_prep)
    t_stage["colour_prep"] = time.perf_counter() - t
    t = time.perf_counter()
    area = find_wall_area(ortho, s.wall_area)
    t_stage["wall_area"] = time.perf_counter() - t
    t = time.perf_counter()
    d_img = depth_images(ortho, area, s.depth)  # J_D and its wall level, computed once per wall
    d_rois = depth_rois(ortho, area, s.depth, templates, d_img)
    d_cands = match_depth(ortho, area, d_rois, templates, s.depth, images=d_img)
    t_stage["depth"] = time.perf_counter() - t
    t = time.perf_counter()
    c_img = colour_image(ortho, area, s.colour)  # J_C and J_BW, computed once per wall
    c_rois = colour_rois(ortho, area, s.colour, c_img, largest_px=prototypes.largest_footprint_px)
    c_cands = match_colour(ortho, area, c_rois, prototypes, s.colour, image=c_img)
    d_cands, c_cands = resolve_on_wall(d_cands, c_cands, c_img, prototypes, s.lookalikes,
                                       relief=d_img.levelled, gain_range=s.depth.gain_range)
    if s.colour.relief_must_allow:  # a print without its object's relief is not the object
        c_cands, _ = colour_where_relief_allows(c_cands, d_img.levelled, *library_relief_models(prototypes),
                                                s.depth.gain_range)
    taught = taught_amplitudes(prototypes.templates) if s.depth.examples_limit else {}
    if taught:  # nor a hit where the relief stands out further than the building's own examples (sbsc learn)
        noise_m = noise_relief(ortho, area, d_img, s.depth)
        d_cands, _ = as_far_as_examples(d_cands, d_img.levelled, taught, noise_m)
        c_cands, _ = as_far_as_examples(c_cands, d_img.levelled, taught, noise_m)
    t_stage["colour"] = time.perf_counter() - t
    return WallResult(ortho, area, d_rois, c_rois, d_cands, c_cands), t_stage


def _partition_wall_job(scratch: str, w: int, wall_id: str, frame: WallFrame, *,
                        templates: dict[str, ModelTemplate],
                        prototypes: ColourPrototypes, s: DetectionSettings, images: str | None = None
                        ) -> tuple[str, WallResult, dict[str, float]]:
    """One wall's work from its partition file (what a worker, local or on a cluster, runs).

    With ``images`` (a folder beside the partitions) the wall's images are written there
    and the result is returned without them (:func:`park_wall`).
    """
    t = time.perf_counter()
    ortho = wall_orthoimage(scratch, w, wall_id, frame, s.orthoimage)
    res, t_stage = process_orthoimage(ortho, templates, prototypes, s, {"orthoimage": time.perf_counter() - t})
    if images is not None:
        res = park_wall(res, Path(images))
    return wall_id, res, t_stage


def _templates_job(library: ModelLibrary, s: DetectionSettings, classes: list[str]
                   ) -> tuple[dict[str, ModelTemplate], ColourPrototypes]:
    """The templates of the searched classes at the orthoimage's pixel size, and their colour
    prototypes with what the look-alike decisions read of the library alone made once
    (:func:`~sbsc_core.recognition.lookalikes.prepare_library`: each wall's task receives it)."""
    templates = make_templates(library, s.orthoimage.pixel_m, classes)
    return templates, prepare_library(learn_prototypes(templates, s.colour), s.lookalikes)


def _wall_cloud(cloud: PointCloud, wall: Wall) -> tuple[PointCloud, Wall]:
    """The points of one wall as a cloud of their own (what a worker process receives)."""
    sub = PointCloud(cloud.xyz[wall.point_index], cloud.rgb[wall.point_index], cloud.origin, cloud.sources)
    return sub, Wall(wall.id, wall.frame, np.arange(len(wall.point_index), dtype=np.int64), wall.storey)


def _process_wall_job(sub: PointCloud, wall: Wall, templates: dict[str, ModelTemplate],
                      prototypes: ColourPrototypes, s: DetectionSettings
                      ) -> tuple[str, WallResult, dict[str, float]]:
    res, t_stage = process_wall(sub, wall, templates, prototypes, s)
    return wall.id, res, t_stage


def _as_expected(expected: Expected | None) -> ExpectedCounts | None:
    from ..io.documents import ExpectedCounts

    if expected is None or isinstance(expected, ExpectedCounts):
        return expected
    return ExpectedCounts(dict(expected))


def search_classes(library: ModelLibrary, expected: dict[str, int] | None, kind: str = "wall") -> list[str]:
    """The classes searched for on surfaces of ``kind``: expected (or all) and mounted there."""
    if expected is not None:
        unknown = sorted(set(expected) - set(library.models))
        if unknown:
            raise InputError("expected", f"class '{unknown[0]}' is not in the model library")
        return library.classes_on(kind, sorted(c for c, n in expected.items() if n > 0))
    return library.classes_on(kind)


def searched_surfaces(s: DetectionSettings, library: ModelLibrary, expected: ExpectedCounts | None) -> DetectionSettings:
    """``s`` with ceilings and columns searched only where they may hold a searched class.

    Every kind of surface is searched by default (contract 6): ``settings.ceilings.enabled``
    and ``settings.columns.enabled`` say that the user allows it (``--no-ceilings`` and
    ``--no-columns`` do not); a kind is then searched when a class searched for (expected, or
    every class of the library) may be mounted there (its ``model.json`` ``mount``, every
    surface when it has none).
    """
    counts = None if expected is None else expected.counts
    ceilings = s.ceilings.enabled and bool(search_classes(library, counts, "ceiling"))
    columns = s.columns.enabled and bool(search_classes(library, counts, "column"))
    if (ceilings, columns) == (s.ceilings.enabled, s.columns.enabled):
        return s
    return replace(s, ceilings=replace(s.ceilings, enabled=ceilings), columns=replace(s.columns, enabled=columns))


def _box_uv(ortho: Orthoimage, b: Box) -> dict:
    px, h = ortho.pixel_m, ortho.frame.height_m
    return {"u_min": round(b.c0 * px, 4), "u_max": round(b.c1 * px, 4),
            "v_min": round(h - b.r1 * px, 4), "v_max": round(h - b.r0 * px, 4)}


def depth_visualisation(depth: np.ndarray, scale_m: float = 0.10) -> np.ndarray:
    """8-bit grey image of a depth map: wall plane mid-grey, relief darker, no data white."""
    grey = depth / scale_m  # on the whole image, then white where no data (as on the pixels with data only)
    grey *= 127
    np.subtract(128, grey, out=grey)
    np.clip(grey, 0, 254, out=grey)
    grey[~np.isfinite(depth)] = 255
    return grey.astype(np.uint8)


def overlay_image(w: WallResult, detections: Sequence[Detection], colour_bgr: np.ndarray | None = None) -> np.ndarray:
    """The colour orthoimage with depth RoIs (cyan), colour RoIs (magenta) and red spots (BGR).

    ``colour_bgr`` is the colour orthoimage when ``w`` no longer holds it (see :func:`park_wall`).
    """
    img = cv2.cvtColor(w.ortho.colour, cv2.COLOR_RGB2BGR).copy() if colour_bgr is None else colour_bgr.copy()
    for b in w.depth_rois:
        cv2.rectangle(img, (b.c0, b.r0), (b.c1 - 1, b.r1 - 1), (255, 255, 0), 1)
    for b in w.colour_rois:
        cv2.rectangle(img, (b.c0, b.r0), (b.c1 - 1, b.r1 - 1), (255, 0, 255), 1)
    for d in detections:
        r, c = w.ortho.uv_to_pixel(d.u, d.v)
        cv2.circle(img, (int(round(float(c))), int(round(float(r)))), 6, (0, 0, 255), -1)
    return img


def _write_wall_images(ortho: Orthoimage, images: Path) -> None:
    """The colour and depth images of one wall (``<wall>_colour.png``, ``_depth.png``, ``_depth.npy``)."""
    wid = ortho.wall_id
    if not cv2.imwrite(str(images / f"{wid}_colour.png"), cv2.cvtColor(ortho.colour, cv2.COLOR_RGB2BGR)):
        raise SbscError(f"{images}: cannot write images")
    cv2.imwrite(str(images / f"{wid}_depth.png"), depth_visualisation(ortho.depth))
    np.save(images / f"{wid}_depth.npy", np.asarray(ortho.depth, np.float32))


_PARKED = np.zeros((0, 0), bool)


def park_wall(res: WallResult, images: Path) -> WallResult:
    """Write a wall's images now and keep only what the consensus and the documents need.

    The orthoimages and masks (about 10 bytes a pixel) are the part of a wall's result that
    grows with the building; :func:`write_outputs` with ``parked=images`` moves the images
    into the output and draws the overlays from the colour images on disk.
    """
    _write_wall_images(res.ortho, images)
    o = res.ortho
    ortho = Orthoimage(wall_id=o.wall_id, frame=o.frame, pixel_m=o.pixel_m, colour=np.zeros((0, 0, 3), np.uint8),
                       depth=np.zeros((0, 0), np.float32), mask=_PARKED)
    area = WallArea(visible=_PARKED, openings=res.area.openings, opening_mask=_PARKED,
                    wall_colour=res.area.wall_colour)
    return WallResult(ortho, area, res.depth_rois, res.colour_rois, res.depth_candidates, res.colour_candidates)
