"""Consensus of depth and colour candidates (consensus.py, paper section 4.4)."""

import numpy as np
import pytest

from sbsc_core.recognition.consensus import (
    ConsensusHit,
    coherence_level,
    coherence_matrix,
    consensus,
    suppress_conflicts,
    weighted_centre,
)
from sbsc_core.recognition.matching import box_at
from sbsc_core.settings import ConsensusSettings
from sbsc_core.types import Box, Candidate

S = ConsensusSettings()


def cand(source: str, centre: tuple[float, float], score: float, size=(16, 16), wall="W01", cls="socket") -> Candidate:
    return Candidate(cls, wall, source, box_at(centre, *size), centre, score)


def test_equation_15_cases() -> None:
    a = Box(0, 0, 10, 10)
    assert coherence_level(a, a) == 1.0  # identical
    assert coherence_level(a, Box(20, 20, 30, 30)) == 0.0  # disjoint (case II)
    assert coherence_level(a, Box(10, 0, 20, 10)) == 0.0  # touching is not intersecting
    # diagonal half shift: union 175 px over the 15 x 15 enclosing box
    assert coherence_level(a, Box(5, 5, 15, 15)) == pytest.approx(175 / 225)
    # a box inside a bigger one: the union is the bigger box
    assert coherence_level(Box(2, 2, 5, 5), a) == 1.0
    psi = coherence_matrix([cand("depth", (5, 5), 0.9)], [], S)
    assert psi.shape == (2, 1) and psi[0, 0] == 0.5  # exclusive (case III)


def test_matrix_rows_columns_and_walls() -> None:
    d = [cand("depth", (50, 50), 0.9), cand("depth", (50, 200), 0.8), cand("depth", (50, 50), 0.9, wall="W02")]
    c = [cand("colour", (51, 49), 0.05), cand("colour", (300, 300), 0.1)]
    psi = coherence_matrix(d, c, S)
    assert psi.shape == (4, 3)
    assert psi[0, 0] > 0.8 and psi[1, 0] == 0 and psi[2, 0] == 0  # other wall never overlaps
    assert (psi[:3, 2] == 0.5).all() and (psi[3, :2] == 0.5).all() and psi[3, 2] == 0


def figure13():
    """Three depth and four colour candidates; pairs (C1,D1), (C4,D2), (C2,D3); C3 alone; D4 alone."""
    d = [cand("depth", (50, 50), 0.95), cand("depth", (50, 150), 0.85), cand("depth", (150, 50), 0.9),
         cand("depth", (250, 250), 0.8)]
    c = [cand("colour", (51, 50), 0.05), cand("colour", (152, 51), 0.1), cand("colour", (150, 300), 0.04),
         cand("colour", (50, 148), 0.12)]
    return d, c


def test_iterative_selection_like_figure_13() -> None:
    d, c = figure13()
    paper = ConsensusSettings(prefer_depth=False)  # ties by goodness only
    hits = consensus(d, c, 4, paper)
    assert len(hits) == 4
    pairs = {(h.depth and d.index(h.depth), h.colour and c.index(h.colour)) for h in hits}
    assert pairs == {(0, 0), (1, 3), (2, 1), (None, 2)}  # C3 beats D4 by goodness at alpha 0.5
    assert [h.source for h in hits][:3] == ["both"] * 3 and hits[3].source == "colour"
    assert hits[3].alpha == 0.5 and hits[3].rho_depth is None and hits[3].rho_colour == 0.04
    assert all(h.alpha > 0.5 for h in hits[:3])
    # by default a depth-only detection outranks a colour-only one at equal alpha
    hits = consensus(d, c, 4, S)
    assert hits[3].depth is d[3] and hits[3].source == "depth"


def test_no_expected_count_stops_when_psi_is_null_and_counts_each_candidate_once() -> None:
    d, c = figure13()
    hits = consensus(d, c, None, S)
    assert len(hits) == 5  # three pairs and two exclusive detections
    assert sum(h.depth is d[3] for h in hits) == 1
    assert consensus(d, c, 0, S) == []
    assert len(consensus(d, c, 2, S)) == 2
    assert consensus([], [], None, S) == []


def test_min_alpha_drops_exclusive_detections() -> None:
    d, c = figure13()
    strict = ConsensusSettings(min_alpha=0.5)
    hits = consensus(d, c, None, strict)
    assert len(hits) == 3 and all(h.source == "both" for h in hits)


def test_equation_16_weights() -> None:
    d = cand("depth", (10.0, 10.0), 0.9)
    c = cand("colour", (12.0, 14.0), 0.1)  # weight 1 - 0.1 = 0.9: the midpoint
    assert weighted_centre(d, c) == pytest.approx((11.0, 12.0))
    c = cand("colour", (12.0, 14.0), 0.55)  # weight 0.45 = half of rho_D
    assert weighted_centre(d, c) == pytest.approx((10 + 2 / 3, 10 + 4 / 3))
    assert weighted_centre(d, None) == (10.0, 10.0)  # exclusive: the candidate's own centre
    assert weighted_centre(None, c) == (12.0, 14.0)
    hit = consensus([d], [c], None, ConsensusSettings(max_disagreement_px=float("inf")))[0]
    assert hit.centre == pytest.approx(weighted_centre(d, c)) and hit.source == "both"


def test_equation_16_only_for_centres_that_agree() -> None:
    """A colour match placed 4 px off the depth match measures another point: depth's centre."""
    d = cand("depth", (10.0, 10.0), 0.9)
    c = cand("colour", (12.0, 14.0), 0.1)
    assert weighted_centre(d, c, 3.0) == (10.0, 10.0)
    assert weighted_centre(d, c, 4.0) == pytest.approx((11.0, 12.0))  # within 4 px: equation 16
    hit = consensus([d], [c], None, ConsensusSettings(max_disagreement_px=3.0))[0]
    assert hit.centre == (10.0, 10.0) and hit.source == "both"
    # by default centres 2 px (10 mm) apart do not agree: each is good to ~2 mm
    c = cand("colour", (12.0, 10.5), 0.1)
    assert consensus([d], [c], None, ConsensusSettings())[0].centre == (10.0, 10.0)
    c = cand("colour", (11.0, 10.5), 0.1)  # 1 px: equation 16
    assert consensus([d], [c], None, ConsensusSettings())[0].centre == pytest.approx((10.5, 10.25))


def _hit(cls: str, centre, alpha: float, rho_d=None, rho_c=None, size=(16, 16), wall="W01") -> ConsensusHit:
    src = "both" if rho_d is not None and rho_c is not None else ("depth" if rho_d is not None else "colour")
    return ConsensusHit(cls, wall, centre, alpha, rho_d, rho_c, src, box=box_at(centre, *size))


def test_cross_class_suppression() -> None:
    hits = {
        "socket": [_hit("socket", (50, 50), 1.0, 0.9, 0.05), _hit("socket", (200, 200), 0.5, 0.95)],
        "switch": [_hit("switch", (51, 50), 0.5, 0.97),  # same place as the socket, lower alpha
                   _hit("switch", (200, 205), 0.5, 0.90)],  # same place, same alpha, worse rho
        "sign": [_hit("sign", (50, 50), 0.5, None, 0.02, wall="W02"),  # other wall: kept
                 _hit("sign", (50, 62), 0.5, None, 0.02)],  # overlaps the socket by 4/16 columns: kept
    }
    out = suppress_conflicts(hits, S)
    assert [h.centre for h in out["socket"]] == [(50, 50), (200, 200)]
    # at equal alpha a depth-only hit outranks a colour-only one of another class
    mixed = {"sign": [_hit("sign", (300, 300), 0.5, None, 0.01)], "knob": [_hit("knob", (302, 300), 0.5, 0.8)]}
    out2 = suppress_conflicts(mixed, S)
    assert out2["sign"] == [] and len(out2["knob"]) == 1
    out2 = suppress_conflicts(mixed, ConsensusSettings(prefer_depth=False))
    assert out2["knob"] == [] and len(out2["sign"]) == 1
    assert out["switch"] == []
    assert len(out["sign"]) == 2
    # a small object inside a big one overlaps fully (intersection over the smaller footprint)
    big = {"panel": [_hit("panel", (100, 100), 1.0, 0.9, 0.1, size=(120, 80))],
           "socket": [_hit("socket", (100, 100), 0.5, 0.99)]}
    out = suppress_conflicts(big, S)
    assert len(out["panel"]) == 1 and out["socket"] == []


def test_goodness_orders_hits() -> None:
    assert _hit("a", (0, 0), 0.5, 0.9).goodness == pytest.approx(0.9)
    assert _hit("a", (0, 0), 0.5, None, 0.1).goodness == pytest.approx(0.9)
    assert _hit("a", (0, 0), 1.0, 0.8, 0.2).goodness == pytest.approx(0.8)
    assert np.isfinite(_hit("a", (0, 0), 1.0).goodness)


def test_a_colour_match_half_over_a_recognized_object_is_suppressed() -> None:
    """Scenario I, every class searched: the colour candidate of a switch placed 3.7 cm under
    a socket (footprints overlapping by 0.48) was a second object; real objects do not overlap."""
    hits = {"socket": [_hit("socket", (50, 50), 1.0, 0.9, 0.03)],
            "switch": [_hit("switch", (58, 49), 0.5, None, 0.03)]}  # 8 rows lower: overlap 0.47
    out = suppress_conflicts(hits, S)
    assert [h.centre for h in out["socket"]] == [(50, 50)] and out["switch"] == []
    loose = suppress_conflicts(hits, ConsensusSettings(suppress_overlap=0.5))
    assert len(loose["switch"]) == 1


def test_an_outscored_depth_match_confirms_no_colour_candidate() -> None:
    """one_room (standard, seed 2): at a socket, depth says socket 0.98 and flush socket 0.82
    and colour says flush socket; the flush socket's pair must not outrank the socket's depth
    match, nor use up the count of the real flush socket elsewhere (depth 0.97)."""
    from sbsc_core.recognition.consensus import consensus_all

    d = [cand("depth", (50, 50), 0.98, cls="socket"), cand("depth", (50, 50), 0.82, cls="flush"),
         cand("depth", (200, 200), 0.97, cls="flush")]
    c = [cand("colour", (50, 50), 0.02, cls="flush")]
    out = consensus_all(d, c, {"socket": 1, "flush": 1}, S)
    assert [h.centre for h in out["socket"]] == [(50, 50)]
    assert [h.centre for h in out["flush"]] == [(200, 200)]
    # without the rule the colour-confirmed weaker match wins the place and the count
    off = consensus_all(d, c, {"socket": 1, "flush": 1}, ConsensusSettings(depth_outscored_margin=float("inf")))
    assert [h.centre for h in off["flush"]] == [pytest.approx((50, 50))] and off["socket"] == []


def test_consensus_all_keeps_the_count_for_the_places_that_are_left() -> None:
    from sbsc_core.recognition.consensus import consensus_all

    # class "switch": a strong pair at (50, 50) and a weaker depth-only one at (200, 200);
    # class "socket": a better pair at the same place (50, 50), so the switch's pair must give way
    d = [cand("depth", (50, 50), 0.90, cls="switch"), cand("depth", (200, 200), 0.85, cls="switch"),
         cand("depth", (50, 50), 0.95, cls="socket")]
    c = [cand("colour", (50, 50), 0.10, cls="switch"), cand("colour", (50, 50), 0.02, cls="socket")]
    out = consensus_all(d, c, {"switch": 1, "socket": 1}, S)
    assert [h.centre for h in out["socket"]] == [(50, 50)] and out["socket"][0].source == "both"
    assert [h.centre for h in out["switch"]] == [(200, 200)]  # the count went to the free place
    # the two-step way spends the switch's only count on the suppressed place
    two = suppress_conflicts({"switch": consensus(d[:2], c[:1], 1, S), "socket": consensus(d[2:], c[1:], 1, S)}, S)
    assert two["switch"] == []
    # without counts: every place once
    out = consensus_all(d, c, None, S)
    assert sorted((k, h.centre) for k, hs in out.items() for h in hs) == [("socket", (50, 50)), ("switch", (200, 200))]
    assert consensus_all(d, c, {"switch": 0, "socket": 0}, S) == {}


# --------------------------------------------------------------------------- bundled library

def _bundled_library():
    from sbsc_core.io.models import load_model_library
    from sbsc_core.paths import bundled_models_dir

    root = bundled_models_dir()
    if not (root.is_dir() and any(root.iterdir())):
        pytest.skip("the bundled library sbsc_core/data/models is not there yet")
    return load_model_library(root)


def _recognise_bundled(wall_colour, seed: int):
    """Paste every bundled class on a synthetic wall; recognise with all classes searched."""
    from sbsc_core.recognition.colour_recognition import colour_rois, learn_prototypes, match_colour
    from sbsc_core.recognition.consensus import consensus_all
    from sbsc_core.recognition.depth_recognition import depth_rois, match_depth
    from sbsc_core.recognition.templates import make_templates
    from sbsc_core.settings import DetectionSettings
    from tests.recognition_synth import make_wall, paste

    lib = _bundled_library()
    s = DetectionSettings()
    t = make_templates(lib, s.orthoimage.pixel_m)
    # lay the classes out on a grid with room around each
    ids = sorted(t)
    cols, gap = 5, 40
    cell_w = max(x.width_px for x in t.values()) + gap
    cell_h = max(x.height_px for x in t.values()) + gap
    rows = (len(ids) + cols - 1) // cols
    ortho, area = make_wall(h_px=rows * cell_h + gap, w_px=cols * cell_w + gap, colour=wall_colour,
                            colour_noise=3.0, depth_noise_m=0.0015, holes=6, seed=seed)
    truth = {}
    for k, cid in enumerate(ids):
        centre = (gap / 2 + (k // cols + 0.5) * cell_h + 0.3, gap / 2 + (k % cols + 0.5) * cell_w - 0.4)
        paste(ortho, area, t[cid], centre, seed=seed + k, depth_noise_m=0.0015)
        truth[cid] = centre
    protos = learn_prototypes(t, s.colour)
    d = match_depth(ortho, area, depth_rois(ortho, area, s.depth), t, s.depth)
    c = match_colour(ortho, area, colour_rois(ortho, area, s.colour), protos, s.colour)
    hits = consensus_all(d, c, None, s.consensus, ids)
    return truth, hits


def _score(truth, hits):
    tp, err, fp = 0, [], 0
    for cid, hs in hits.items():
        for h in hs:
            dist = np.hypot(h.centre[0] - truth[cid][0], h.centre[1] - truth[cid][1])
            if dist < 4:
                tp += 1
                err.append(dist)
            else:
                fp += 1
    return tp, fp, err


@pytest.mark.slow
def test_bundled_library_on_a_neutral_wall() -> None:
    truth, hits = _recognise_bundled((214, 210, 200), seed=11)
    tp, fp, err = _score(truth, hits)
    assert tp >= len(truth) - 1, hits
    assert fp <= 1
    assert np.mean(err) < 1.0  # pixels of 5 mm


@pytest.mark.slow
def test_bundled_library_on_a_low_contrast_wall() -> None:
    truth, hits = _recognise_bundled((240, 240, 236), seed=12)  # the white of most sockets
    tp, fp, err = _score(truth, hits)
    assert tp >= len(truth) - 2, hits
    assert fp <= 1
