"""Objects on ceilings (issue 11): ceiling tiles, their partitions and detect --ceilings."""

from __future__ import annotations

import json
from functools import partial

import numpy as np
import pytest

from sbsc_core.imaging.partition import plan_parts, scan_origin
from sbsc_core.io.ply import write_ply
from sbsc_core.scene.ceilings import (
    CeilingBinning,
    binned_records,
    ceiling_levels,
    ceiling_part,
    ceiling_tiles,
    in_core,
    tile_orthoimage,
)
from sbsc_core.settings import CeilingSettings, OrthoimageSettings
from sbsc_core.types import Box, Candidate, PointCloud, Segmentation, Storey
from tests.synthetic_rooms import plan_wall

_wall = partial(plan_wall, height=2.8)


def _room(w: float = 13.0, d: float = 7.0) -> Segmentation:
    walls = [_wall("W1", (0, 0), (0, d)), _wall("W2", (0, d), (w, d)), _wall("W3", (w, d), (w, 0)),
             _wall("W4", (w, 0), (0, 0))]
    return Segmentation(0.0, 2.8, walls, [Storey("S1", 0.0, 2.8)])


def test_tiles_cover_the_ceiling_once_seen_from_below():
    tiles = ceiling_tiles(_room(), CeilingSettings(tile_m=6.0, overlap_m=0.3))
    assert [t.id for t in tiles] == [f"C0{k}" for k in range(1, 7)]  # 3 x 2 tiles
    rng = np.random.default_rng(0)
    for x, y in rng.uniform((0, 0), (13, 7), (500, 2)):
        owners = [t for t in tiles if t.owns(*t.frame.to_uvd(np.array([[x, y, 2.8]]))[0, :2])]
        assert len(owners) == 1
        # the owner's image holds the whole neighbourhood of an object centred there
        u, v = owners[0].frame.to_uvd(np.array([[x, y, 2.8]]))[0, :2]
        f = owners[0].frame
        assert (min(u, 13 - x) >= -1e-9 and min(f.width_m - u, x) >= -1e-9)
    for t in tiles:
        f = t.frame
        assert np.allclose(f.normal, [0, 0, -1]) and f.axis_v[2] == 0
        assert np.isclose(np.cross(f.axis_u, f.axis_v) @ f.normal, 1.0)
        assert f.width_m <= 6.0 / 1 + 0.6 and f.origin[2] == 2.8
        # points below the ceiling have positive depth (they hang into the room)
        assert f.to_uvd(np.array([[f.origin[0] + 0.1, f.origin[1] - 0.1, 2.75]]))[0, 2] == pytest.approx(0.05)


def test_ceiling_points_are_binned_into_tiles_without_the_walls(tmp_path):
    seg = _room(4.0, 3.0)
    (tile,) = ceiling_tiles(seg, CeilingSettings())
    g = np.arange(0.0025, 4.0, 0.004)
    h = np.arange(0.0025, 3.0, 0.004)
    gx, gy = np.meshgrid(g, h)
    ceiling = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, 2.8)])
    bump = (np.abs(ceiling[:, 0] - 2.0) < 0.05) & (np.abs(ceiling[:, 1] - 1.0) < 0.05)
    ceiling[bump, 2] = 2.75  # a 10 cm box hanging 5 cm below the ceiling
    zz, yy = np.meshgrid(np.arange(2.5, 2.785, 0.004), h)
    wall = np.column_stack([np.zeros(zz.size), yy.ravel(), zz.ravel()])  # the top of wall W1 (x = 0)
    xyz = np.vstack([ceiling, wall]).astype(np.float32)
    rgb = np.full((len(xyz), 3), 200, np.uint8)
    rgb[len(ceiling):] = (10, 200, 10)
    write_ply(tmp_path / "scan.ply", xyz, rgb)
    parts, _ = plan_parts([tmp_path / "scan.ply"])
    origin = scan_origin(tmp_path / "scan.ply")
    ortho = OrthoimageSettings()
    walls = [w.frame for w in seg.walls]
    written = sum(np.asarray(ceiling_part(p, origin, [tile], walls, str(tmp_path), ortho=ortho,
                                          wall_clear_m=0.05)) for p in parts)
    assert written[0] == len(ceiling)  # every ceiling point, none of the wall's
    img = tile_orthoimage(tmp_path, 0, tile, ortho)
    assert img.depth.shape == (600, 800)
    r, c = img.uv_to_pixel(2.0, 2.0)  # u = x, v = 3 - y
    assert img.depth[int(r), int(c)] == pytest.approx(0.05, abs=1e-3)
    assert np.nanmedian(img.depth) == pytest.approx(0.0, abs=1e-3)
    assert not (img.colour[img.mask] == (10, 200, 10)).all(axis=1).any()  # no wall colour in the image
    cands = [Candidate("smoke_detector", tile.id, "depth", Box(0, 0, 1, 1), (float(r), float(c)), 0.9),
             Candidate("smoke_detector", tile.id, "depth", Box(0, 0, 1, 1), (-50.0, float(c)), 0.9)]
    assert in_core(cands, tile, ortho.pixel_m) == cands[:1]


@pytest.mark.slow
def test_detect_ceilings_finds_the_smoke_detector_on_the_ceiling(tmp_path):
    from sbsc_core.cli import main
    from sbsc_core.io.documents import read_detections

    sim, det = tmp_path / "sim", tmp_path / "det"
    assert main(["-q", "simulate", "--scene", "one_room", "--ceiling-objects", "--out", str(sim)]) == 0
    assert main(["-q", "detect", str(sim / "scan.ply"), "--models", str(sim / "models"), "--expected",
                 str(sim / "expected.json"), "--out", str(det)]) == 0  # every surface by default
    doc = json.loads((det / "detections.json").read_text())
    read_detections(det / "detections.json")  # the document validates (surfaces, detections on them)
    assert [s["kind"] for s in doc["surfaces"]] == ["ceiling"]
    truth = json.loads((sim / "ground_truth.json").read_text())
    (want,) = [o for o in truth["objects"] if o["surface"] == "ceiling"]
    on_ceiling = [d for d in doc["detections"] if d.get("surface") == "ceiling"]
    assert [d["class"] for d in on_ceiling] == [want["class"]]
    assert np.linalg.norm(np.subtract(on_ceiling[0]["position"], want["position"])) < 0.01
    assert all(o["wall"] in {w["id"] for w in doc["walls"]} for o in doc["openings"])
    assert (det / "orthoimages" / "C01_depth.npy").exists()


def test_evaluate_gives_figures_per_surface_kind(tmp_path):
    from sbsc_core.evaluate import evaluate, format_table
    from sbsc_core.io.documents import read_truth

    def obj(cls, pos, surface):
        return {"class": cls, "position": pos, "normal": [0, 0, -1], "width_m": 0.1, "height_m": 0.1,
                "surface": surface}

    truth = {"schema": "sbsc.truth/1", "objects": [
        obj("smoke_detector", [1, 1, 2.8], "ceiling"), obj("smoke_detector", [3, 1, 2.8], "ceiling"),
        obj("switch", [0, 2, 1.1], "wall"), obj("socket_x1", [5, 5, 0.3], "column")]}
    (tmp_path / "t.json").write_text(json.dumps(truth))

    def det(i, cls, pos, surface=None):
        d = {"id": f"D{i}", "class": cls, "wall": "C01" if surface else "W1", "position": pos, "u": 0, "v": 0,
             "width_m": 0.1, "height_m": 0.1, "alpha": 1.0, "rho_depth": 0.9, "rho_colour": None, "source": "depth"}
        return {**d, **({"surface": surface} if surface else {})}

    doc = {"schema": "sbsc.detections/1", "walls": [], "openings": [], "detections": [
        det(1, "smoke_detector", [1.003, 1, 2.8], "ceiling"), det(2, "smoke_detector", [7, 7, 2.8], "ceiling"),
        det(3, "switch", [0, 2.002, 1.1])]}
    table = evaluate(doc, read_truth(tmp_path / "t.json"))
    rows = {r.class_id: r for r in table.surfaces}
    assert (rows["ceiling"].instances, rows["ceiling"].tp, rows["ceiling"].fp) == (2, 1, 1)
    assert rows["ceiling"].h_mean_mm == pytest.approx(3.0)
    assert (rows["wall"].tp, rows["wall"].fp, rows["column"].fn) == (1, 0, 1)
    assert "on ceilings" in format_table(table) and table.to_dict()["surfaces"][1]["class"] == "ceiling"


def _stepped_cloud(rng, low_x: float = 8.0, low_z: float = 2.5) -> PointCloud:
    """A 13 m x 7 m room, ceiling at 2.8 m, lower (``low_z``) over x > ``low_x``; walls to the ceiling."""
    n = 120_000
    xy = rng.uniform((0.0, 0.0), (13.0, 7.0), (n, 2))
    z = np.where(xy[:, 0] > low_x, low_z, 2.8) + rng.normal(0, 0.002, n)
    ceiling = np.column_stack([xy, z])
    step = np.column_stack([np.full(4000, low_x), rng.uniform(0, 7, 4000), rng.uniform(low_z, 2.8, 4000)])
    floor = np.column_stack([rng.uniform((0.0, 0.0), (13.0, 7.0), (40_000, 2)), np.zeros(40_000)])
    xyz = np.vstack([ceiling, step, floor]).astype(np.float32)
    return PointCloud(xyz, np.full((len(xyz), 3), 200, np.uint8), np.zeros(3))


def test_the_walls_partition_pass_bins_the_ceilings_as_ceiling_part_does(tmp_path):
    """The walls' partition pass with a :class:`CeilingBinning` writes the tiles' partitions
    byte for byte as :func:`ceiling_part` does (the scan read once for both, in several
    parts), and :func:`binned_records` counts what each tile got."""
    from sbsc_core.imaging.partition import WallIndex, partition_part
    from sbsc_core.settings import SegmentationSettings

    seg = _room()
    s = CeilingSettings()
    rng = np.random.default_rng(5)
    cloud = _stepped_cloud(rng)
    tiles = ceiling_tiles(seg, s, ceiling_levels(cloud, seg, s))
    assert any(t.level == 1 for t in tiles)
    wall = np.column_stack([np.zeros(20_000), rng.uniform(0, 7, 20_000), rng.uniform(0, 2.8, 20_000)])  # W1, x = 0
    xyz = np.vstack([cloud.xyz, wall.astype(np.float32)])
    write_ply(tmp_path / "scan.ply", xyz, np.full((len(xyz), 3), 200, np.uint8))
    parts, _ = plan_parts([tmp_path / "scan.ply"], part_points=len(xyz) // 3)
    assert len(parts) >= 3
    origin = scan_origin(tmp_path / "scan.ply")
    ortho = OrthoimageSettings()
    walls = [w.frame for w in seg.walls]
    alone, fused = tmp_path / "alone", tmp_path / "fused"
    want = sum(np.asarray(ceiling_part(p, origin, tiles, walls, str(alone), ortho=ortho, wall_clear_m=0.05))
               for p in parts)
    index = WallIndex.build(seg.walls, origin, SegmentationSettings())
    binning = CeilingBinning(tiles, walls, str(fused), origin, ortho, 0.05)
    for p in parts:
        partition_part(p, origin, index, str(fused), points=0, spilled=False, ortho=ortho, also=binning)
    assert want.sum() > 100_000 and (want == 0).any()
    np.testing.assert_array_equal(binned_records(fused, len(tiles)), want)
    files = sorted(f.relative_to(alone) for f in (alone / "ceilings").rglob("*.rec"))
    assert files == sorted(f.relative_to(fused) for f in (fused / "ceilings").rglob("*.rec"))
    for f in files:
        assert (alone / f).read_bytes() == (fused / f).read_bytes()
    assert any((fused / "wall-0000").rglob("*.rec"))  # and the walls' partitions as ever


def test_a_lower_ceiling_gets_its_own_level_and_tiles(tmp_path):
    seg = _room()
    s = CeilingSettings()
    (levels,) = ceiling_levels(_stepped_cloud(np.random.default_rng(3)), seg, s)
    assert levels.storey == "S1" and levels.z == pytest.approx((2.5,), abs=0.003)
    lab = levels.label(np.array([[10.5, 3.5], [4.0, 3.5], [12.8, 0.2], [7.5, 3.5], [50.0, 50.0]]))
    assert list(lab) == [1, 0, 1, 0, 0]
    tiles = ceiling_tiles(seg, s, [levels])
    main, low = [t for t in tiles if t.level == 0], [t for t in tiles if t.level == 1]
    assert [t.id for t in main] == [f"C0{k}" for k in range(1, 7)]  # as without levels
    assert [t.id for t in low] == ["C07", "C08"] and low[0].frame.origin[2] == pytest.approx(2.5, abs=0.003)
    assert 7.5 <= low[0].frame.origin[0] <= 8.3 and low[0].frame.width_m <= 5.5
    # the low ceiling's points go to its own tile at depth ~0, not to the storey's tiles
    cloud = _stepped_cloud(np.random.default_rng(4))
    write_ply(tmp_path / "scan.ply", cloud.xyz, cloud.rgb)
    parts, _ = plan_parts([tmp_path / "scan.ply"])
    origin = scan_origin(tmp_path / "scan.ply")
    ortho = OrthoimageSettings()
    walls = [w.frame for w in seg.walls]
    written = sum(np.asarray(ceiling_part(p, origin, tiles, walls, str(tmp_path), ortho=ortho,
                                          wall_clear_m=0.05)) for p in parts)
    img = tile_orthoimage(tmp_path, 6, low[0], ortho)
    assert written[6] > 10_000 and np.nanmedian(img.depth) == pytest.approx(0.0, abs=0.003)
    for k, t in enumerate(main):
        x0 = t.frame.origin[0]
        if x0 > 8.5:  # over the low ceiling only: the storey's tile gets nothing there
            assert written[k] == 0
    no_levels = ceiling_levels(_stepped_cloud(np.random.default_rng(3), low_z=2.8), seg, s)
    assert no_levels == []


def test_surfaces_without_points_are_left_out(tmp_path):
    from sbsc_core.pipeline.executors import InlineExecutor, surface_stage
    from sbsc_core.settings import DetectionSettings

    ran = []

    def part_fn(n):
        return [0, n, 0]

    def job_fn(scratch, k, sf, *, templates, prototypes, s, images):
        ran.append((k, images))  # the task parks its result itself
        return sf, "result", {}

    import sbsc_core.pipeline.executors as pl

    saved = pl._templates_job
    pl._templates_job = lambda library, s, classes: ({}, None)
    try:
        kept, results, _ = surface_stage(InlineExecutor(), stage="x", part_fn=part_fn, part_jobs=[(3,), (4,)],
                                         job_fn=job_fn, surfaces=["A", "B", "C"], library=None, classes=[],
                                         s=DetectionSettings(), scratch=tmp_path, parked=tmp_path, in_flight=2,
                                         progress=lambda *a: None)
    finally:
        pl._templates_job = saved
    assert list(kept) == [0, 7, 0] and ran == [(1, str(tmp_path))] and results == {"B": "result"}


def test_surfaces_are_searched_where_the_library_mounts_a_searched_class():
    from sbsc_core.io.documents import ExpectedCounts
    from sbsc_core.io.models import load_model_library
    from sbsc_core.paths import bundled_models_dir
    from sbsc_core.pipeline.walls import searched_surfaces
    from sbsc_core.settings import DetectionSettings

    lib = load_model_library(bundled_models_dir())
    s = DetectionSettings()
    both = searched_surfaces(s, lib, None)  # the bundled smoke detector may be on a ceiling, a switch on a column
    assert both.ceilings.enabled and both.columns.enabled
    walls_only = searched_surfaces(s, lib, ExpectedCounts({"radiator": 2, "switch": 0}))
    assert not walls_only.ceilings.enabled and not walls_only.columns.enabled
    ceiling = searched_surfaces(s, lib, ExpectedCounts({"smoke_detector": 1}))
    assert ceiling.ceilings.enabled and not ceiling.columns.enabled
    s.ceilings.enabled = False  # --no-ceilings
    assert not searched_surfaces(s, lib, ExpectedCounts({"smoke_detector": 1})).ceilings.enabled


@pytest.mark.slow
def test_detect_no_ceilings_leaves_the_ceiling_unsearched(tmp_path):
    from sbsc_core.cli import main

    sim, det = tmp_path / "sim", tmp_path / "det"
    assert main(["-q", "simulate", "--scene", "one_room", "--ceiling-objects", "--out", str(sim)]) == 0
    assert main(["-q", "detect", str(sim / "scan.ply"), "--models", str(sim / "models"), "--expected",
                 str(sim / "expected.json"), "--no-ceilings", "--out", str(det)]) == 0
    doc = json.loads((det / "detections.json").read_text())
    assert not doc.get("surfaces") and not any(d.get("surface") == "ceiling" for d in doc["detections"])


def test_cells_sorted_highest_first_as_lexsort():
    """The packed-key sort of ceiling_levels orders cells and heights exactly as np.lexsort,
    negative heights, signed zeros and subnormals included."""
    from sbsc_core.scene.ceilings import _by_cell_highest_first

    rng = np.random.default_rng(3)
    z = rng.normal(0.0, 3.0, 20_000).astype(np.float32)
    z[:4] = [0.0, -0.0, 1e-40, -1e-40]
    cell = rng.integers(0, 300, len(z))
    order = np.lexsort((-z.astype(np.float64), cell))
    cell_s, z_s = _by_cell_highest_first(cell, z)
    assert np.array_equal(cell_s, cell[order])
    assert np.array_equal(z_s, z[order])
    assert z_s.dtype == np.float32


def test_ceiling_binning_is_made_when_a_ceiling_class_is_searched(tmp_path):
    """The walls' partition pass bins the ceilings only when :func:`detect_ceilings` will search
    a tile for a class: the binning holds the tiles it will search, else there is none."""
    from sbsc_core.io.models import load_model_library
    from sbsc_core.paths import bundled_models_dir
    from sbsc_core.pipeline.surfaces import ceiling_binning
    from sbsc_core.settings import DetectionSettings

    lib = load_model_library(bundled_models_dir())
    seg = _room()
    s = DetectionSettings()
    on_ceiling = lib.classes_on("ceiling")
    assert on_ceiling and "switch" not in on_ceiling
    binning = ceiling_binning(seg, np.zeros(3), library=lib, expected={on_ceiling[0]: 2, "switch": 3}, s=s,
                              scratch=tmp_path)
    assert [t.id for t in binning.tiles] == [t.id for t in ceiling_tiles(seg, s.ceilings)]
    assert len(binning.walls) == len(seg.walls) and binning.scratch == str(tmp_path)
    assert ceiling_binning(seg, np.zeros(3), library=lib, expected={"switch": 3}, s=s, scratch=tmp_path) is None
    assert ceiling_binning(Segmentation(0.0, 2.8, [], []), np.zeros(3), library=lib, expected=None, s=s,
                           scratch=tmp_path) is None


def test_plan_cells_are_the_cells_of_the_points_xy_in_float64():
    """:func:`_plan_cells` (one axis at a time, in place) gives the lowest coordinate and the
    cells that the (N, 2) float64 arithmetic gives on a scan's float32 points far from the
    origin, cell edges and all."""
    from sbsc_core.scene.ceilings import _plan_cells

    rng = np.random.default_rng(11)
    origin = np.array([512_345.0, 5_402_117.0, 211.0])
    xyz = rng.uniform((-20.0, -9.0, 0.0), (14.0, 30.0, 3.0), (200_000, 3)).astype(np.float32)
    xyz[:1000, :2] = np.round(xyz[:1000, :2] * 4) / 4  # on the edges of 0.25 m cells
    idx = np.flatnonzero(xyz[:, 2] > 1.0)
    c = 0.25
    xy = np.take(xyz, idx, axis=0)[:, :2].astype(np.float64) + origin[:2]
    x0, y0 = xy.min(axis=0)
    ij = np.floor((xy - (x0, y0)) / c).astype(np.int64)
    for axis, lo in ((0, x0), (1, y0)):
        got_lo, got = _plan_cells(xyz[:, axis], idx, origin[axis], c)
        assert got_lo == lo
        np.testing.assert_array_equal(got, ij[:, axis])
