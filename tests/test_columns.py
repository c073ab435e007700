"""Free-standing columns (issue 11): finding them, their faces, and detect --columns."""

from __future__ import annotations

import json
import math
from functools import partial

import numpy as np
import pytest

from sbsc_core.scene.columns import column_faces, find_columns
from sbsc_core.settings import ColumnSettings
from sbsc_core.types import Box, PointCloud, Segmentation, Storey
from tests.synthetic_rooms import plan_wall

_wall = partial(plan_wall, height=3.0)


def _scene(rng) -> tuple[PointCloud, Segmentation]:
    """A 10 x 8 m room, 3 m high: a 0.45 m square column turned 20 degrees at (3, 4), a round
    one of 0.5 m at (7, 4) and a table (not tall)."""
    zs = np.arange(0.02, 2.98, 0.01)
    parts = []
    for y in np.arange(0.0, 8.0, 0.01):  # the walls x = 0 and x = 10
        parts += [np.column_stack([np.full(len(zs), 0.0), np.full(len(zs), y), zs]),
                  np.column_stack([np.full(len(zs), 10.0), np.full(len(zs), y), zs])]
    a = math.radians(20.0)
    e1, e2 = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    t = np.arange(-0.225, 0.225, 0.01)
    for n, s in ((e1, e2), (-e1, e2), (e2, e1), (-e2, e1)):
        xy = np.array([3.0, 4.0]) + 0.225 * n + t[:, None] * s
        gx, gz = np.meshgrid(np.arange(len(xy)), zs)
        parts.append(np.column_stack([xy[gx.ravel(), 0], xy[gx.ravel(), 1], gz.ravel()]))
    ang = np.arange(0, 2 * math.pi, 0.02)
    ga, gz = np.meshgrid(ang, zs)
    parts.append(np.column_stack([7.0 + 0.25 * np.cos(ga.ravel()), 4.0 + 0.25 * np.sin(ga.ravel()), gz.ravel()]))
    tx, ty = np.meshgrid(np.arange(5.0, 5.8, 0.01), np.arange(1.0, 1.6, 0.01))  # a table top, 0.75 m
    parts.append(np.column_stack([tx.ravel(), ty.ravel(), np.full(tx.size, 0.75)]))
    xyz = np.vstack(parts)
    xyz = xyz + rng.normal(0, 0.002, xyz.shape)
    cloud = PointCloud(xyz.astype(np.float32), np.full((len(xyz), 3), 200, np.uint8))
    walls = [_wall("W1", (0, 0), (0, 8)), _wall("W3", (10, 8), (10, 0))]
    return cloud, Segmentation(0.0, 3.0, walls, [Storey("S1", 0.0, 3.0)])


def test_find_columns_rect_and_round_not_walls_or_tables():
    cloud, seg = _scene(np.random.default_rng(1))
    cols = find_columns(cloud, seg, ColumnSettings(enabled=True))
    assert [c.shape for c in cols] == ["rect", "round"]
    rect, rnd = cols
    assert rect.centre == pytest.approx((3.0, 4.0), abs=0.01) and rect.size_m == pytest.approx((0.45, 0.45), abs=0.01)
    assert (rect.angle_deg - 20.0 + 45.0) % 90.0 - 45.0 == pytest.approx(0.0, abs=0.5)
    assert rnd.centre == pytest.approx((7.0, 4.0), abs=0.005) and rnd.size_m[0] == pytest.approx(0.5, abs=0.01)
    faces = column_faces(cols)
    assert sorted(f.id for f in faces) == ["COL1-E", "COL1-N", "COL1-S", "COL1-W", "COL2"]
    faces = sorted(faces, key=lambda f: f.id)
    for f in faces[:4]:  # each face lies on the column's side, its normal out of the column
        mid = f.frame.to_world(f.frame.width_m / 2, 1.0)
        assert np.dot(mid[:2] - (3.0, 4.0), f.frame.normal[:2]) == pytest.approx(0.225, abs=0.01)
        assert f.frame.width_m == pytest.approx(0.45, abs=0.01)
        assert np.isclose(np.cross(f.frame.axis_u, f.frame.axis_v) @ f.frame.normal, 1.0)
    # the round face is unrolled: u is the arc length counter-clockwise from +x, depth out of it
    rf = faces[4]
    p = np.array([[7.0, 4.0 + 0.25 + 0.05, 1.2]], np.float32)
    u, v, d = rf.coords(p, np.zeros(3))[0]
    assert (u, v, d) == pytest.approx((0.25 * math.pi / 2, 1.2, 0.05), abs=1e-3)
    assert rf.to_world(u, v) == pytest.approx([7.0, 4.25, 1.2], abs=1e-3)


def test_no_columns_in_an_empty_room():
    cloud, seg = _scene(np.random.default_rng(2))
    walls_only = np.abs(cloud.xyz[:, 0] - 5.0) > 4.9
    cloud = PointCloud(cloud.xyz[walls_only], cloud.rgb[walls_only])
    assert find_columns(cloud, seg, ColumnSettings(enabled=True)) == []


def _column_seen_from_one_side(rng, *, stub: bool = False) -> tuple[PointCloud, Segmentation]:
    """A 10 x 8 m room, 3 m high, with a 0.49 x 0.41 m column at (4.75, 2.56) seen only from
    the south-east (its S face y = 2.355 and its E face x = 4.995; a 45 mm object stands out
    of the E face), the S face segmented as a short wall ``W2`` (its points are its own).
    With ``stub``, a 0.5 m stub of the wall x = 0 (x 0 to 0.5 at y = 6) is a short wall too."""
    zs = np.arange(0.02, 2.98, 0.01)
    parts, own = [], {}

    def face(xy: np.ndarray, name: str | None = None) -> None:
        gx, gz = np.meshgrid(np.arange(len(xy)), zs)
        pts = np.column_stack([xy[gx.ravel(), 0], xy[gx.ravel(), 1], gz.ravel()])
        if name:
            start = sum(len(p) for p in parts)
            own[name] = np.arange(start, start + len(pts))
        parts.append(pts)

    for y in np.arange(0.0, 8.0, 0.01):  # the walls x = 0 and x = 10
        parts.append(np.column_stack([np.zeros(len(zs)), np.full(len(zs), y), zs]))
        parts.append(np.column_stack([np.full(len(zs), 10.0), np.full(len(zs), y), zs]))
    xs, ys = np.arange(4.505, 4.995, 0.01), np.arange(2.355, 2.765, 0.01)
    face(np.column_stack([xs, np.full(len(xs), 2.355)]), "W2")
    face(np.column_stack([np.full(len(ys), 4.995), ys]))
    ox, oy, oz = np.meshgrid([5.04], np.arange(2.50, 2.58, 0.01), np.arange(1.40, 1.48, 0.01))  # the object
    parts.append(np.column_stack([ox.ravel(), oy.ravel(), oz.ravel()]))
    walls = [_wall("W1", (0, 0), (0, 8)), _wall("W3", (10, 8), (10, 0))]
    if stub:
        xs = np.arange(0.0, 0.5, 0.01)
        face(np.column_stack([xs, np.full(len(xs), 6.0)]), "W4")
    xyz = np.vstack(parts) + rng.normal(0, 0.002, (sum(len(p) for p in parts), 3))
    cloud = PointCloud(xyz.astype(np.float32), np.full((len(xyz), 3), 200, np.uint8))
    w2 = _wall("W2", (4.505 - 0.6, 2.355), (4.995 + 0.6, 2.355))  # a free end's frame is padded
    w2.point_index = own["W2"]
    walls.append(w2)
    if stub:
        w4 = _wall("W4", (0.0, 6.0), (0.5, 6.0))
        w4.point_index = own["W4"]
        walls.append(w4)
    return cloud, Segmentation(0.0, 3.0, walls, [Storey("S1", 0.0, 3.0)])


def test_a_column_seen_from_one_side_whose_face_was_taken_for_a_wall():
    """Two faces of a column seen (an L: its smallest enclosing rectangle is diagonal), the
    wider one segmented as a short wall: the column is found whole, turned like its faces,
    the wall is dropped for its faces; a wall stub that meets a wall stays a wall."""
    from sbsc_core.pipeline.detect import _columns_of
    from sbsc_core.settings import DetectionSettings

    cloud, seg = _column_seen_from_one_side(np.random.default_rng(3), stub=True)
    s = DetectionSettings()
    cols = _columns_of(cloud, seg, s)
    assert len(cols) == 1 and cols[0].shape == "rect"
    c = cols[0]
    assert c.centre == pytest.approx((4.75, 2.56), abs=0.02)
    a = math.radians(c.angle_deg)
    along_x = abs(math.cos(a)) > 0.9  # the first side along x or along y
    assert (c.size_m if along_x else c.size_m[::-1]) == pytest.approx((0.49, 0.41), abs=0.025)
    assert (c.angle_deg + 45.0) % 90.0 - 45.0 == pytest.approx(0.0, abs=0.5)
    assert [w.id for w in seg.walls] == ["W1", "W3", "W4"]
    # without the lone wall's points the column is not found (what happened before)
    cloud2, seg2 = _column_seen_from_one_side(np.random.default_rng(3))
    assert find_columns(cloud2, seg2, ColumnSettings()) == []


@pytest.mark.slow
def test_detect_columns_and_ceilings_on_a_hall(tmp_path):
    import yaml

    from sbsc_core.cli import main
    from sbsc_core.evaluate import evaluate
    from sbsc_core.io.documents import read_detections, read_truth

    scene = {"schema": "sbsc.scene/1", "name": "hall", "ceiling_height_m": 2.8,
             "rooms": [{"id": "H", "rect": [0, 0, 7, 6.5]}],
             "openings": [{"wall": "H-S", "kind": "door", "u": 2.0, "width_m": 0.9, "height_m": 2.1}],
             "objects": [{"class": "switch", "wall": "H-S", "u": 3.0, "v": 1.1}],
             "scanner": {"angular_step_deg": 0.1}}
    (tmp_path / "hall.yaml").write_text(yaml.safe_dump(scene))
    sim, det = tmp_path / "sim", tmp_path / "det"
    assert main(["-q", "simulate", "--scene", str(tmp_path / "hall.yaml"), "--ceiling-objects", "--columns",
                 "--out", str(sim)]) == 0
    assert main(["-q", "detect", str(sim / "scan.ply"), "--models", str(sim / "models"), "--expected",
                 str(sim / "expected.json"), "--out", str(det)]) == 0  # every surface by default
    doc = read_detections(det / "detections.json")
    kinds = {s["id"]: s["kind"] for s in doc["surfaces"]}
    assert sorted(k for k in kinds if kinds[k] == "column") == ["COL1-E", "COL1-N", "COL1-S", "COL1-W"]
    assert len(doc["walls"]) == 4  # the column is no wall
    table = evaluate(doc, read_truth(sim / "ground_truth.json"))
    rows = {r.class_id: r for r in table.surfaces}
    assert rows["column"].instances >= 4  # the objects on the sides the stations see
    assert rows["column"].tp == rows["column"].instances and rows["column"].fp == 0
    assert rows["ceiling"].tp == rows["ceiling"].instances and rows["ceiling"].fp == 0
    assert json.loads((det / "detections.json").read_text())["surfaces"][0]["kind"] == "ceiling"
    # the library's in-memory detect() runs the ceiling and column stages too, with the same result
    from sbsc_core.io.documents import read_expected_counts
    from sbsc_core.io.models import load_model_library
    from sbsc_core.io.scans import read_scan
    from sbsc_core.pipeline.detect import detect
    from sbsc_core.settings import DetectionSettings

    settings = DetectionSettings()  # ceilings and columns searched by default
    res = detect(read_scan(sim / "scan.ply"), load_model_library(sim / "models"),
                 read_expected_counts(sim / "expected.json"), settings=settings)
    assert [sf["id"] for sf in res.surfaces] == [sf["id"] for sf in doc["surfaces"]]
    mem = sorted((d.class_id, d.wall_id, d.surface) for d in res.detections)
    assert mem == sorted((d["class"], d["wall"], d.get("surface")) for d in doc["detections"])
    by_key = {(d["class"], d["wall"]): d["position"] for d in doc["detections"]}
    for d in res.detections:
        assert np.linalg.norm(np.subtract(d.position, by_key[(d.class_id, d.wall_id)])) < 0.002
    # the walls keep their ids and frames with ceilings and columns turned off
    off = DetectionSettings()
    off.ceilings.enabled = off.columns.enabled = False
    plain = detect(read_scan(sim / "scan.ply"), load_model_library(sim / "models"),
                   read_expected_counts(sim / "expected.json"), settings=off)
    assert not plain.surfaces and all(d.surface is None for d in plain.detections)
    assert [(w.id, list(np.round(w.frame.origin, 4))) for w in plain.segmentation.walls] == \
        [(w["id"], list(np.round(w["origin"], 4))) for w in doc["walls"]]
    assert sorted((d.class_id, d.wall_id) for d in plain.detections) == \
        sorted((d["class"], d["wall"]) for d in doc["detections"] if d.get("surface") in (None, "wall"))


def test_round_column_image_wraps_its_seam(tmp_path):
    from sbsc_core.imaging.partition import plan_parts, scan_origin
    from sbsc_core.io.ply import write_ply
    from sbsc_core.scene.columns import column_part, face_orthoimage
    from sbsc_core.settings import OrthoimageSettings
    from sbsc_core.types import Candidate, Orthoimage

    cloud, seg = _scene(np.random.default_rng(5))
    # a 10 cm box standing 4 cm out of the round column, centred on its seam (+x, angle 0)
    by, bz = np.meshgrid(np.arange(-0.05, 0.05, 0.004), np.arange(1.15, 1.25, 0.004))
    box = np.column_stack([np.full(by.size, 7.0 + 0.25 + 0.04), 4.0 + by.ravel(), bz.ravel()])
    xyz = np.vstack([cloud.xyz, box]).astype(np.float32)
    write_ply(tmp_path / "scan.ply", xyz, np.full((len(xyz), 3), 200, np.uint8))
    cols = find_columns(cloud, seg, ColumnSettings(enabled=True))
    (rf,) = [f for f in column_faces(cols, wrap_m=0.4) if f.radius_m is not None]
    circ = rf.circumference_m
    assert rf.frame.width_m == pytest.approx(circ + 0.4) and rf.wrap_m == 0.4
    parts, _ = plan_parts([tmp_path / "scan.ply"])
    origin = scan_origin(tmp_path / "scan.ply")
    ortho = OrthoimageSettings()
    for p in parts:
        column_part(p, origin, [rf], [0.6], str(tmp_path), ortho=ortho)
    img: Orthoimage = face_orthoimage(tmp_path, 0, rf, ortho)
    # the box is whole past the circumference (the start repeated) and cut at the start
    r = int(img.uv_to_pixel(0.0, 1.2)[0])
    cols_out = np.flatnonzero(np.nan_to_num(img.depth[r], nan=0.0) > 0.03) * ortho.pixel_m
    whole = cols_out[cols_out > circ - 0.1]
    assert whole.min() == pytest.approx(circ - 0.05 * 0.25 / 0.29, abs=0.015)
    assert whole.max() == pytest.approx(circ + 0.05 * 0.25 / 0.29, abs=0.015)
    # a candidate on the seam is kept once: at its whole copy, not at its cut start
    px = ortho.pixel_m

    def cand(u):
        return Candidate("socket_x1", rf.id, "depth", Box(0, 0, 1, 1), (float(r), u / px - 0.5), 0.9)

    kept = [u for u in (0.01, circ + 0.01, circ - 0.3, 0.3, circ + 0.3) if rf.owns((cand(u).centre[1] + 0.5) * px)]
    assert kept == pytest.approx([circ + 0.01, circ - 0.3, 0.3])
    assert rf.arc_u(circ + 0.01) == pytest.approx(0.01)
    assert rf.to_world(circ + 0.01, 1.2) == pytest.approx(rf.to_world(0.01, 1.2))


@pytest.mark.slow
def test_objects_on_a_round_columns_seam_are_found_once(tmp_path, monkeypatch):
    import yaml

    import sbsc_core.simulate.surfaces as sim_surfaces
    from sbsc_core.cli import main

    # two halls: the second one's column is round, with an extinguisher and a socket across its seam (+x)
    monkeypatch.setattr(sim_surfaces, "ROUND_COLUMN_OBJECTS",
                        [("fire_extinguisher", 0.0, 1.2), ("socket_x1", 2.0, 0.3), ("fire_alarm_switch", 180.0, 1.4)])
    scene = {"schema": "sbsc.scene/1", "name": "halls", "ceiling_height_m": 2.8,
             "rooms": [{"id": "H", "rect": [0, 0, 8, 7]}, {"id": "K", "rect": [8.15, 0, 16.15, 7]}],
             "openings": [{"wall": "H-S", "kind": "door", "u": 2.0, "width_m": 0.9, "height_m": 2.1},
                          {"wall": "K-S", "kind": "door", "u": 2.0, "width_m": 0.9, "height_m": 2.1}],
             "objects": [{"class": "switch", "wall": "H-S", "u": 3.0, "v": 1.1}],
             "scanner": {"angular_step_deg": 0.1}}
    (tmp_path / "hall.yaml").write_text(yaml.safe_dump(scene))
    sim, det = tmp_path / "sim", tmp_path / "det"
    assert main(["-q", "simulate", "--scene", str(tmp_path / "hall.yaml"), "--columns", "--out", str(sim)]) == 0
    assert main(["-q", "detect", str(sim / "scan.ply"), "--models", str(sim / "models"), "--expected",
                 str(sim / "expected.json"), "--columns", "--out", str(det)]) == 0
    truth = json.loads((sim / "ground_truth.json").read_text())
    doc = json.loads((det / "detections.json").read_text())
    (col,) = [sf for sf in doc["surfaces"] if sf.get("radius_m")]
    circ = 2 * math.pi * col["radius_m"]
    on_column = [d for d in doc["detections"] if d["wall"] == col["id"]]
    want = [o for o in truth["objects"] if o["wall"] == "K-COL2"]
    assert sorted(o["class"] for o in want) == ["fire_alarm_switch", "fire_extinguisher", "socket_x1"]
    assert sorted(d["class"] for d in on_column) == sorted(o["class"] for o in want)  # each once
    for o in want:
        (d,) = [d for d in on_column if d["class"] == o["class"]]
        assert np.linalg.norm(np.subtract(d["position"], o["position"])) < 0.015
        assert 0.0 <= d["u"] < circ


def test_find_columns_at_survey_coordinates():
    """The same columns in a frame at UTM-like coordinates, turned 23.5 degrees in plan."""
    cloud, seg = _scene(np.random.default_rng(1))
    a = math.radians(23.5)
    rot = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
    offset = np.array([412000.0, 5612000.0, 100.0])
    world = cloud.xyz.astype(np.float64) @ rot.T + offset
    origin = world.mean(axis=0)
    turned = PointCloud((world - origin).astype(np.float32), cloud.rgb, origin)
    walls = []
    for w in seg.walls:
        f = w.frame
        frame = type(f)(f.origin @ rot.T + offset, f.axis_u @ rot.T, f.axis_v @ rot.T, f.normal @ rot.T,
                        f.width_m, f.height_m)
        walls.append(type(w)(w.id, frame, w.point_index, w.storey))
    seg_t = Segmentation(100.0, 103.0, walls, [Storey("S1", 100.0, 103.0)])
    rect, rnd = find_columns(turned, seg_t, ColumnSettings(enabled=True))
    assert (rect.shape, rnd.shape) == ("rect", "round")
    assert rect.centre == pytest.approx(tuple((np.array([3.0, 4.0, 0.0]) @ rot.T + offset)[:2]), abs=0.01)
    assert rect.size_m == pytest.approx((0.45, 0.45), abs=0.01)
    assert (rect.angle_deg - 43.5 + 45.0) % 90.0 - 45.0 == pytest.approx(0.0, abs=0.5)
    assert rnd.centre == pytest.approx(tuple((np.array([7.0, 4.0, 0.0]) @ rot.T + offset)[:2]), abs=0.005)
    assert rnd.size_m[0] == pytest.approx(0.5, abs=0.01)
