"""Recognition with colour (colour_recognition.py, paper section 4.3)."""

from dataclasses import replace

import numpy as np
import pytest

from sbsc_core.recognition.colour_recognition import (
    colour_image,
    colour_rois,
    learn_prototypes,
    match_colour,
)
from sbsc_core.recognition.templates import make_templates
from sbsc_core.settings import ColourRecognitionSettings
from tests.recognition_synth import PIXEL_M, make_wall, paste, synthetic_library

WALL = (150, 160, 190)  # a blue-grey wall: every synthetic object contrasts with it
PLACES = [("socket", (50.3, 60.7), 0), ("panel", (150.0, 200.0), 0), ("knob", (60.0, 300.0), 0),
          ("sign", (100.0, 420.0), 90), ("socket", (230.0, 300.0), 180), ("panel", (220.0, 440.0), 0)]


@pytest.fixture(scope="module")
def library():
    templates = make_templates(synthetic_library(), PIXEL_M)
    return templates, learn_prototypes(templates, ColourRecognitionSettings())


def _scene(templates, wall=WALL, places=PLACES, seed=1):
    ortho, area = make_wall(seed=seed, colour=wall)
    for i, (cid, centre, rot) in enumerate(places):
        paste(ortho, area, templates[cid], centre, rot, seed=i)
    return ortho, area


def test_rois_one_per_object_none_on_plain_wall(library) -> None:
    templates, _ = library
    s = ColourRecognitionSettings()
    ortho, area = _scene(templates)
    rois = colour_rois(ortho, area, s)
    assert len(rois) == len(PLACES)
    for _, (r, c), _ in PLACES:
        assert sum(b.r0 <= r < b.r1 and b.c0 <= c < b.c1 for b in rois) == 1
    plain, plain_area = make_wall(seed=2, colour=WALL, holes=10, colour_noise=4.0)
    assert colour_rois(plain, plain_area, s) == []


def test_classifier_picks_the_right_class_at_the_right_place(library) -> None:
    templates, protos = library
    s = ColourRecognitionSettings()
    ortho, area = _scene(templates)
    cands = match_colour(ortho, area, colour_rois(ortho, area, s), protos, s)
    assert len(cands) == len(PLACES)
    for cid, (r, c), _ in PLACES:
        near = [x for x in cands if np.hypot(x.centre[0] - r, x.centre[1] - c) < 1.0]
        assert [x.class_id for x in near] == [cid], (cid, r, c, [(x.class_id, x.centre) for x in cands])
        assert near[0].score <= s.mu_c and near[0].source == "colour"
        h, w = templates[cid].height_px, templates[cid].width_px
        assert sorted((near[0].box.height, near[0].box.width)) == sorted((h, w))


def test_threshold_mu_c_refuses_an_unknown_object(library) -> None:
    templates, protos = library
    s = ColourRecognitionSettings()
    ortho, area = make_wall(seed=4, colour=WALL, holes=0)
    # a yellow-black hatched plate the size of a sign: a RoI, but no class within mu_C
    ortho.colour[100:142, 200:242] = (230, 200, 0)
    ortho.colour[100:142:6, 200:242] = (20, 20, 20)
    rois = colour_rois(ortho, area, s)
    assert len(rois) == 1
    assert match_colour(ortho, area, rois, protos, s) == []


def test_low_contrast_wall_learns_what_is_visible(library) -> None:
    templates, protos = library
    s = ColourRecognitionSettings()
    white = (244, 244, 239)  # the socket's own white
    ortho, area = _scene(templates, wall=white, places=[("socket", (80.0, 80.0), 0), ("panel", (150.0, 300.0), 0)])
    img = colour_image(ortho, area, s)
    seen = protos.for_wall(img.wall_rgb, img.threshold, img.noise_rgb)
    # only the socket's dark recess is visible on its own colour: a smaller visible extent
    assert seen["socket"].size_px[0] < templates["socket"].height_px * 0.8
    cands = match_colour(ortho, area, colour_rois(ortho, area, s), protos, s)
    found = {(x.class_id, round(x.centre[0]), round(x.centre[1])) for x in cands}
    assert ("socket", 80, 80) in found and ("panel", 150, 300) in found


def test_size_gate_uses_the_known_scale(library) -> None:
    templates, protos = library
    s = ColourRecognitionSettings()
    ortho, area = make_wall(seed=7, colour=WALL, holes=0)
    big = replace(templates["socket"])  # paste a socket drawn at 2.5x its real size
    import cv2
    big.colour_views = [cv2.resize(templates["socket"].colour_views[0], (40, 40), interpolation=cv2.INTER_LINEAR)]
    big.height_px = big.width_px = 40
    big.depth = None
    paste(ortho, area, big, (100.0, 100.0))
    rois = colour_rois(ortho, area, s)
    assert len(rois) == 1
    assert not [x for x in match_colour(ortho, area, rois, protos, s) if x.class_id == "socket"]


def test_base_prototypes_from_front_views(library) -> None:
    templates, protos = library
    assert sorted(protos.base) == sorted(templates)
    assert all(v.shape == (15,) for v in protos.base.values())


def test_a_protruding_class_is_not_accepted_on_a_flat_wall(library) -> None:
    templates, protos = library
    s = ColourRecognitionSettings()
    ortho, area = make_wall(seed=9, colour=WALL, holes=0)
    flat_panel = replace(templates["panel"], depth=None)  # a print of the panel, flat on the wall
    paste(ortho, area, flat_panel, (120.0, 200.0))
    rois = colour_rois(ortho, area, s)
    assert not [x for x in match_colour(ortho, area, rois, protos, s) if x.class_id == "panel"]
    off = replace(s, depth_check_gain=0.0)
    assert [x for x in match_colour(ortho, area, rois, protos, off) if x.class_id == "panel"]


def _door_with_casing(objects: list[tuple[slice, slice, tuple[int, int, int]]]):
    """A wall with a door (rows 120.., cols 150..250), a 16 px brown casing hugging it and ``objects``."""
    from sbsc_core.types import Opening

    ortho, area = make_wall(seed=11, colour=WALL, holes=0)
    r0, c0, c1, band = 120, 150, 250, 16
    ortho.colour[r0 - band:, c0 - band:c1 + band] = (110, 70, 40)  # casing
    door = np.zeros(area.visible.shape, bool)
    door[r0:, c0:c1] = True
    ortho.colour[door] = (30, 30, 30)
    area.visible &= ~door
    area.visible[r0 - band:, c0 - band:c1 + band] = False
    area.opening_mask = door
    px = ortho.pixel_m
    h_m = ortho.frame.height_m
    area.openings = [Opening(ortho.wall_id, "door", c0 * px, c1 * px, 0.0, h_m - r0 * px)]
    for rows, cols, rgb in objects:
        ortho.colour[rows, cols] = rgb
        area.visible[rows, cols] = False
    return ortho, area


def test_a_door_casing_does_not_swallow_an_object_touching_it() -> None:
    s = ColourRecognitionSettings()
    exit_light = (slice(76, 104), slice(170, 230), (20, 150, 90))  # 28 x 60 px, touches the casing ...
    leg = (slice(100, 106), slice(198, 203), (20, 150, 90))  # ... through a thin strip
    switch = (slice(160, 176), slice(120, 130), (200, 40, 40))  # 6 px left of the casing, not touching it
    ortho, area = _door_with_casing([exit_light, leg, switch])
    rois = colour_rois(ortho, area, s)
    def near(b, box):  # the closing of J_BW may grow a region by a pixel
        return max(abs(x - y) for x, y in zip((b.r0, b.c0, b.r1, b.c1), box, strict=True)) <= 1

    assert any(near(b, (76, 170, 104, 230)) for b in rois), rois  # the exit light alone
    assert any(near(b, (160, 120, 176, 130)) for b in rois), rois  # the switch beside the casing, whole
    assert all(b.height < 60 for b in rois)  # no RoI holds the casing
    kept = replace(s, casing_max_m=0.0)  # without frame removal: one RoI of casing and exit light
    assert any(b.r0 == 76 and b.height > 150 for b in colour_rois(ortho, area, kept))


def test_a_region_longer_than_any_object_gathers_no_object_into_its_roi(library) -> None:
    """A dark rail along the wall and up its end, longer than any object, is no object's part:
    a socket inside its box keeps a RoI of its own (merged with the rail, the RoI would be too
    long to match)."""
    templates, protos = library
    s = ColourRecognitionSettings()
    ortho, area = make_wall(seed=12, colour=WALL, holes=0)
    for rows, cols in ((slice(200, 208), slice(40, 460)), (slice(40, 208), slice(40, 48))):
        ortho.colour[rows, cols] = (40, 35, 30)  # an L of rail, 2.1 m by 0.84 m
        area.visible[rows, cols] = False
    paste(ortho, area, templates["socket"], (150.0, 250.0), seed=3)  # inside the L's box, apart from it
    rois = colour_rois(ortho, area, s, largest_px=protos.largest_footprint_px)
    assert [b for b in rois if b.width > 400]  # the rail, a RoI of its own
    cands = match_colour(ortho, area, rois, protos, s)
    assert [x.class_id for x in cands if np.hypot(x.centre[0] - 150, x.centre[1] - 250) < 2] == ["socket"]
    merged = colour_rois(ortho, area, s)  # without the library's limit: one RoI, too long to match
    assert len(merged) == 1 and not match_colour(ortho, area, merged, protos, s)
