"""Recognition with geometry (depth_recognition.py, paper section 4.2)."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from sbsc_core.recognition.depth_recognition import depth_rois, match_depth
from sbsc_core.recognition.matching import cluster_boxes
from sbsc_core.recognition.templates import make_templates
from sbsc_core.settings import DepthRecognitionSettings
from sbsc_core.types import Box
from tests.recognition_synth import PIXEL_M, make_wall, paste, synthetic_library

PLACES = [("socket", (50.3, 60.7), 0), ("panel", (150.0, 200.0), 0), ("knob", (60.0, 300.0), 0),
          ("arrow", (200.0, 400.0), 90), ("arrow", (250.0, 80.0), 180), ("sign", (100.0, 420.0), 0),
          ("socket", (230.0, 300.0), 0)]


@pytest.fixture(scope="module")
def scene():
    templates = make_templates(synthetic_library(), PIXEL_M)
    ortho, area = make_wall(seed=1)
    for i, (cid, centre, rot) in enumerate(PLACES):
        paste(ortho, area, templates[cid], centre, rot, seed=i)
    return templates, ortho, area


def _contains(box: Box, r: float, c: float) -> bool:
    return box.r0 <= r < box.r1 and box.c0 <= c < box.c1


def test_rois_cover_each_protruding_object_and_nothing_else(scene) -> None:
    templates, ortho, area = scene
    rois = depth_rois(ortho, area, DepthRecognitionSettings())
    protruding = [p for p in PLACES if templates[p[0]].depth is not None]
    for cid, (r, c), _ in protruding:
        assert sum(_contains(b, r, c) for b in rois) == 1, cid
    # one RoI per object: the flat sign, the no-data holes and the noise give none
    assert len(rois) == len(protruding)


def test_plain_wall_with_holes_has_no_roi() -> None:
    ortho, area = make_wall(seed=3, holes=12)
    assert depth_rois(ortho, area, DepthRecognitionSettings()) == []


def test_true_class_matches_with_high_rho_and_subpixel_centre(scene) -> None:
    templates, ortho, area = scene
    s = DepthRecognitionSettings()
    cands = match_depth(ortho, area, depth_rois(ortho, area, s), templates, s)
    for cid, (r, c), rot in PLACES:
        if templates[cid].depth is None:
            continue
        best = max((x for x in cands if x.class_id == cid and np.hypot(x.centre[0] - r, x.centre[1] - c) < 3),
                   key=lambda x: x.score, default=None)
        assert best is not None, (cid, r, c)
        assert best.score > 0.9
        assert np.hypot(best.centre[0] - r, best.centre[1] - c) < 1.0
        assert best.source == "depth" and best.wall_id == "W01"
        if cid == "arrow":  # asymmetric: the rotation is recovered and the box turned
            assert abs((best.rotation_deg - rot + 180) % 360 - 180) <= 3.0
            if best.rotation_deg == rot:
                assert (best.box.height, best.box.width) == ((30, 16) if rot % 180 else (16, 30))


def test_wrong_class_stays_below_mu_d(scene) -> None:
    templates, ortho, area = scene
    s = DepthRecognitionSettings()
    cands = match_depth(ortho, area, depth_rois(ortho, area, s), templates, s)
    # the panel (40 x 60 px) is nowhere near a socket, a knob or an arrow
    for cid, (r, c), _ in PLACES:
        if cid in ("socket", "knob"):
            assert not any(x.class_id == "panel" and _contains(x.box, r, c) for x in cands)
    panel_r, panel_c = 150.0, 200.0
    assert not any(x.class_id in ("socket", "knob") and _contains(x.box, panel_r, panel_c) for x in cands)
    # every candidate passed the threshold
    assert all(x.score >= s.mu_d for x in cands)


def test_without_rotations_a_turned_asymmetric_object_is_missed(scene) -> None:
    templates, ortho, area = scene
    s = replace(DepthRecognitionSettings(), rotations=(0,))
    cands = match_depth(ortho, area, depth_rois(ortho, area, s), templates, s)
    assert not any(x.class_id == "arrow" and np.hypot(x.centre[0] - 200, x.centre[1] - 400) < 3 for x in cands)


def test_relief_amplitude_must_agree() -> None:
    templates = make_templates(synthetic_library(), PIXEL_M)
    ortho, area = make_wall(seed=5, holes=0)
    weak = replace(templates["panel"], depth=templates["panel"].depth * 0.3)  # same shape, 30 % relief
    paste(ortho, area, weak, (120.0, 250.0), seed=1)
    s = DepthRecognitionSettings()
    rois = depth_rois(ortho, area, s)
    assert len(rois) == 1
    assert not [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "panel"]
    loose = replace(s, gain_range=(0.1, 10.0))
    assert [x for x in match_depth(ortho, area, rois, templates, loose) if x.class_id == "panel"]


def test_two_instances_in_one_roi_are_both_found() -> None:
    templates = make_templates(synthetic_library(), PIXEL_M)
    ortho, area = make_wall(seed=6, holes=0)
    paste(ortho, area, templates["socket"], (100.0, 100.0), seed=1)
    paste(ortho, area, templates["socket"], (100.0, 122.0), seed=2)
    ortho.depth[99:101, 107:116] = 0.006  # a cable between them: one clustered RoI
    s = DepthRecognitionSettings()
    rois = depth_rois(ortho, area, s)
    assert len(rois) == 1
    socks = [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "socket"]
    assert sorted(round(x.centre[1]) for x in socks) == [100, 122]


def test_a_frame_around_the_wall_gathers_no_objects_into_its_roi() -> None:
    """A door frame joined to the skirting spans the wall: its box would merge every object
    inside it into one RoI, which holds at most ``max_peaks_per_roi`` of a class."""
    templates = make_templates(synthetic_library(), PIXEL_M)
    ortho, area = make_wall(seed=9, holes=0)
    for r0, r1, c0, c1 in ((40, 280, 20, 30), (40, 280, 470, 480), (270, 280, 20, 480)):
        ortho.depth[r0:r1, c0:c1] = 0.006  # a 5 cm architrave, 6 mm proud, and the skirting
    cols = [80, 160, 240, 320, 400]
    for i, c in enumerate(cols):
        paste(ortho, area, templates["socket"], (150.0, float(c)), seed=i)
    s = DepthRecognitionSettings()
    rois = depth_rois(ortho, area, s, templates)
    assert sum(r.height > 200 for r in rois) == 1  # the frame: its own RoI
    for c in cols:  # each socket in a RoI of its own size
        assert [r for r in rois if _contains(r, 150, c) and r.width < 40], c
    socks = [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "socket"]
    assert sorted(round(x.centre[1]) for x in socks) == cols


def test_a_part_of_something_larger_is_not_an_instance() -> None:
    """Isolation: relief continuing past a side of the footprint (a casing, a double socket)."""
    templates = make_templates(synthetic_library(), PIXEL_M)
    ortho, area = make_wall(seed=8, holes=0)
    paste(ortho, area, templates["socket"], (100.0, 100.0), seed=1)
    paste(ortho, area, templates["socket"], (100.0, 116.0), seed=2)  # touching: a double plate
    s = DepthRecognitionSettings()
    rois = depth_rois(ortho, area, s)
    socks = [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "socket"]
    assert socks == []
    loose = replace(s, isolation_max_occupancy=1.0)
    socks = [x for x in match_depth(ortho, area, rois, templates, loose) if x.class_id == "socket"]
    cols = sorted(x.centre[1] for x in socks)
    assert len(cols) == 2 and abs(cols[0] - 100) < 2 and abs(cols[1] - 116) < 2


def test_cluster_boxes_merges_overlapping_and_touching() -> None:
    boxes = [Box(0, 0, 10, 10), Box(5, 5, 15, 15), Box(30, 30, 40, 40), Box(16, 0, 20, 4), Box(100, 100, 101, 101)]
    out = cluster_boxes(boxes, gap_px=2)
    assert Box(0, 0, 20, 15) in out  # (0..15) grown by 2 touches (16..20)
    assert Box(30, 30, 40, 40) in out and len(out) == 3
    assert len(cluster_boxes(boxes, gap_px=0)) == 4


def test_holes_take_the_lowest_relief_around_them() -> None:
    from sbsc_core.recognition.depth_recognition import depth_image

    templates = make_templates(synthetic_library(), PIXEL_M)
    ortho, area = make_wall(seed=10, holes=0)
    paste(ortho, area, templates["panel"], (120.0, 200.0), seed=1)
    ortho.depth[125:135, 195:205] = np.nan  # unseen patch inside the panel's face (50 mm)
    ortho.depth[100:140, 221:231] = np.nan  # shadow on the wall beside the panel
    jd = depth_image(ortho, area, DepthRecognitionSettings())
    assert np.all(np.abs(jd[127:133, 197:203] - 0.05) < 0.006)  # filled like the face
    assert np.all(np.abs(jd[102:138, 224:231]) < 0.004)  # filled like the wall
    s = DepthRecognitionSettings()
    rois = depth_rois(ortho, area, s)
    panels = [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "panel"]
    assert len(panels) == 1 and np.hypot(panels[0].centre[0] - 120, panels[0].centre[1] - 200) < 1


# --------------------------------------------------------------------------- unseen pixels


def _unseen_below(ortho, area, row: int) -> None:
    """No data below ``row`` (the wall under a scanner's field of view)."""
    ortho.depth[row:] = np.nan
    ortho.mask[row:] = False
    area.visible[row:] = False


def test_masked_ncc_is_the_correlation_over_known_pixels() -> None:
    from sbsc_core.recognition.matching import masked_ncc

    rng = np.random.default_rng(0)
    region = rng.normal(0, 0.003, (30, 40)).astype(np.float32)
    tmpl = rng.normal(0, 0.003, (9, 11)).astype(np.float32)
    known = rng.random((30, 40)) > 0.3
    got = masked_ncc(region, known, tmpl)
    for y, x in [(0, 0), (5, 17), (21, 29), (10, 3)]:
        m = known[y:y + 9, x:x + 11]
        a, b = region[y:y + 9, x:x + 11][m].astype(float), tmpl[m].astype(float)
        a, b = a - a.mean(), b - b.mean()
        assert got[y, x] == pytest.approx((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum()), abs=1e-4)
    # all known: the plain normalised cross-correlation
    import cv2
    full = masked_ncc(region, np.ones_like(known), tmpl)
    assert np.allclose(full, cv2.matchTemplate(region, tmpl, cv2.TM_CCOEFF_NORMED), atol=1e-4)


def test_partly_seen_object_is_matched_on_its_seen_part() -> None:
    """A panel whose lower 30 % is unseen: the filled wall level there hid it from the plain NCC."""
    templates = make_templates(synthetic_library(), PIXEL_M)
    s = DepthRecognitionSettings()
    ortho, area = make_wall(seed=12, holes=0)
    paste(ortho, area, templates["panel"], (150.0, 200.0), seed=1)  # rows 120..179
    _unseen_below(ortho, area, 162)
    rois = depth_rois(ortho, area, s)
    assert any(_contains(b, 150.0, 200.0) for b in rois)
    panels = [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "panel"]
    assert len(panels) == 1 and np.hypot(panels[0].centre[0] - 150, panels[0].centre[1] - 200) < 1.5
    # the plain correlation alone (no masked path) misses it (at best a match pushed up into the seen wall)
    plain = replace(s, full_known_share=0.0)
    assert not [x for x in match_depth(ortho, area, rois, templates, plain)
                if x.class_id == "panel" and np.hypot(x.centre[0] - 150, x.centre[1] - 200) < 3]


def test_an_object_seen_on_less_than_min_known_share_is_no_match() -> None:
    templates = make_templates(synthetic_library(), PIXEL_M)
    s = DepthRecognitionSettings()
    ortho, area = make_wall(seed=13, holes=0)
    paste(ortho, area, templates["panel"], (150.0, 200.0), seed=1)
    _unseen_below(ortho, area, 148)  # 47 % of it seen
    rois = depth_rois(ortho, area, s)
    # no match, neither here nor pushed up into the seen wall beside the refused peak
    assert not [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "panel"]
    loose = replace(s, min_known_share=0.3)
    panels = [x for x in match_depth(ortho, area, rois, templates, loose) if x.class_id == "panel"]
    assert len(panels) == 1 and np.hypot(panels[0].centre[0] - 150, panels[0].centre[1] - 200) < 1.5


def test_plausibility_checks_ignore_unseen_pixels() -> None:
    from sbsc_core.recognition.depth_recognition import isolation, relief_overlap
    from sbsc_core.recognition.matching import padded_template

    model = np.full((20, 20), 0.01, np.float32)
    jd = np.zeros((60, 60), np.float32)
    jd[20:40, 20:40] = 0.01
    jd[30:, :] = 0.0  # unseen below row 30, filled at wall level
    jd[42:, 20:] = 0.01  # ... and a guess that would look like relief below it
    known = np.ones_like(jd, bool)
    known[30:] = False
    box = Box(20, 20, 40, 40)
    tp = padded_template(model, 4)
    assert relief_overlap(jd, tp, box, 4, 0.005, gain=1.0) < 0.5
    assert relief_overlap(jd, tp, box, 4, 0.005, gain=1.0, known=known) == pytest.approx(1.0)
    assert isolation(jd, box, 0.005, 2, 3) == 1.0  # the strip below "has relief"
    assert isolation(jd, box, 0.005, 2, 3, known=known) == 0.0  # ... but it is unseen


def test_a_mixed_pixel_trail_is_not_something_larger() -> None:
    """A 5 cm deep box seen obliquely: mixed ranges ramp down to the wall beside one edge.
    That side strip stands out, but falls at every pixel to the wall: a trail, not a larger
    object. Relief that levels off (a neighbour's recessed face) or rises again is not."""
    from sbsc_core.recognition.depth_recognition import is_trail, isolation

    jd = np.zeros((60, 80), np.float32)
    jd[20:40, 20:40] = 0.05
    jd[20:40, 40:57] = np.linspace(0.047, 0.0, 17, dtype=np.float32)  # the ramp, 3 mm per pixel
    box = Box(20, 20, 40, 40)
    assert isolation(jd, box, 0.02, 2, 3) == 1.0
    assert isolation(jd, box, 0.02, 2, 3, trails=True) == 0.0
    jd[20:40, 47:57] = 0.03  # the ramp levels off: a larger object beside the box
    assert isolation(jd, box, 0.02, 2, 3, trails=True) == 1.0
    assert is_trail(np.array([0.033, 0.030, 0.027, 0.024, 0.021, 0.018]), 0.02)
    assert is_trail(-np.array([0.033, 0.030, 0.027, 0.024, 0.021, 0.018]), 0.02)  # a recess the same
    assert not is_trail(np.array([0.010, 0.009, 0.008, 0.005, 0.005, 0.006, 0.012]), 0.004)  # a double plate
    assert not is_trail(np.array([0.033, 0.030, 0.027, 0.026]), 0.02)  # never reaches the wall
    assert not is_trail(np.array([0.01, 0.005]), 0.02)  # no relief beside the box


# --------------------------------------------------------------------------- stepped wall


def _flush_templates() -> dict:
    from sbsc_core.types import ModelLibrary
    from tests.recognition_synth import make_model, socket_like

    view, depth = socket_like(w_px=24, h_px=24, relief_m=0.0037)  # a flush built-in socket
    return make_templates(ModelLibrary({"flush": make_model("flush", view, depth)}, root="synthetic"), PIXEL_M)


def test_wall_level_follows_a_long_step_but_not_a_flat_sign() -> None:
    from sbsc_core.recognition.depth_recognition import depth_image_known, wall_level

    s = replace(DepthRecognitionSettings(), refit_plane=False)  # the level alone, not the plane fit
    ortho, area = make_wall(seed=14, holes=0)
    ortho.depth[40:100, 100:160] += 0.003  # a 30 cm flat sign
    jd, known = depth_image_known(ortho, area, s)
    assert np.all(wall_level(jd, known, ortho.pixel_m, s) == 0.0)  # the sign is no step of the wall
    ortho.depth[240:, :400] += 0.003  # a second station's wall, 3 mm off, bottom left
    jd, known = depth_image_known(ortho, area, s)
    level = wall_level(jd, known, ortho.pixel_m, s)
    assert np.all(np.abs(level[265:, 20:375] - (0.003 - s.level_dead_m)) < 0.0005)
    assert np.all(level[:200] == 0.0) and np.all(level[:, 430:] == 0.0)  # the sign, the plain wall


def test_flush_object_on_a_stepped_wall_is_found() -> None:
    """A 3 mm step of the wall under a 3.7 mm flush socket: isolation used to refuse it."""
    templates = _flush_templates()
    s = DepthRecognitionSettings()
    ortho, area = make_wall(seed=15, holes=0)
    ortho.depth[255:, :350] += 0.003  # a second station's wall, 3 mm off, bottom left
    paste(ortho, area, templates["flush"], (272.0, 200.0), seed=2)
    ortho.depth[260:285, 187:213] += 0.003  # the socket is mounted on the stepped wall
    rois = depth_rois(ortho, area, s)
    assert [b for b in rois if _contains(b, 272.0, 200.0) and b.width < 40]  # its own RoI
    found = [x for x in match_depth(ortho, area, rois, templates, s) if x.class_id == "flush"]
    assert len(found) == 1 and np.hypot(found[0].centre[0] - 272, found[0].centre[1] - 200) < 1.5
    flat = replace(s, level_max_m=0.0)  # without the wall level: the step hides it
    assert not [x for x in match_depth(ortho, area, depth_rois(ortho, area, flat), templates, flat)
                if x.class_id == "flush"]


def test_a_further_depth_model_finds_another_design_of_the_class() -> None:
    """A library model of another product misses the object; the object's own relief as a
    further depth model (an exemplar from a reviewed floor) finds it, and costs nothing elsewhere."""
    from dataclasses import replace as dc_replace

    from sbsc_core.types import ModelLibrary
    from tests.recognition_synth import make_model, panel_like, socket_like

    view, ref = socket_like(relief_m=0.012)
    _, other = panel_like(w_px=16, h_px=16, relief_m=0.03)  # the design on site: sloped, deeper
    scene_t = make_templates(ModelLibrary({"socket": make_model("socket", view, other)}), PIXEL_M)["socket"]
    ortho, area = make_wall(seed=5)
    paste(ortho, area, scene_t, (120.0, 200.0), 0, seed=1)
    s = DepthRecognitionSettings()
    rois = depth_rois(ortho, area, s)
    lib = make_templates(ModelLibrary({"socket": make_model("socket", view, ref)}), PIXEL_M)
    near = lambda cands: [x for x in cands if np.hypot(x.centre[0] - 120, x.centre[1] - 200) < 3]  # noqa: E731
    before = near(match_depth(ortho, area, rois, lib, s))
    learnt = {"socket": dc_replace(lib["socket"], extra_depths=[scene_t.depth.copy()])}
    after = near(match_depth(ortho, area, rois, learnt, s))
    assert not before or max(x.score for x in before) < 0.9
    assert after and max(x.score for x in after) > 0.9


def test_candidates_carry_their_relief_gain_and_fit(scene) -> None:
    """A true object: gain ~1 and the reliefs overlap; an object 1.6x as deep but of the same
    outline still correlates, and its candidate says so (the confidence reads both)."""
    templates, ortho, area = scene
    s = DepthRecognitionSettings()
    panels = [x for x in match_depth(ortho, area, depth_rois(ortho, area, s), templates, s) if x.class_id == "panel"]
    assert panels and panels[0].gain == pytest.approx(1.0, abs=0.15) and panels[0].relief_iou > 0.8
    deep_ortho, deep_area = make_wall(seed=5, holes=0)
    paste(deep_ortho, deep_area, replace(templates["panel"], depth=templates["panel"].depth * 1.6), (120.0, 250.0))
    deep = [x for x in match_depth(deep_ortho, deep_area, depth_rois(deep_ortho, deep_area, s), templates, s)
            if x.class_id == "panel"]
    assert deep and deep[0].gain == pytest.approx(1.6, abs=0.2)


def test_face_gain_reads_a_deep_object_s_face_whatever_its_mixed_pixels_do() -> None:
    """A 12 cm deep panel whose outline a scan's mixed pixels widen by 3 pixels of half its
    depth (as the realistic scanner's do): the match's gain, read mostly on the wall ring
    around the footprint, falls far below 1, while its face stands out exactly as far as the
    model's: face_gain ~1. A panel of that outline 0.7x as deep: face_gain ~0.7."""
    s = DepthRecognitionSettings()
    templates = make_templates(synthetic_library(), PIXEL_M)
    deep = replace(templates["panel"], depth=templates["panel"].depth * (0.12 / 0.05))
    found = {}
    for depth_factor in (1.0, 0.7):
        ortho, area = make_wall(seed=7, holes=0)
        paste(ortho, area, replace(deep, depth=deep.depth * depth_factor), (150.0, 250.0))
        stands = np.nan_to_num(ortho.depth) > 0.01
        grown = stands
        for share in (0.75, 0.5, 0.25):  # the trail of mixed ranges around the outline, falling to the wall
            ring = ndimage.binary_dilation(grown) & ~grown
            ortho.depth[ring] = share * 0.12 * depth_factor
            grown = grown | ring
        lib = {"panel": deep}
        cands = match_depth(ortho, area, depth_rois(ortho, area, s), lib, s)
        found[depth_factor] = max(cands, key=lambda c: c.score)
    right, shallow = found[1.0], found[0.7]
    assert right.gain < 0.8  # the wall ring's trail pulls the window's amplitude down
    assert right.face_gain == pytest.approx(1.0, abs=0.05)
    assert shallow.face_gain == pytest.approx(0.7, abs=0.05)


def test_face_gain_leaves_the_outline_and_unseen_pixels_out() -> None:
    from sbsc_core.recognition.depth_recognition import face_gain, face_region

    model = np.zeros((20, 20), np.float32)
    model[2:18, 2:18] = 0.02
    relief = np.zeros((40, 40), np.float32)
    relief[12:28, 12:28] = 0.03  # 1.5x as deep
    relief[12:14, 12:28] = 0.0  # its top rows blurred into the wall: part of the outline
    box = Box(10, 10, 30, 30)
    face = face_region(model, 2)
    assert face.sum() == 12 * 12
    assert face_gain(relief, model, box, region=face) == pytest.approx(1.5)
    assert face_gain(relief, model, box, region=face_region(model, 0)) < 1.4
    known = np.ones((40, 40), bool)
    relief[20, 20] = 0.5  # a spike where the scan has no data
    known[20, 20] = False
    assert face_gain(relief, model, box, region=face, known=known) == pytest.approx(1.5)
    tiny = np.zeros((5, 5), np.float32)
    tiny[1:4, 1:4] = 0.01
    assert face_region(tiny, 2).sum() == 9  # too small to erode: its whole footprint
    assert not face_region(np.zeros((20, 20), np.float32), 2).any()
    assert face_gain(relief, np.zeros((20, 20), np.float32), box, region=np.zeros((20, 20), bool)) is None
    assert face_gain(relief, model, Box(10, 10, 31, 30), region=face) is None  # not the model's size


def test_see_through_gaps_are_closed_and_solid_models_left_alone() -> None:
    from sbsc_core.recognition.depth_recognition import close_see_through

    rails = np.zeros((40, 60), np.float32)
    rails[:, :4] = rails[:, -4:] = 0.09  # two posts
    for r in range(0, 40, 10):
        rails[r:r + 5, 4:-4] = 0.1  # and tubes between them, the wall showing in between
    closed = close_see_through(rails, 0.1)
    assert closed is not None
    assert closed[7, 30] == pytest.approx(0.097, abs=0.005)  # a gap between tubes: the rim's mean relief
    assert closed[0, 30] == pytest.approx(0.1) and closed[39, 30] == 0.0  # the open bottom stays wall
    solid = np.full((20, 20), 0.01, np.float32)
    assert close_see_through(solid, 0.1) is None
    recess = np.full((20, 20), 0.01, np.float32)
    recess[5:15, 5:15] = 0.004  # a socket's recess is part of the object, no gap
    assert close_see_through(recess, 0.1) is None


def test_parts_that_fit_one_footprint_are_grouped() -> None:
    from sbsc_core.recognition.matching import group_boxes

    parts = [Box(0, 0, 5, 40), Box(10, 0, 15, 40), Box(20, 0, 25, 40), Box(100, 100, 110, 110)]
    assert group_boxes(parts, height=30, width=45, gap_px=6) == [Box(0, 0, 25, 40)]
    assert group_boxes(parts, height=30, width=45, gap_px=3) == []  # too far apart to be one object
    assert group_boxes(parts, height=12, width=45, gap_px=6) == []  # together too big for the model


def test_fill_gaps_fills_a_small_gap_with_its_neighbours_mean_and_leaves_a_large_hole():
    from sbsc_core.recognition.depth_recognition import fill_gaps

    ok = np.ones((60, 60), bool)
    ok[30, 30] = False  # a gap: known pixels all around
    ok[0:20, 0:20] = False  # a hole: its middle has no known neighbour within the Gaussian's reach
    grey = np.where(ok, 0.02, 0.0).astype(np.float32)
    rgb = np.zeros((60, 60, 3), np.uint8)
    rgb[ok] = (200, 100, 50)
    for values, want in ((grey, 0.02), (rgb, (200, 100, 50))):
        out, filled = fill_gaps(values, ok, 1.0, 0.5)
        assert out.dtype == np.float32 and filled[30, 30] and not filled[5, 5]
        assert np.allclose(out[30, 30], want, rtol=1e-5) and not np.any(out[5, 5])
        assert np.array_equal(out[ok], np.asarray(values, np.float32)[ok])
