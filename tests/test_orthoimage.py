"""The 4D orthoimage J_CD (paper, section 3.2): depth, colour, holes, robust medians."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sbsc_core.imaging.orthoimage import build_orthoimage, near_wall, near_walls, rasterize_median
from sbsc_core.settings import OrthoimageSettings
from sbsc_core.types import PointCloud, Wall, WallFrame

WALL_RGB = (200, 190, 180)


def _wall(angle_deg: float = 30.0, width: float = 1.2, height: float = 1.0) -> WallFrame:
    a = math.radians(angle_deg)
    u = np.array([math.cos(a), math.sin(a), 0.0])
    n = np.cross(u, [0.0, 0.0, 1.0])
    return WallFrame(origin=np.array([12.0, -7.0, 3.0]), axis_u=u, axis_v=np.array([0.0, 0.0, 1.0]),
                     normal=n, width_m=width, height_m=height)


def _cloud(frame: WallFrame, uvd: np.ndarray, rgb: np.ndarray, origin=(10.0, -5.0, 2.0)) -> tuple[PointCloud, Wall]:
    world = frame.to_world(uvd[:, 0], uvd[:, 1], uvd[:, 2])
    org = np.asarray(origin, float)
    cloud = PointCloud((world - org).astype(np.float32), rgb.astype(np.uint8), org)
    return cloud, Wall("W07", frame, np.arange(len(world), dtype=np.int64))


def _grid(frame: WallFrame, step: float, rng: np.random.Generator) -> np.ndarray:
    u, v = np.meshgrid(np.arange(step / 2, frame.width_m, step), np.arange(step / 2, frame.height_m, step))
    u = u.ravel() + rng.uniform(-0.2, 0.2, u.size) * step
    v = v.ravel() + rng.uniform(-0.2, 0.2, v.size) * step
    return np.column_stack([u, v, rng.normal(0.0, 0.001, u.size)])


def test_box_depth_at_the_right_place_on_a_rotated_wall() -> None:
    rng = np.random.default_rng(0)
    fr = _wall()
    uvd = _grid(fr, 0.0025, rng)
    box = (uvd[:, 0] > 0.40) & (uvd[:, 0] < 0.60) & (uvd[:, 1] > 0.30) & (uvd[:, 1] < 0.40)
    uvd[box, 2] += 0.05
    rgb = np.tile(WALL_RGB, (len(uvd), 1))
    rgb[box] = (30, 40, 200)
    cloud, wall = _cloud(fr, uvd, rgb)
    o = build_orthoimage(cloud, wall, OrthoimageSettings())
    assert o.wall_id == "W07" and o.pixel_m == 0.005
    assert o.shape == (200, 240)
    assert o.mask.all()
    high = o.depth > 0.025
    r, c = np.nonzero(high)
    u, v = o.pixel_to_uv(r, c)
    assert u.min() == pytest.approx(0.40, abs=0.006) and u.max() == pytest.approx(0.60, abs=0.006)
    assert v.min() == pytest.approx(0.30, abs=0.006) and v.max() == pytest.approx(0.40, abs=0.006)
    assert np.median(o.depth[high]) == pytest.approx(0.05, abs=0.001)
    assert abs(np.median(o.depth[~high])) < 0.001
    assert np.all(o.colour[high][:, 2] > 150) and np.all(np.abs(o.colour[~high].astype(int) - WALL_RGB).max(axis=1) <= 1)
    # row 0 is the top of the wall: the box (v 0.30-0.40 of 1.0 m) is in the lower half
    assert r.min() > 100


def test_holes_stay_holes_sampling_gaps_are_filled() -> None:
    rng = np.random.default_rng(1)
    fr = _wall(angle_deg=-75.0)
    uvd = _grid(fr, 0.004, rng)
    hole = (uvd[:, 0] > 0.5) & (uvd[:, 0] < 0.6) & (uvd[:, 1] > 0.5) & (uvd[:, 1] < 0.6)
    gap = (np.abs(uvd[:, 0] - 0.2025) < 0.0025) & (np.abs(uvd[:, 1] - 0.2025) < 0.0025)  # one pixel
    keep = ~hole & ~gap
    cloud, wall = _cloud(fr, uvd[keep], np.tile(WALL_RGB, (keep.sum(), 1)))
    o = build_orthoimage(cloud, wall, OrthoimageSettings())
    r0, r1 = int((1.0 - 0.6) / 0.005) + 1, int((1.0 - 0.5) / 0.005) - 1
    c0, c1 = int(0.5 / 0.005) + 1, int(0.6 / 0.005) - 1
    assert not o.mask[r0:r1, c0:c1].any()
    assert np.isnan(o.depth[r0:r1, c0:c1]).all()
    assert (o.colour[r0:r1, c0:c1] == 0).all()
    # the isolated missing pixel was a sampling gap: filled from its neighbours
    assert o.mask[int((1.0 - 0.2025) / 0.005), int(0.2025 / 0.005)]
    off = build_orthoimage(cloud, wall, OrthoimageSettings(fill_gaps_px=0))
    assert not off.mask[int((1.0 - 0.2025) / 0.005), int(0.2025 / 0.005)]
    assert off.mask.sum() < o.mask.sum()


def test_median_is_robust_to_outliers_and_depth_range_applies() -> None:
    rng = np.random.default_rng(2)
    fr = _wall(width=0.5, height=0.5)
    base = _grid(fr, 0.005, rng)
    parts, cols = [], []
    for k in range(5):  # five points per pixel, one of them an outlier
        p = base.copy()
        p[:, :2] += rng.uniform(-0.0015, 0.0015, (len(p), 2))
        c = np.tile(WALL_RGB, (len(p), 1))
        if k == 0:
            p[:, 2] += 0.08  # a stray point in front
            c[:] = (255, 0, 0)
        parts.append(p)
        cols.append(c)
    far = base[:500].copy()
    far[:, 2] = -0.5  # seen through a hole: outside the depth range, ignored
    uvd = np.concatenate([*parts, far])
    rgb = np.concatenate([*cols, np.zeros((500, 3))])
    cloud, wall = _cloud(fr, uvd, rgb)
    o = build_orthoimage(cloud, wall, OrthoimageSettings(fill_gaps_px=0))
    assert o.mask.mean() > 0.95
    assert np.nanmax(np.abs(o.depth)) < 0.005
    assert np.abs(o.colour[o.mask].astype(int) - WALL_RGB).max() <= 1


def test_rasterize_median_even_counts_and_empty_pixels() -> None:
    pixel = np.array([0, 0, 3, 3, 3, 5])
    depth = np.array([0.01, 0.03, 0.0, 0.02, 0.2, -0.01])
    rgb = np.array([[10, 20, 30], [30, 40, 50], [1, 1, 1], [3, 3, 3], [250, 250, 250], [7, 8, 9]])
    d, c, m = rasterize_median(pixel, depth, rgb, (2, 3), depth_range=(-0.06, 0.3), quantum=0.0001)
    np.testing.assert_array_equal(m.ravel(), [True, False, False, True, False, True])
    assert d.ravel()[0] == pytest.approx(0.02, abs=1e-4)
    assert d.ravel()[3] == pytest.approx(0.02, abs=1e-4)
    assert d.ravel()[5] == pytest.approx(-0.01, abs=1e-4)
    np.testing.assert_array_equal(c.reshape(-1, 3)[0], [20, 30, 40])
    np.testing.assert_array_equal(c.reshape(-1, 3)[3], [3, 3, 3])
    assert np.isnan(d.ravel()[1]) and (c.reshape(-1, 3)[1] == 0).all()


def test_sparse_scan_is_filled_but_hole_edges_do_not_move() -> None:
    """Points every ~2.2 pixels: the sieve is closed, a 30 cm hole keeps its exact edges."""
    rng = np.random.default_rng(3)
    fr = _wall(angle_deg=10.0, width=1.0, height=1.0)
    uvd = _grid(fr, 0.011, rng)
    hole = (uvd[:, 0] > 0.30) & (uvd[:, 0] < 0.60) & (uvd[:, 1] > 0.30) & (uvd[:, 1] < 0.60)
    cloud, wall = _cloud(fr, uvd[~hole], np.tile(WALL_RGB, ((~hole).sum(), 1)))
    raw = build_orthoimage(cloud, wall, OrthoimageSettings(fill_gaps_px=0))
    o = build_orthoimage(cloud, wall, OrthoimageSettings())
    outside = np.ones(o.shape, bool)
    outside[int(0.38 / 0.005):int(0.72 / 0.005), int(0.28 / 0.005):int(0.62 / 0.005)] = False
    outside[:3] = outside[-3:] = False
    outside[:, :3] = outside[:, -3:] = False
    assert raw.mask[outside].mean() < 0.3
    assert o.mask[outside].mean() > 0.97
    assert np.nanmax(np.abs(o.depth)) < 0.005
    # no pixel more than 1.5 cm (= one point spacing) inside the hole got data
    inner = (slice(int(0.415 / 0.005), int(0.685 / 0.005)), slice(int(0.315 / 0.005), int(0.585 / 0.005)))
    assert not o.mask[inner].any()


def test_layers_keep_the_wall_behind_furniture_and_hide_furniture_alone() -> None:
    """Per-pixel layers: points of furniture standing off the wall (a layer reaching beyond
    ``furniture_depth_m``) never mix into the wall's depth or colour; where furniture alone was
    seen the pixel has no data; an object's relief (one layer) and a pixel whose majority is
    a near layer keep their depth, the plain median (no layers) is unchanged."""
    pixel = np.array([0, 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4])
    depth = np.array([0.001, -0.001, 0.12, 0.28,  # wall, a desk top continuum 0.12..0.28 in front
                      0.12, 0.2, 0.29,  # furniture alone (a desk top seen edge-on, reaching 0.29)
                      0.118, 0.12, 0.121,  # an extinguisher's front: one layer
                      0.05, 0.051, 0.0,  # a board 5 cm out seen twice, the wall once: the board
                      0.0, 0.0, 0.29])  # the wall, a stray cabinet point far out
    rgb = np.array([[200, 190, 180], [202, 192, 182], [90, 60, 30], [90, 60, 30],
                    [90, 60, 30]] * 2 + [[220, 30, 30]] * 3 + [[20, 20, 200]] * 2 + [[200, 190, 180]] * 3)[:16]
    rgb[7:10] = (220, 30, 30)
    rgb[10:12] = (20, 20, 200)
    rgb[12:15] = (200, 190, 180)
    rgb[15] = (90, 60, 30)
    d, c, m = rasterize_median(pixel, depth, rgb, (1, 5), depth_range=(-0.06, 0.3), quantum=0.0001, layer_gap=0.02,
                               furniture_depth=0.25, min_layer_share=0.5)
    np.testing.assert_array_equal(m.ravel(), [True, False, True, True, True])
    assert d.ravel()[0] == pytest.approx(0.0, abs=2e-4) and d.ravel()[4] == pytest.approx(0.0, abs=2e-4)
    assert (np.abs(c[0, 0].astype(int) - (201, 191, 181)) <= 1).all()  # the wall's colour, not the desk's
    assert (c[0, 4] == (200, 190, 180)).all()
    assert d.ravel()[2] == pytest.approx(0.12, abs=2e-4) and (c[0, 2] == (220, 30, 30)).all()
    assert d.ravel()[3] == pytest.approx(0.0505, abs=2e-4) and (c[0, 3] == (20, 20, 200)).all()
    plain = rasterize_median(pixel, depth, rgb, (1, 5), depth_range=(-0.06, 0.3), quantum=0.0001)
    assert plain[2].all() and plain[0].ravel()[0] == pytest.approx(0.0605, abs=2e-4)


def test_desk_in_front_of_a_wall_leaves_the_wall_and_a_socket_under_it() -> None:
    """A desk's top (a horizontal surface: one pixel row sees it at every depth) and a cabinet's
    side (one pixel column), both reaching far out, seen with the wall and a socket beside
    them: the wall stays at the plane, the socket keeps its relief and the cabinet-only
    pixels are holes, not relief (with ``layer_gap_m``; off by default)."""
    rng = np.random.default_rng(5)
    fr = _wall(width=1.0, height=1.0)
    wall = _grid(fr, 0.004, rng)
    sock = (np.abs(wall[:, 0] - 0.5) < 0.04) & (np.abs(wall[:, 1] - 0.3) < 0.04)
    wall[sock, 2] += 0.012
    n = 4000
    top = np.column_stack([rng.uniform(0.0, 1.0, n), rng.uniform(0.7, 0.705, n), rng.uniform(0.01, 0.3, n)])
    side = np.column_stack([rng.uniform(0.8, 0.805, n), rng.uniform(0.0, 0.7, n), rng.uniform(0.01, 0.3, n)])
    front = np.column_stack([rng.uniform(0.85, 1.0, n), rng.uniform(0.0, 0.7, n), rng.uniform(0.26, 0.29, n)])
    hidden = (wall[:, 0] > 0.81) & (wall[:, 1] < 0.7)  # behind the cabinet: not seen
    uvd = np.concatenate([wall[~hidden], top, side, front])
    rgb = np.concatenate([np.tile(WALL_RGB, ((~hidden).sum(), 1)), np.tile((90, 60, 30), (3 * n, 1))])
    cloud, w = _cloud(fr, uvd, rgb)
    o = build_orthoimage(cloud, w, OrthoimageSettings(fill_gaps_px=0, layer_gap_m=0.02))
    px = 0.005
    row = int((1.0 - 0.7025) / px)
    seen = o.mask[row, : int(0.78 / px)]
    top_row = o.depth[row, : int(0.78 / px)]
    assert seen.mean() > 0.7 and np.nanmedian(np.abs(top_row)) < 0.003
    assert (np.abs(top_row[seen]) < 0.025).mean() > 0.95
    assert not o.mask[int(0.5 / px):, int(0.86 / px):].any()  # the cabinet's front alone: no data
    s = o.depth[int((1.0 - 0.3) / px), int(0.5 / px)]
    assert s == pytest.approx(0.012, abs=0.003)
    old = build_orthoimage(cloud, w, OrthoimageSettings(fill_gaps_px=0, layer_gap_m=None))
    assert np.nanmax(old.depth[row, : int(0.78 / px)]) > 0.05  # the plain median mixed the desk in


def test_near_walls_is_near_wall_of_each_wall_or_ed() -> None:
    """Walls of a room (one turned 30 degrees, one leaning), points near them, beyond their
    ends and far off, relative to a far origin: :func:`near_walls` marks exactly the points
    that :func:`near_wall` marks for some wall."""
    rng = np.random.default_rng(3)
    origin = np.array([1000.0, -2000.0, 5.0])

    def frame(o, u, w, lean=0.0):
        u = np.array([math.cos(u), math.sin(u), 0.0])
        n = np.array([-u[1], u[0], 0.0])
        up = np.array([0.0, 0.0, 1.0])
        v = math.cos(lean) * up + math.sin(lean) * n
        return WallFrame(np.array(o, float) + origin, u, v, np.cross(u, v), w, 3.0)

    frames = [frame((0, 0, 0), 0.0, 8.0), frame((8, 0, 0), math.pi / 2, 6.0), frame((8, 6, 0), math.pi, 8.0),
              frame((0, 6, 0), -math.pi / 2, 6.0), frame((2, 2, 0), math.pi / 6, 3.0),
              frame((1, 5, 0), 0.0, 2.0, lean=0.3)]
    on = []
    for f in frames:  # points on and about each wall's plane, a little beyond its ends
        u, v, d = rng.uniform(-0.3, f.width_m + 0.3, 4000), rng.uniform(0, 3, 4000), rng.normal(0, 0.06, 4000)
        on.append(f.origin + u[:, None] * f.axis_u + v[:, None] * f.axis_v + d[:, None] * f.normal)
    far = rng.uniform((-20, -20, 0), (30, 30, 3), (20000, 3)) + origin
    xyz = (np.concatenate(on + [far]) - origin).astype(np.float32)
    want = np.zeros(len(xyz), bool)
    for f in frames:
        want |= near_wall(xyz, f, 0.05, origin)
    got = near_walls(xyz, frames, 0.05, origin)
    assert 5000 < want.sum() < len(xyz) - 20000
    np.testing.assert_array_equal(got, want)
    assert not near_walls(xyz, [], 0.05, origin).any()
    site = frames + [frame((2500, 2000, 0), 0.3, 5.0)]  # a wall far off: a coarser grid over the site
    f = site[-1]
    far_wall = f.origin + rng.uniform(0, 5, 3000)[:, None] * f.axis_u + rng.normal(0, 0.06, 3000)[:, None] * f.normal
    xyz = np.concatenate([xyz, (far_wall - origin).astype(np.float32)])
    want = np.zeros(len(xyz), bool)
    for f in site:
        want |= near_wall(xyz, f, 0.05, origin)
    assert want[-3000:].sum() > 1000
    np.testing.assert_array_equal(near_walls(xyz, site, 0.05, origin), want)
    assert not near_walls(xyz[:0], frames, 0.05, origin).any()


def test_fill_sampling_gaps_fills_between_data_with_the_window_mean_not_a_hole():
    from sbsc_core.imaging.orthoimage import fill_sampling_gaps

    rng = np.random.default_rng(3)
    mask = np.ones((40, 50), bool)
    mask[10, 10] = mask[20, 30] = False  # sampling gaps: data all around
    mask[25:40, 0:20] = False  # a hole (an opening): its rim has data on one side only
    depth = np.where(mask, rng.normal(0.0, 0.01, mask.shape), np.nan).astype(np.float32)
    colour = (rng.integers(0, 256, mask.shape + (3,)) * mask[..., None]).astype(np.uint8)
    d, c, m = fill_sampling_gaps(depth, colour, mask, 2, 0.5)
    assert m[10, 10] and m[20, 30] and not m[25:40, 0:20].any()
    for r, q in ((10, 10), (20, 30)):
        win = (slice(r - 2, r + 3), slice(q - 2, q + 3))
        ok = mask[win]
        assert d[r, q] == pytest.approx(float(depth[win][ok].astype(np.float64).mean()), abs=1e-6)
        assert np.array_equal(c[r, q], np.rint(colour[win][ok].astype(np.float64).mean(axis=0)).astype(np.uint8))
    assert np.array_equal(d[mask], depth[mask]) and np.array_equal(c[mask], colour[mask])


def test_depth_visualisation_greys_the_relief_and_whitens_no_data():
    from sbsc_core.pipeline.walls import depth_visualisation

    depth = np.array([[0.0, 0.05, -0.05], [np.nan, 1.0, -1.0]], np.float32)
    assert depth_visualisation(depth).tolist() == [[128, 64, 191], [255, 0, 254]]


def test_mean_of_packed_colours_is_the_shifted_channels_mean():
    """:func:`_mean_of_packed` gives each channel's ``(a + b + 1) // 2`` as the int64 shifts
    and masks do, over the whole 24-bit range (white, black, odd sums)."""
    from sbsc_core.imaging.orthoimage import _mean_of_packed

    rng = np.random.default_rng(4)
    a = rng.integers(0, 1 << 24, 50_000, dtype=np.int64)
    b = rng.integers(0, 1 << 24, 50_000, dtype=np.int64)
    a[:3], b[:3] = (0xFFFFFF, 0, 0xFFFFFF), (0xFFFFFF, 0, 0xFEFEFE)
    want = np.stack([((((a >> s) & 255) + ((b >> s) & 255) + 1) // 2).astype(np.uint8) for s in (16, 8, 0)], axis=-1)
    got = _mean_of_packed(a, b)
    assert got.dtype == np.uint8
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(_mean_of_packed(a[::3], b[::3]), want[::3])  # strided input
