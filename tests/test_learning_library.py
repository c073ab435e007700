"""``sbsc learn`` (sbsc_core.recognition.learning): new classes and designs taught by reviewed objects.

Synthetic detect outputs (a wall's orthoimages and detections.json) keep these fast; the
learnt library is then read by the library reader and searched by depth recognition.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from sbsc_core.cli import main
from sbsc_core.errors import InputError
from sbsc_core.io.models import load_model_library
from sbsc_core.recognition.depth_recognition import depth_rois, match_depth
from sbsc_core.recognition.learning.library import learn_library
from sbsc_core.recognition.templates import make_template, make_templates
from sbsc_core.settings import DepthRecognitionSettings
from sbsc_core.types import ModelLibrary, Orthoimage
from tests.recognition_synth import (
    PIXEL_M,
    make_model,
    make_wall,
    paste,
    socket_like,
    synthetic_library,
)

READER_AT = (150.0, 200.0)  # (row, col) of the taught object on the first wall


def write_library(lib: ModelLibrary, root: Path) -> Path:
    for cid, m in lib.models.items():
        d = root / cid
        d.mkdir(parents=True)
        meta = {"name": m.name, "ifc_class": m.ifc_class, "width_m": m.width_m, "height_m": m.height_m}
        (d / "model.json").write_text(json.dumps(meta), encoding="utf-8")
        cv2.imwrite(str(d / "colour.png"), cv2.cvtColor(m.colour_views[0], cv2.COLOR_RGBA2BGRA))
        if m.depth is not None:
            np.save(d / "depth.npy", m.depth.astype(np.float32))
    return root


def write_detect_output(walls: list[Orthoimage], out: Path, detections: list[dict] = ()) -> Path:
    (out / "orthoimages").mkdir(parents=True)
    for o in walls:
        cv2.imwrite(str(out / "orthoimages" / f"{o.wall_id}_colour.png"), cv2.cvtColor(o.colour, cv2.COLOR_RGB2BGR))
        np.save(out / "orthoimages" / f"{o.wall_id}_depth.npy", o.depth.astype(np.float32))
    doc = {"schema": "sbsc.detections/1", "pixel_m": PIXEL_M, "openings": [], "detections": list(detections),
           "walls": [{"id": o.wall_id, **o.frame.to_dict()} for o in walls]}
    (out / "detections.json").write_text(json.dumps(doc), encoding="utf-8")
    return out


def world(o: Orthoimage, row: float, col: float) -> list[float]:
    u, v = o.pixel_to_uv(row, col)
    return [float(x) for x in o.frame.origin + float(u) * o.frame.axis_u + float(v) * o.frame.axis_v]


def reviewed(path: Path, objects: list[dict]) -> Path:
    path.write_text(json.dumps({"schema": "sbsc.detections/1", "detections": objects}), encoding="utf-8")
    return path


@pytest.fixture()
def taught(tmp_path: Path) -> dict:
    """A wall with one card reader (a class the library lacks: the synthetic socket's shape)."""
    lib = synthetic_library()
    reader = make_template(make_model("card_reader", *socket_like()), PIXEL_M)
    library = write_library(ModelLibrary({k: m for k, m in lib.models.items() if k != "socket"}, "x"),
                            tmp_path / "lib")
    ortho, area = make_wall(seed=3)
    paste(ortho, area, reader, READER_AT, seed=3)
    det = write_detect_output([ortho], tmp_path / "det")
    rev = reviewed(tmp_path / "reviewed.json", [{"class": "card_reader", "position": world(ortho, *READER_AT)}])
    return {"lib": library, "det": det, "rev": rev, "ortho": ortho, "reader": reader, "tmp": tmp_path}


def test_a_new_class_from_one_example_round_trip(taught) -> None:
    out = taught["tmp"] / "new"
    classes = taught["tmp"] / "classes.json"
    classes.write_text(json.dumps({"card_reader": {"name": "Card reader", "ifc_class": "IfcCommunicationsAppliance",
                                                   "predefined_type": "USERDEFINED"}}), encoding="utf-8")
    done = learn_library(taught["det"], taught["rev"], taught["lib"], out, classes=classes)
    assert [(t.class_id, t.action, t.examples) for t in done] == [("card_reader", "new class", 1)]
    lib = load_model_library(out)
    assert set(lib.class_ids) == {"panel", "sign", "knob", "arrow", "card_reader"}
    m = lib["card_reader"]
    assert (m.name, m.ifc_class, m.predefined_type, m.mount) == ("Card reader", "IfcCommunicationsAppliance",
                                                                 "USERDEFINED", ("wall",))
    # size measured from the relief under the click: the 16 x 16 px (0.08 m) plate, within two pixels
    assert abs(m.width_m - 0.08) <= 2 * PIXEL_M and abs(m.height_m - 0.08) <= 2 * PIXEL_M
    # the learnt depth model is the plate: its rim stands out about 12 mm, its recess less
    assert m.depth is not None and 0.009 < float(np.nanmax(m.depth)) < 0.015
    assert float(m.depth[m.depth.shape[0] // 2, m.depth.shape[1] // 2]) < 0.5 * float(np.nanmax(m.depth))
    # untouched classes are copied file for file
    assert sorted(p.name for p in (out / "panel").iterdir()) == ["colour.png", "depth.npy", "model.json"]


def test_a_new_class_defaults_to_a_proxy_mounted_where_its_examples_are(taught) -> None:
    out = taught["tmp"] / "new"
    learn_library(taught["det"], taught["rev"], taught["lib"], out)
    meta = json.loads((out / "card_reader" / "model.json").read_text(encoding="utf-8"))
    assert meta["ifc_class"] == "IfcBuildingElementProxy" and meta["mount"] == ["wall"]


def test_a_class_learnt_from_one_example_refuses_plain_wall_and_clutter_of_another_size(taught) -> None:
    out = taught["tmp"] / "new"
    learn_library(taught["det"], taught["rev"], taught["lib"], out)
    templates = make_templates(load_model_library(out), PIXEL_M, classes=["card_reader"])
    ortho, area = make_wall(seed=11)
    paste(ortho, area, taught["reader"], (100.0, 120.0), seed=4)  # another instance
    for i, (w, h) in enumerate(((32, 32), (10, 10), (16, 40))):  # boxes of other sizes, as relief alike
        clutter = make_template(make_model(f"clutter{i}", *socket_like(w, h)), PIXEL_M)
        paste(ortho, area, clutter, (200.0, 100.0 + 130 * i), seed=5 + i)
    s = DepthRecognitionSettings()
    found = match_depth(ortho, area, depth_rois(ortho, area, s), templates, s)
    assert len(found) == 1
    r, c = found[0].centre
    assert abs(r - 100.0) <= 1.5 and abs(c - 120.0) <= 1.5
    plain, plain_area = make_wall(seed=12)
    assert match_depth(plain, plain_area, depth_rois(plain, plain_area, s), templates, s) == []


def test_a_known_class_that_recognition_missed_gets_another_design(tmp_path: Path) -> None:
    lib = synthetic_library()
    library = write_library(lib, tmp_path / "lib")
    # the building's socket: twice as deep, with a wider recess (another product)
    other = make_template(make_model("socket", *socket_like(relief_m=0.024, body=(200, 200, 190))), PIXEL_M)
    ortho, area = make_wall(seed=5)
    paste(ortho, area, other, READER_AT, seed=5)
    det = write_detect_output([ortho], tmp_path / "det")  # recognition found nothing
    rev = reviewed(tmp_path / "r.json", [{"class": "socket", "position": world(ortho, *READER_AT)}])
    done = learn_library(det, rev, library, tmp_path / "new")
    assert [(t.class_id, t.action) for t in done] == [("socket", "new design")]
    assert sorted(p.name for p in (tmp_path / "new" / "socket").iterdir()) == [
        "colour.png", "colour_1.png", "depth.npy", "depth_1.npy", "model.json"]
    m = load_model_library(tmp_path / "new")["socket"]
    assert len(m.colour_views) == 2 and len(m.extra_depths) == 1
    assert 0.018 < float(np.nanmax(m.extra_depths[0])) < 0.03


def test_a_known_class_that_recognition_found_is_copied_unchanged(tmp_path: Path) -> None:
    lib = synthetic_library()
    library = write_library(lib, tmp_path / "lib")
    t = make_templates(lib, PIXEL_M, classes=["socket"])["socket"]
    ortho, area = make_wall(seed=6)
    paste(ortho, area, t, READER_AT, seed=6)
    u, v = (float(x) for x in ortho.pixel_to_uv(*READER_AT))
    det = write_detect_output([ortho], tmp_path / "det", [{
        "id": "D1", "class": "socket", "wall": "W01", "position": world(ortho, *READER_AT), "u": u, "v": v,
        "width_m": 0.08, "height_m": 0.08, "alpha": 0.9, "rho_depth": 0.9, "rho_colour": 0.1, "source": "both"}])
    rev = reviewed(tmp_path / "r.json", [{"class": "socket", "position": world(ortho, *READER_AT)}])
    done = learn_library(det, rev, library, tmp_path / "new")
    assert done[0].action == "matches" and done[0].rho > 0.9
    assert sorted(p.name for p in (tmp_path / "new" / "socket").iterdir()) == ["colour.png", "depth.npy", "model.json"]


@pytest.mark.parametrize(("change", "why"), [
    ({"position": "far"}, "off the surface: the nearest surface is 0.50 m away"),
    ({"position": "edge"}, "off the surface: its 0.08 x 0.08 m footprint"),
    ({"position": "unseen"}, "not scanned: only 0% of its footprint"),
    ({"rotation_deg": 30}, "turned by 30 degrees"),
])
def test_an_unusable_example_is_named_with_the_reason(taught, change: dict, why: str) -> None:
    o = taught["ortho"]
    obj = {"class": "card_reader", "position": world(o, *READER_AT)}
    if change.get("position") == "far":
        obj["position"] = list(np.asarray(obj["position"]) + 0.5 * o.frame.normal)
    elif change.get("position") == "edge":
        obj["position"], obj["width_m"], obj["height_m"] = world(o, 2.0, 200.0), 0.08, 0.08
    elif change.get("position") == "unseen":
        o.depth[100:200, 300:400] = np.nan
        np.save(taught["det"] / "orthoimages" / "W01_depth.npy", o.depth)
        obj["position"], obj["width_m"], obj["height_m"] = world(o, 150.0, 350.0), 0.08, 0.08
    else:
        obj.update(change)
    rev = reviewed(taught["tmp"] / "bad.json", [{"class": "card_reader", "position": world(o, *READER_AT)}, obj])
    with pytest.raises(InputError) as err:
        learn_library(taught["det"], rev, taught["lib"], taught["tmp"] / "new")
    assert str(err.value).startswith("bad.json: detections[1] (card_reader): " + why)
    assert not (taught["tmp"] / "new").exists()


def test_cli_learn_writes_a_library_and_refuses_bad_input_in_one_line(taught, capsys) -> None:
    out = taught["tmp"] / "new"
    args = [str(taught["det"]), "--reviewed", str(taught["rev"]), "--models", str(taught["lib"])]
    assert main(["learn", *args, "--out", str(out), "--json", "-q"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert [c["action"] for c in summary["classes"]] == ["new class"]
    assert "card_reader" in load_model_library(out).class_ids
    # an output folder that holds something already
    assert main(["learn", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists and is not empty" in err[0]
    # not a detect output
    assert main(["learn", str(taught["tmp"]), *args[1:], "--out", str(taught["tmp"] / "n2")]) == 2
    assert "not a detect output" in capsys.readouterr().err
    # a reviewed object without a place
    bad = reviewed(taught["tmp"] / "noplace.json", [{"class": "card_reader"}])
    assert main(["learn", args[0], "--reviewed", str(bad), "--models", args[4], "--out", str(taught["tmp"] / "n3")]) == 2
    assert "detections[0] (card_reader): give its 'position'" in capsys.readouterr().err
    # CLASSES.json naming a class of the library
    classes = taught["tmp"] / "c.json"
    classes.write_text(json.dumps({"panel": {"name": "P", "ifc_class": "IfcWall"}}), encoding="utf-8")
    assert main(["learn", *args, "--classes", str(classes), "--out", str(taught["tmp"] / "n4")]) == 2
    assert "the library has this class already" in capsys.readouterr().err
    assert not any((taught["tmp"] / n).exists() for n in ("n2", "n3", "n4"))


def test_look_alikes_are_found_between_learnt_designs_too() -> None:
    from dataclasses import replace

    from sbsc_core.recognition.lookalikes import design_templates, lookalike_sets
    from sbsc_core.settings import LookalikeSettings
    from tests.recognition_synth import sign_like

    green, _ = sign_like()
    red, _ = sign_like(back=(200, 20, 30))
    tall = cv2.resize(red, (42, 60), interpolation=cv2.INTER_NEAREST)  # the library's design: another size
    lib = ModelLibrary({"a": make_model("a", green, np.full((42, 42), 0.004, np.float32)),
                        "b": make_model("b", tall, np.full((60, 42), 0.004, np.float32))}, "x")
    templates = make_templates(lib, PIXEL_M)
    assert lookalike_sets(templates, LookalikeSettings()) == []
    # b's building has a square sign like a's: taught as b's learnt design (the last view, with alpha)
    view = np.zeros((60, 42, 4), np.uint8)
    view[9:51, :] = green
    b = templates["b"]
    templates["b"] = replace(b, colour_views=[*b.colour_views, view], extra={"learnt_views": 1})
    assert [len(design_templates(t)) for t in templates.values()] == [1, 2]
    assert lookalike_sets(templates, LookalikeSettings()) == [frozenset({"a", "b"})]


def test_a_learnt_view_is_the_median_of_what_each_crop_saw() -> None:
    from sbsc_core.recognition.learning.crops import learnt_view

    a = np.full((4, 4, 3), 100.0, np.float32)
    b = np.full((4, 4, 3), 110.0, np.float32)
    c = np.full((4, 4, 3), 200.0, np.float32)
    a[0, 0] = b[0, 0] = np.nan  # unseen by two crops: the third's colour
    c[1, 1] = np.nan
    view = learnt_view([a, b, c])
    assert view.dtype == np.uint8 and int(view[0, 0, 0]) == 200 and int(view[1, 1, 0]) == 105
    assert int(view[2, 2, 0]) == 110
    a[:] = np.nan  # a pixel no crop saw takes the view's median colour
    assert int(learnt_view([a])[0, 0, 0]) == 0 and int(learnt_view([a, c])[1, 1, 0]) == 200


def test_an_example_moves_to_a_snap_only_where_the_relief_agrees(tmp_path: Path) -> None:
    from sbsc_core.recognition.learning.examples import read_detect_output, trust_snap

    other = make_template(make_model("x", *socket_like(relief_m=0.02)), PIXEL_M)
    ortho, area = make_wall(seed=8)
    paste(ortho, area, other, READER_AT, seed=8)
    surface = read_detect_output(write_detect_output([ortho], tmp_path / "det"))["W01"]
    u, v = (float(x) for x in ortho.pixel_to_uv(*READER_AT))
    # the relief blob is the 0.08 m plate at the click: a snap 1 cm off agrees, 4 cm off does not
    assert trust_snap(surface, u, v, su=u + 0.01, sv=v, rho=0.9, width_m=0.08, height_m=0.08, min_rho=0.75)
    assert not trust_snap(surface, u, v, su=u + 0.04, sv=v, rho=0.9, width_m=0.08, height_m=0.08,
                          min_rho=0.75)
    assert not trust_snap(surface, u, v, su=u + 0.01, sv=v, rho=0.6, width_m=0.08, height_m=0.08,
                          min_rho=0.75)  # a weak match
    # a class of another size (no blob of its size there): the match alone decides
    assert trust_snap(surface, u, v, su=u + 0.04, sv=v, rho=0.9, width_m=0.30, height_m=0.30, min_rho=0.75)


def test_what_was_learnt_for_a_class_can_be_removed_and_nothing_else(taught) -> None:
    from sbsc_core.recognition.learning.forget import forget_learnt, learnt_parts

    tmp = taught["tmp"]
    lib = synthetic_library()
    write_library(ModelLibrary({"socket": lib["socket"]}, "x"), tmp / "lib")  # beside the others
    other = make_template(make_model("socket", *socket_like(relief_m=0.024, body=(200, 200, 190))), PIXEL_M)
    ortho = taught["ortho"]
    at = (150.0, 400.0)
    paste(ortho, make_wall(seed=3)[1], other, at, seed=7)
    det = write_detect_output([ortho], tmp / "det2")
    rev = reviewed(tmp / "r2.json", [{"class": "card_reader", "position": world(ortho, *READER_AT)},
                                     {"class": "socket", "position": world(ortho, *at)}])
    learn_library(det, rev, taught["lib"], tmp / "learnt")
    assert learnt_parts(tmp / "learnt") == {"card_reader": "class", "socket": "designs"}
    done = forget_learnt(tmp / "learnt", tmp / "no_design", ["socket"])
    assert done == {"socket": "designs"}
    assert sorted(p.name for p in (tmp / "no_design" / "socket").iterdir()) == ["colour.png", "depth.npy", "model.json"]
    assert "learnt_views" not in json.loads((tmp / "no_design" / "socket" / "model.json").read_text())
    assert learnt_parts(tmp / "no_design") == {"card_reader": "class"}
    assert forget_learnt(tmp / "no_design", tmp / "neither", ["card_reader"]) == {"card_reader": "class"}
    assert set(load_model_library(tmp / "neither").class_ids) == set(load_model_library(taught["lib"]).class_ids)
    for cid, why in (("panel", "nothing in the library was learnt"), ("badge_reader", "no such class")):
        with pytest.raises(InputError, match=why):
            forget_learnt(tmp / "learnt", tmp / f"bad_{cid}", [cid])
        assert not (tmp / f"bad_{cid}").exists()  # nothing half-written


def _flush_wall(tmp_path: Path) -> tuple[Path, Path, Orthoimage, tuple, tuple]:
    """A library with a flush plate (3 mm) and a wall holding one (the example, found) and, 2 m
    away, the same print on a 20 mm box (a room controller of the plate's size)."""
    view, depth = socket_like(w_px=24, h_px=24, relief_m=0.003)
    lib = ModelLibrary({"flush": make_model("flush", view, depth)}, "x")
    library = write_library(lib, tmp_path / "lib")
    t = make_templates(lib, PIXEL_M)["flush"]
    tall = make_template(make_model("flush", view, np.full_like(depth, 0.020)), PIXEL_M)
    ortho, area = make_wall(seed=21)
    at, box = (150.0, 100.0), (150.0, 400.0)
    paste(ortho, area, t, at, seed=21)
    paste(ortho, area, tall, box, seed=22)
    u, v = (float(x) for x in ortho.pixel_to_uv(*at))
    det = write_detect_output([ortho], tmp_path / "det", [{
        "id": "D1", "class": "flush", "wall": "W01", "position": world(ortho, *at), "u": u, "v": v,
        "width_m": 0.12, "height_m": 0.12, "alpha": 0.9, "rho_depth": 0.9, "rho_colour": 0.1, "source": "both"}])
    rev = reviewed(tmp_path / "r.json", [{"class": "flush", "position": world(ortho, *at)}])
    return library, learn_and(det, rev, library, tmp_path / "new"), ortho, at, box


def learn_and(det: Path, rev: Path, library: Path, out: Path) -> Path:
    learn_library(det, rev, library, out)
    return out


def _searched(ortho: Orthoimage, models: Path):  # noqa: ANN202 - a WallResult
    """The walls' stages on (a copy of) ``ortho``, searched with the library at ``models``."""
    from dataclasses import replace

    from sbsc_core.pipeline.walls import _templates_job, process_orthoimage
    from sbsc_core.settings import DetectionSettings

    lib = load_model_library(models)
    s = DetectionSettings()
    templates, protos = _templates_job(lib, s, lib.class_ids)
    o = replace(ortho, colour=ortho.colour.copy(), depth=ortho.depth.copy(), mask=ortho.mask.copy())
    return process_orthoimage(o, templates, protos, s)[0]


def _colour_hits(ortho: Orthoimage, models: Path) -> list[tuple[float, float]]:
    """The colour candidates' centres of class ``flush`` on a wall searched with ``models``."""
    return [c.centre for c in _searched(ortho, models).colour_candidates if c.class_id == "flush"]


def _near(hits: list, where: tuple) -> bool:
    """Whether a candidate centre (row, col) lies within 6 px of ``where``."""
    return any(abs(r - where[0]) < 6 and abs(c - where[1]) < 6 for r, c in hits)


def test_a_taught_class_refuses_its_print_on_a_relief_much_taller_than_its_examples(tmp_path: Path) -> None:
    library, learnt, ortho, at, box = _flush_wall(tmp_path)
    meta = json.loads((learnt / "flush" / "model.json").read_text())
    assert 0.002 < min(meta["example_relief_m"]) <= max(meta["example_relief_m"]) < 0.005
    before, after = _colour_hits(ortho, library), _colour_hits(ortho, learnt)
    assert _near(before, at) and _near(before, box)  # the library alone takes the print on the box
    assert _near(after, at) and not _near(after, box)  # the example stood out 3 mm, the box 20 mm


def test_a_taught_class_refuses_a_depth_match_standing_out_twice_as_far_as_its_examples(tmp_path: Path) -> None:
    """A library switch (12 mm), the building's switches (11 mm: the examples, found) and a box of
    the switch's shape standing out 21 mm (a room controller): within the depth recognizer's
    generic 2x of the library's model and of the examples, so the library alone takes the box in
    depth and in colour. Taught, the examples measured 11 mm and their spread 0, the wall's
    noise relief is a few mm: the box is refused, the switches are kept."""
    view, depth = socket_like(relief_m=0.012)
    library = write_library(ModelLibrary({"switch": make_model("switch", view, depth)}, "x"), tmp_path / "lib")
    own = make_template(make_model("switch", view, depth * (0.011 / 0.012)), PIXEL_M)
    box = make_template(make_model("switch", view, depth * (0.021 / 0.012)), PIXEL_M)
    ortho, area = make_wall(seed=23)
    switches, controller = [(150.0, 80.0), (150.0, 200.0)], (150.0, 380.0)
    for k, at in enumerate(switches):
        paste(ortho, area, own, at, seed=23 + k)
    paste(ortho, area, box, controller, seed=29)
    found = []
    for k, at in enumerate(switches):
        u, v = (float(x) for x in ortho.pixel_to_uv(*at))
        found.append({"id": f"D{k}", "class": "switch", "wall": "W01", "position": world(ortho, *at), "u": u, "v": v,
                      "width_m": 0.08, "height_m": 0.08, "alpha": 0.9, "rho_depth": 0.9, "rho_colour": 0.5,
                      "source": "both"})
    det = write_detect_output([ortho], tmp_path / "det", found)
    rev = reviewed(tmp_path / "r.json", [{"class": "switch", "position": world(ortho, *at)} for at in switches])
    learnt = learn_and(det, rev, library, tmp_path / "new")
    amps = json.loads((learnt / "switch" / "model.json").read_text())["example_relief_m"]
    assert len(amps) == 2 and all(0.010 < a < 0.012 for a in amps)  # matched: no new design, the amplitudes only

    def hits(models: Path, source: str) -> list[tuple[float, float]]:
        res = _searched(ortho, models)
        return [c.centre for c in (res.depth_candidates if source == "depth" else res.colour_candidates)]

    before, after = hits(library, "depth"), hits(learnt, "depth")
    assert _near(before, controller) and all(_near(before, at) for at in switches)  # 1.75x the library's model
    assert all(_near(after, at) for at in switches) and not _near(after, controller)  # 1.9x the examples: refused
    assert _near(hits(library, "colour"), controller) and not _near(hits(learnt, "colour"), controller)


def _two_designs(tmp_path: Path, lib: dict, building: dict) -> tuple[list, Path]:
    """Learn, from two examples each, the building's designs (``building``: class -> (view,
    depth)) of the library's classes (``lib``: class -> (view, depth)), on one noisy wall."""
    library = write_library(ModelLibrary({c: make_model(c, v, d) for c, (v, d) in lib.items()}, "x"), tmp_path / "lib")
    ortho, area = make_wall(w_px=900, seed=31)
    places = {}
    for k, (cid, (v, d)) in enumerate(sorted(building.items())):
        t = make_template(make_model(cid, v, d), PIXEL_M)
        places[cid] = [(100.0, 100.0 + 400 * k), (100.0, 300.0 + 400 * k)]
        for j, at in enumerate(places[cid]):
            paste(ortho, area, t, at, seed=40 + 2 * k + j)
    det = write_detect_output([ortho], tmp_path / "det")
    rev = reviewed(tmp_path / "r.json", [{"class": c, "position": world(ortho, *at)}
                                         for c, ats in places.items() for at in ats])
    return learn_library(det, rev, library, tmp_path / "new"), tmp_path / "new"


def test_a_learnt_relief_that_does_not_tell_its_examples_apart_is_left_out_of_look_alikes(tmp_path: Path) -> None:
    from sbsc_core.recognition.lookalikes import relief_muted
    from tests.recognition_synth import arrow_like, sign_like

    plate = np.full((42, 42), 0.004, np.float32)
    red_cross, _ = sign_like(back=(200, 20, 30))
    red_bar = red_cross.copy()
    red_bar[..., :3] = (200, 20, 30)
    red_bar[17:25, 6:36, :3] = 250
    # two flat sign plates of the building, other prints than the library's: their learnt relief is
    # the scan's noise on a plate, which the other sign's model explains as well (left one out)
    done, new = _two_designs(tmp_path / "signs", {"a": (sign_like()[0], plate), "b": (sign_like(back=(20, 40, 160))[0], plate)},
                             {"a": (red_cross, plate), "b": (red_bar, plate)})
    assert [t.action for t in done] == ["new design", "new design"]
    muted = relief_muted(make_templates(load_model_library(new), PIXEL_M))
    assert muted and muted == {t.class_id for t in done if not t.relief_decides}
    assert all(json.loads((new / c / "model.json").read_text())["relief_decides"] is False for c in muted)
    # a socket's recess and a ramp of its size: each learnt relief tells its own examples
    done, new = _two_designs(tmp_path / "reliefs", {"socket": socket_like(), "ramp": arrow_like(w_px=16, h_px=16)},
                             {"socket": socket_like(relief_m=0.024, body=(200, 200, 190)),
                              "ramp": arrow_like(w_px=16, h_px=16, body=(90, 90, 200), relief_m=0.02)})
    assert [t.action for t in done] == ["new design", "new design"] and all(t.relief_decides for t in done)
    assert relief_muted(make_templates(load_model_library(new), PIXEL_M)) == frozenset()
    assert all("relief_decides" not in json.loads((new / c / "model.json").read_text()) for c in ("socket", "ramp"))
