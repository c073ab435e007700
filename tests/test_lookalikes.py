"""Look-alike classes (lookalikes.py): two square red signs of the same size with different
pictograms, found from the library itself and told apart by their print."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from sbsc_core.recognition.colour_recognition import (
    ColourImage,
    ColourPrototypes,
    colour_image,
    colour_rois,
    learn_prototypes,
    match_colour,
)
from sbsc_core.recognition.consensus import consensus_all
from sbsc_core.recognition.depth_recognition import depth_rois, match_depth
from sbsc_core.recognition.lookalikes import (
    content_box,
    lookalike_sets,
    prepare_library,
    resolve_on_wall,
)
from sbsc_core.recognition.templates import make_templates
from sbsc_core.settings import DetectionSettings
from sbsc_core.types import Box, Candidate, ModelLibrary, ObjectModel, Orthoimage, WallArea
from tests.recognition_synth import _rgba, make_model, make_wall, paste, socket_like

RED, WHITE = (200, 30, 35), (250, 250, 250)


@dataclass
class _Recognized:
    """A synthetic wall with objects pasted on it, and what the paper's recognizers found."""

    templates: dict
    ortho: Orthoimage
    area: WallArea
    protos: ColourPrototypes
    image: ColourImage
    depth: list[Candidate]
    colour: list[Candidate]


def _recognized(library: ModelLibrary, places: dict[str, tuple[float, float]], s: DetectionSettings, *, seed: int,
                turns: dict[str, int] | None = None, gain: np.ndarray | None = None, **wall) -> _Recognized:
    """Each class of ``places`` pasted at its centre (turned by ``turns``) on ``make_wall(seed, **wall)``,
    seen with the colour ``gain`` of a station (exposure and white balance), and its depth and
    colour candidates."""
    templates = make_templates(library, 0.005)
    ortho, area = make_wall(seed=seed, holes=0, **wall)
    for cid, c in places.items():
        paste(ortho, area, templates[cid], c, (turns or {}).get(cid, 0), seed=seed)
    if gain is not None:
        ortho.colour[:] = np.clip(ortho.colour * gain, 0, 255).astype(np.uint8)
        area.wall_colour = np.median(ortho.colour[area.visible], axis=0).astype(float)
    protos = learn_prototypes(templates, s.colour)
    d = match_depth(ortho, area, depth_rois(ortho, area, s.depth, templates), templates, s.depth)
    img = colour_image(ortho, area, s.colour)
    c = match_colour(ortho, area, colour_rois(ortho, area, s.colour, img), protos, s.colour, image=img)
    return _Recognized(templates, ortho, area, protos, img, d, c)


def _near(cands: list[Candidate], p: tuple[float, float]) -> set[str]:
    """The classes of the candidates within 3 pixels of ``p``."""
    return {x.class_id for x in cands if np.hypot(x.centre[0] - p[0], x.centre[1] - p[1]) < 3}


def _plate(pictogram: str, px: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A 3 mm red square plate with a white pictogram: 'flame' (a block low left and a bar)
    or 'hand' (a ring in the upper right)."""
    rgb = np.empty((px, px, 3), np.uint8)
    rgb[:] = RED
    if pictogram == "flame":
        rgb[22:34, 6:18] = WHITE
        rgb[8:34, 24:28] = WHITE
    else:
        yy, xx = np.mgrid[0:px, 0:px]
        r = np.hypot(yy - 14, xx - 25)
        rgb[(r > 5) & (r < 10)] = WHITE
        rgb[28:33, 6:34] = WHITE
    return _rgba(rgb), np.full((px, px), 0.003, np.float32)


@pytest.fixture(scope="module")
def library() -> ModelLibrary:
    specs = {"extinguisher_sign": _plate("flame"), "call_point_sign": _plate("hand"), "socket": socket_like()}
    return ModelLibrary({k: make_model(k, v, d) for k, (v, d) in specs.items()}, root="synthetic")


def test_lookalike_sets_come_from_the_library(library) -> None:
    s = DetectionSettings()
    templates = make_templates(library, 0.005)
    assert lookalike_sets(templates, s.lookalikes) == [frozenset({"extinguisher_sign", "call_point_sign"})]


def test_a_prepared_library_reaches_a_wall_task_and_decides_alike(library) -> None:
    """The look-alike sets, same-size pairs and relief models made once (prepare_library)
    travel with the prototypes to a wall's task (pickled) and give the same decisions."""
    import pickle

    s = DetectionSettings()
    w = _recognized(library, {"extinguisher_sign": (80.0, 120.0), "call_point_sign": (200.0, 330.0)}, s, seed=0)
    fresh = resolve_on_wall(w.depth, w.colour, w.image, learn_prototypes(w.templates, s.colour), s.lookalikes)
    prepared = prepare_library(learn_prototypes(w.templates, s.colour), s.lookalikes)
    received = pickle.loads(pickle.dumps(prepared))
    made = set(received._cache)
    assert ("relief_models",) in made and ("same_size_pairs", s.lookalikes.size_tolerance) in made
    assert [frozenset({"extinguisher_sign", "call_point_sign"})] in list(received._cache.values())
    again = resolve_on_wall(w.depth, w.colour, w.image, received, s.lookalikes)
    assert set(received._cache) - made  # only this wall's prototypes were made there
    assert all(k[0] not in ("lookalike_sets", "same_size_pairs", "relief_models") for k in set(received._cache) - made)
    assert [(c.class_id, c.centre, c.score, c.lookalike_margin) for c in again[0] + again[1]] == \
        [(c.class_id, c.centre, c.score, c.lookalike_margin) for c in fresh[0] + fresh[1]]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_size_signs_are_told_apart_by_their_pictogram(library, seed: int) -> None:
    s = DetectionSettings()
    rng = np.random.default_rng(seed)
    places = {"extinguisher_sign": (80.0 + rng.uniform(-0.5, 0.5), 120.0), "call_point_sign": (200.0, 330.0)}
    turns = {"extinguisher_sign": 0, "call_point_sign": int(rng.choice([0, 90]))}
    w = _recognized(library, places, s, seed=seed, turns=turns)
    # the paper's recognizers alone cannot tell: depth gives both classes at both places
    assert {x.class_id for x in w.depth} >= set(places)
    d2, c2 = resolve_on_wall(w.depth, w.colour, w.image, w.protos, s.lookalikes)
    hits = consensus_all(d2, c2, None, s.consensus, sorted(w.templates))
    found = {h.class_id: h.centre for v in hits.values() for h in v}
    assert set(found) == set(places)
    for cid, (r, col) in places.items():
        assert np.hypot(found[cid][0] - r, found[cid][1] - col) < 2.0, cid
    assert all(x.lookalike_margin is not None and x.lookalike_margin > 0 for x in d2 if x.class_id in places)


# --------------------------------------------------------------------------- rendered look-alike signs

@pytest.fixture(scope="module", params=["standard", "alt"])
def rendered_signs(request) -> tuple[str, ModelLibrary]:
    """The two signs of a development design set made same-size 0.20 m square plates (each
    in its own catalogue footprint: 0.21 x 0.30 m and 0.21 x 0.21 m), rendered like the
    library (the simulator's straight-on scan), plus a socket."""
    from sbsc_core.simulate.designs_lookalike import lookalike_builder
    from sbsc_core.simulate.library import model_json, render_model

    builder = lookalike_builder(request.param)
    models = {}
    for cid in ("extinguisher_sign", "fire_alarm_switch_sign", "socket_x1"):
        r = render_model(cid, pixel_m=0.0025, n_views=1, supersample=2, object_builder=builder)
        doc = model_json(cid)
        models[cid] = ObjectModel(class_id=cid, name=doc["name"], ifc_class=doc["ifc_class"],
                                  predefined_type=doc["predefined_type"], width_m=doc["width_m"],
                                  height_m=doc["height_m"], colour_views=r.colour_views, depth=r.depth)
    return request.param, ModelLibrary(models, root="rendered")


def test_same_size_plates_in_different_footprints_are_lookalikes(rendered_signs) -> None:
    _, library = rendered_signs
    templates = make_templates(library, 0.005)
    assert templates["extinguisher_sign"].height_px != templates["fire_alarm_switch_sign"].height_px
    assert content_box(templates["extinguisher_sign"]).height == content_box(templates["fire_alarm_switch_sign"]).height
    assert frozenset({"extinguisher_sign", "fire_alarm_switch_sign"}) in lookalike_sets(
        templates, DetectionSettings().lookalikes)


@pytest.mark.parametrize("seed", [3, 4])
def test_rendered_lookalike_signs_are_not_swapped(rendered_signs, seed: int) -> None:
    """Both signs on one wall, seen with another exposure and white balance than the
    library's: the paper's recognizers give both classes at both places (a coin toss, the
    swap of issue 13); after the look-alike step each place has its own class."""
    _, library = rendered_signs
    s = DetectionSettings()
    rng = np.random.default_rng(seed)
    places = {"extinguisher_sign": (110.0 + rng.uniform(-0.5, 0.5), 90.0 + rng.uniform(-0.5, 0.5)),
              "fire_alarm_switch_sign": (150.0, 300.0 + rng.uniform(-0.5, 0.5))}
    gain = np.array([1.12, 1.0, 0.86]) * rng.uniform(0.85, 1.1)  # exposure and white balance of the station
    w = _recognized(library, places, s, seed=seed, gain=gain, w_px=420)
    for p in places.values():
        assert _near(w.depth, p) == set(places)  # depth alone cannot tell
    d2, c2 = resolve_on_wall(w.depth, w.colour, w.image, w.protos, s.lookalikes)
    for cid, p in places.items():
        assert _near(d2, p) == {cid}
        assert _near(c2, p) <= {cid}
    hits = consensus_all(d2, c2, None, s.consensus, sorted(w.templates))
    found = {h.class_id: h.centre for v in hits.values() for h in v}
    for cid, (r, col) in places.items():
        assert np.hypot(found[cid][0] - r, found[cid][1] - col) < 2.0, cid


# --------------------------------------------------------------------------- white plates on a white wall

def _switch_like(px: int = 16, relief_m: float = 0.012) -> tuple[np.ndarray, np.ndarray]:
    """A white square plate with a proud rocker: the same size and colour as a white
    :func:`socket_like`, another relief."""
    rgb = np.empty((px, px, 3), np.uint8)
    rgb[:] = (245, 245, 240)
    depth = np.full((px, px), relief_m, np.float32)
    depth[4:12, 5:11] = relief_m * 1.35
    return _rgba(rgb), depth


WALL = (200, 196, 185)  # a light wall: the white plates stand out in colour, their prints hardly


@pytest.fixture(scope="module")
def white_plates() -> ModelLibrary:
    sock_v, sock_d = socket_like(body=(245, 245, 240), hole=(245, 245, 240))
    sw_v, sw_d = _switch_like()
    return ModelLibrary({"socket": make_model("socket", sock_v, sock_d), "switch": make_model("switch", sw_v, sw_d),
                         "sign": make_model("sign", *_plate("flame"))}, root="synthetic")


def test_plates_the_colour_classifier_cannot_tell_apart_are_lookalikes_on_a_wall(white_plates) -> None:
    from sbsc_core.recognition.lookalikes import colour_confusable

    s = DetectionSettings()
    templates = make_templates(white_plates, 0.005)
    ortho, area = make_wall(seed=0, holes=0, colour=WALL)
    img = colour_image(ortho, area, s.colour)
    protos = learn_prototypes(templates, s.colour).for_wall(img.wall_rgb, img.threshold, img.noise_rgb)
    pairs = colour_confusable(protos, templates, s.lookalikes, s.colour.mu_c)
    assert frozenset({"socket", "switch"}) in pairs
    assert not any("sign" in p for p in pairs)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_white_plates_are_told_apart_by_their_fine_relief(white_plates, seed: int) -> None:
    """A socket and a switch, plain white plates on a light wall: their prints are the same,
    the fine relief (the socket's cup, the switch's rocker) decides."""
    from sbsc_core.recognition.depth_recognition import depth_images

    s = DetectionSettings()
    rng = np.random.default_rng(seed)
    places = {"socket": (100.0 + rng.uniform(-0.5, 0.5), 120.0), "switch": (180.0, 330.0 + rng.uniform(-0.5, 0.5))}
    w = _recognized(white_plates, places, s, seed=seed, colour=WALL)
    relief = depth_images(w.ortho, w.area, s.depth).levelled
    d2, c2 = resolve_on_wall(w.depth, w.colour, w.image, w.protos, s.lookalikes, relief=relief)
    for cid, p in places.items():
        assert _near(d2, p) <= {cid}, (cid, _near(w.depth, p), _near(d2, p))
        assert _near(c2, p) <= {cid}, (cid, _near(w.colour, p), _near(c2, p))
    hits = consensus_all(d2, c2, None, s.consensus, sorted(w.templates))
    found = {h.class_id for v in hits.values() for h in v}
    assert found == set(places)


def test_white_plates_without_print_are_told_apart_by_relief_alone(white_plates) -> None:
    """On a wall of their own colour the plates show no print at all (no colour views, no
    colour candidates): the relief alone decides between the depth candidates."""
    from sbsc_core.recognition.depth_recognition import depth_images

    s = DetectionSettings()
    templates = make_templates(white_plates, 0.005)
    ortho, area = make_wall(seed=5, holes=0, colour=(245, 245, 240))
    places = {"socket": (100.0, 120.0), "switch": (180.0, 330.0)}
    for cid, c in places.items():
        paste(ortho, area, templates[cid], c, 0, seed=5)
    protos = learn_prototypes(templates, s.colour)
    d = match_depth(ortho, area, depth_rois(ortho, area, s.depth, templates), templates, s.depth)
    img = colour_image(ortho, area, s.colour)
    assert not {"socket", "switch"} & set(protos.for_wall(img.wall_rgb, img.threshold, img.noise_rgb))
    relief = depth_images(ortho, area, s.depth).levelled
    d2, _ = resolve_on_wall(d, [], img, protos, s.lookalikes, relief=relief)
    near = lambda cands, p: {x.class_id for x in cands if np.hypot(x.centre[0] - p[0], x.centre[1] - p[1]) < 3}  # noqa: E731
    for cid, p in places.items():
        assert near(d2, p) == {cid}, (cid, near(d, p))


# --------------------------------------------------------------------------- same relief, other colours

def _boxed(body: tuple[int, int, int], mark: str, px: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """A 4 cm deep box with bevelled edges, ``body``-coloured with a ``mark``: 'bar' (a
    white bar across its middle) or 'ring' (a grey ring). Both share the relief."""
    rgb = np.empty((px, px, 3), np.uint8)
    rgb[:] = body
    yy, xx = np.mgrid[0:px, 0:px]
    if mark == "bar":
        rgb[8:12, 3:-3] = WHITE
    else:
        r = np.hypot(yy - (px - 1) / 2, xx - (px - 1) / 2)
        rgb[(r > 4) & (r < 7)] = (120, 120, 120)
    edge = np.minimum.reduce([yy, xx, px - 1 - yy, px - 1 - xx]).astype(np.float32)
    depth = 0.04 * np.minimum(1.0, (edge + 1) / 3.0)
    return _rgba(rgb), depth.astype(np.float32)


@pytest.fixture(scope="module")
def depth_alikes() -> ModelLibrary:
    """A red call-point box and a white detector box of the same size and relief: depth cannot
    tell them, and their mean colours are far apart (CIE76 ~ 70)."""
    specs = {"call_point": _boxed(RED, "bar"), "detector": _boxed(WHITE, "ring"), "socket": socket_like()}
    return ModelLibrary({k: make_model(k, v, d) for k, (v, d) in specs.items()}, root="synthetic")


def test_depth_alikes_of_other_colours_are_lookalikes(depth_alikes) -> None:
    from dataclasses import replace
    s = DetectionSettings().lookalikes
    templates = make_templates(depth_alikes, 0.005)
    assert lookalike_sets(templates, s) == [frozenset({"call_point", "detector"})]
    assert lookalike_sets(templates, replace(s, depth_alike_any_colour=False)) == []


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_a_box_found_in_depth_only_takes_the_class_its_colour_shows(depth_alikes, seed: int) -> None:
    """Depth gives both classes at both boxes; whichever the depth step ranks first, after the
    look-alike step each box has the class of its colours, also where colour recognition found
    nothing (the depth candidates alone are resolved)."""
    s = DetectionSettings()
    rng = np.random.default_rng(seed)
    places = {"call_point": (120.0 + rng.uniform(-0.5, 0.5), 100.0), "detector": (140.0, 300.0 + rng.uniform(-0.5, 0.5))}
    w = _recognized(depth_alikes, places, s, seed=seed, w_px=420)
    for p in places.values():
        assert _near(w.depth, p) == set(places)  # depth alone cannot tell
    d2, _ = resolve_on_wall(w.depth, [], w.image, w.protos, s.lookalikes)
    for cid, p in places.items():
        assert _near(d2, p) == {cid}


# --------------------------------------------------------------------------- depth is metric


def _rocker(px: int = 16) -> np.ndarray:
    """A plate 8 mm proud with a rocker tilted from 8 to 16 mm in its middle (metres)."""
    d = np.full((px, px), 0.008, np.float32)
    d[4:-4, 4:-4] = np.linspace(0.008, 0.016, px - 8, dtype=np.float32)[None, :]
    return d


def test_a_lookalike_that_stands_out_otherwise_than_the_scene_is_not_taken() -> None:
    """The print of a flush 2.5 mm plate matches a candidate perfectly, but the relief there
    stands out 8-16 mm: the flush plate's model cannot be it (gain 6, beyond the depth
    recognizer's range), so the candidate keeps its class; a 12 mm plate of the same print
    may still take it."""
    from sbsc_core.recognition.lookalikes import amplitude_compatible, resolve_lookalikes
    from sbsc_core.settings import LookalikeSettings

    rng = np.random.default_rng(3)
    relief = rng.normal(0.0, 0.0005, (80, 80)).astype(np.float32)
    relief[32:48, 32:48] += _rocker()
    flush = np.full((16, 16), 0.0025, np.float32)
    proud = np.full((16, 16), 0.012, np.float32)
    models = {"switch": _rocker(), "flush": flush, "proud": proud}
    fits = amplitude_compatible(relief, models, dict.fromkeys(models, (39.5, 39.5)), 0.0, (0.5, 2.0))
    assert fits == {"switch": True, "flush": False, "proud": True}
    print_of = {c: rng.normal(0.0, 10.0, (16, 16, 3)).astype(np.float32) for c in ("switch", "flush", "proud")}
    diff = np.zeros((80, 80, 3), np.float32)
    cand = Candidate("switch", "W1", "depth", Box(32, 32, 48, 48), (39.5, 39.5), 0.8)
    s = LookalikeSettings()
    for target in ("flush", "proud"):
        diff[32:48, 32:48] = print_of[target]  # the scene shows the target's print exactly
        group = [frozenset({"switch", target})]
        kw = {"relief": relief, "models": models}
        (blind,) = resolve_lookalikes([cand], diff, print_of, group, s, **kw)
        (metric,) = resolve_lookalikes([cand], diff, print_of, group, s, gain_range=(0.5, 2.0), **kw)
        assert blind.class_id == target  # the print alone relabels it
        assert metric.class_id == ("switch" if target == "flush" else "proud")


def test_a_learnt_plate_of_one_colour_is_compared_with_its_surface_around_it() -> None:
    """A learnt design's print (``sbsc learn``: a crop of the scan over the object's box) of a dark
    plate filling its box is, without the surface around it, one colour plus noise: its NCC with
    the same plate on a wall is noise. With a ring of surface it is the plate standing on the wall."""
    from dataclasses import replace

    import cv2

    from sbsc_core.recognition.lookalikes import design_prints, print_score

    rng = np.random.default_rng(3)
    dark = np.clip(rng.normal(70, 4, (16, 16, 3)), 0, 255).astype(np.uint8)  # a grey plate, scan noise
    wall = np.array([225.0, 220.0, 205.0])
    t = make_templates(ModelLibrary({"switch": make_model("switch", *socket_like())}, "x"), 0.005)["switch"]
    t = replace(t, colour_views=[*t.colour_views, _rgba(dark)], extra={"learnt_views": 1})
    scene = np.clip(wall + rng.normal(0, 3, (80, 80, 3)), 0, 255).astype(np.uint8)
    scene[32:48, 32:48] = np.clip(rng.normal(70, 4, (16, 16, 3)), 0, 255).astype(np.uint8)

    def lab(rgb: np.ndarray) -> np.ndarray:
        return cv2.cvtColor(np.asarray(rgb, np.float32) / 255.0, cv2.COLOR_RGB2Lab)

    diff = lab(scene) - lab(wall.reshape(1, 1, 3))
    diff[np.linalg.norm(diff, axis=2) <= 8.0] = 0.0
    bare = design_prints({"switch": t}, wall, 8.0)["switch"][0]
    ringed = design_prints({"switch": t}, wall, 8.0, pad_px=4)["switch"][0]
    assert ringed.shape == (bare.shape[0] + 8, bare.shape[1] + 8, 3)
    assert print_score(diff, bare, (39.5, 39.5), 0.0, search_px=3) < 0.5
    assert print_score(diff, ringed, (39.5, 39.5), 0.0, search_px=3) > 0.9
    assert DetectionSettings().lookalikes.learnt_print_pad_px == 4
