"""Scan readers (contract 1) on real third-party files and on files written here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.io.ply import write_ply
from sbsc_core.io.scan_source import colours_16_to_8
from sbsc_core.io.scans import read_scan, read_scans

from .scan_files import _write_ply_struct
from .shared_data import shared_data

RNG = np.random.default_rng(7)


def _cloud(n: int = 500, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    xyz = RNG.uniform(-5, 5, (n, 3)) + offset
    rgb = RNG.integers(0, 256, (n, 3), dtype=np.uint8)
    return xyz, rgb


def _check(cloud, xyz: np.ndarray, rgb: np.ndarray, tol: float = 1e-5) -> None:
    assert len(cloud) == len(xyz)
    assert cloud.xyz.dtype == np.float32 and cloud.rgb.dtype == np.uint8
    assert cloud.origin.dtype == np.float64 and cloud.origin.shape == (3,)
    np.testing.assert_allclose(cloud.world(), xyz, atol=tol)
    np.testing.assert_array_equal(cloud.rgb, rgb)




# --------------------------------------------------------------------------- real files


@pytest.fixture
def real() -> Path:
    """The real-format files of other projects (pye57, laspy): ``shared/data/real-formats``."""
    return shared_data("real-formats")


def test_real_e57_matches_pye57(real):
    import pye57

    REAL = real
    cloud = read_scan(REAL / "pumpAVisualReferenceImage.e57")
    assert len(cloud) == 155_201  # all points are flagged valid in this file
    assert np.isfinite(cloud.xyz).all()
    ref = pye57.E57(str(REAL / "pumpAVisualReferenceImage.e57")).read_scan(0, colors=True)
    world = cloud.world()
    np.testing.assert_allclose(world[:, 0], ref["cartesianX"], atol=1e-5)
    np.testing.assert_allclose(world[:, 2], ref["cartesianZ"], atol=1e-5)
    np.testing.assert_array_equal(cloud.rgb[:, 1], ref["colorGreen"])
    assert cloud.rgb.max() == 255 and cloud.rgb.dtype == np.uint8


@pytest.mark.parametrize("name", ["simple.las", "simple.laz"])
def test_real_las_laz(name, real):
    import laspy

    REAL = real
    cloud = read_scan(REAL / name)
    ref = laspy.read(REAL / name)
    assert len(cloud) == 1065
    assert np.isfinite(cloud.xyz).all()
    np.testing.assert_allclose(cloud.world(), np.column_stack([ref.x, ref.y, ref.z]), atol=1e-3)
    # the file's RGB only uses 0..255 in its 16-bit fields: kept as 8-bit values
    np.testing.assert_array_equal(cloud.rgb[:, 0], np.asarray(ref.red))
    assert cloud.sources == (str(REAL / name),)
    assert np.abs(cloud.xyz).max() < 5000  # recentred: float32 keeps centimetres


# --------------------------------------------------------------------------- PLY


def test_ply_binary_uchar_float_and_double(tmp_path):
    xyz, rgb = _cloud(offset=1000.0)
    write_ply(tmp_path / "f.ply", xyz, rgb)
    _check(read_scan(tmp_path / "f.ply"), xyz.astype(np.float32).astype(np.float64), rgb, tol=1e-3)
    utm = xyz + np.array([500_000.0, 4_000_000.0, 0.0])
    write_ply(tmp_path / "d.ply", utm, rgb, double=True)
    cloud = read_scan(tmp_path / "d.ply")
    _check(cloud, utm, rgb, tol=1e-5)  # double input keeps sub-millimetre precision via the origin
    assert np.abs(cloud.xyz).max() < 10


def test_ply_big_endian_float_colour_extra_properties(tmp_path):
    xyz, rgb = _cloud()
    rec = np.zeros(len(xyz), [("nx", "f4"), ("x", "f8"), ("y", "f8"), ("z", "f8"), ("intensity", "u2"),
                              ("red", "f4"), ("green", "f4"), ("blue", "f4")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["red"], rec["green"], rec["blue"] = (rgb / 255.0).T
    rec["intensity"] = 999
    face = "element face 1\nproperty list uchar int vertex_indices\n"
    _write_ply_struct(tmp_path / "be.ply", rec, "binary_big_endian", face, tail=b"\x03\x00\x00\x00\x00")
    _check(read_scan(tmp_path / "be.ply"), xyz, rgb)


def test_ply_ascii_uchar_and_float_colours(tmp_path):
    xyz, rgb = _cloud(200)
    rec = np.zeros(len(xyz), [("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1"), ("green", "u1"),
                              ("blue", "u1"), ("alpha", "u1")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["red"], rec["green"], rec["blue"] = rgb.T
    _write_ply_struct(tmp_path / "a.ply", rec, "ascii", "element face 0\nproperty list uchar int vertex_indices\n")
    _check(read_scan(tmp_path / "a.ply"), xyz, rgb)

    rec2 = np.zeros(len(xyz), [("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "f4"), ("green", "f4"), ("blue", "f4")])
    rec2["x"], rec2["y"], rec2["z"] = xyz.T
    rec2["red"], rec2["green"], rec2["blue"] = (rgb / 255.0).T
    _write_ply_struct(tmp_path / "af.ply", rec2, "ascii")
    _check(read_scan(tmp_path / "af.ply"), xyz, rgb, tol=1e-5)


def test_ply_ushort_colours_scaled_from_16_bit(tmp_path):
    xyz, rgb = _cloud(100)
    rec = np.zeros(len(xyz), [("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u2"), ("green", "u2"), ("blue", "u2")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["red"], rec["green"], rec["blue"] = (rgb.astype(np.uint16) * 257).T
    _write_ply_struct(tmp_path / "u16.ply", rec, "binary_little_endian")
    np.testing.assert_array_equal(read_scan(tmp_path / "u16.ply").rgb, rgb)


# --------------------------------------------------------------------------- text


def test_xyz_txt_and_pts(tmp_path):
    xyz, rgb = _cloud(300)
    rows = np.column_stack([xyz, rgb])
    np.savetxt(tmp_path / "a.xyz", rows, fmt="%.6f %.6f %.6f %d %d %d", header="x y z r g b")
    _check(read_scan(tmp_path / "a.xyz"), xyz, rgb, tol=2e-6)
    # comma separated with an intensity column and float 0..1 colours
    rows7 = np.column_stack([xyz, np.full(len(xyz), 0.5), rgb / 255.0])
    np.savetxt(tmp_path / "b.txt", rows7, fmt="%.6f", delimiter=",")
    _check(read_scan(tmp_path / "b.txt"), xyz, rgb, tol=2e-6)
    # .pts in two blocks (two stations): count, x y z intensity r g b
    with open(tmp_path / "c.pts", "w") as fh:
        for part in (slice(0, 120), slice(120, 300)):
            fh.write(f"{part.stop - part.start}\n")
            block = np.column_stack([xyz[part], np.full(part.stop - part.start, -1200), rgb[part]])
            np.savetxt(fh, block, fmt="%.6f %.6f %.6f %d %d %d %d")
    _check(read_scan(tmp_path / "c.pts"), xyz, rgb, tol=2e-6)


# --------------------------------------------------------------------------- PCD, LAS, E57


def test_pcd_written_by_open3d(tmp_path):
    import open3d as o3d

    xyz, rgb = _cloud(400)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    pcd.colors = o3d.utility.Vector3dVector(rgb / 255.0)
    assert o3d.io.write_point_cloud(str(tmp_path / "a.pcd"), pcd, write_ascii=False)
    _check(read_scan(tmp_path / "a.pcd"), xyz, rgb, tol=1e-5)


def _write_las(path: Path, xyz: np.ndarray, rgb16: np.ndarray, point_format: int = 3) -> None:
    import laspy

    las = laspy.create(point_format=point_format, file_version="1.2")
    las.header.offsets = np.floor(xyz.min(axis=0))
    las.header.scales = [0.0001, 0.0001, 0.0001]
    las.x, las.y, las.z = xyz.T
    if point_format in (2, 3):
        las.red, las.green, las.blue = rgb16.T
    las.write(path)


def test_las_16_bit_colour_and_laz(tmp_path):
    xyz, rgb = _cloud(250, offset=0.0)
    xyz = xyz + np.array([638_000.0, 851_000.0, 400.0])
    _write_las(tmp_path / "a.las", xyz, rgb.astype(np.uint16) * 257)
    _check(read_scan(tmp_path / "a.las"), xyz, rgb, tol=1e-4)
    _write_las(tmp_path / "a.laz", xyz, rgb.astype(np.uint16) * 257)
    _check(read_scan(tmp_path / "a.laz"), xyz, rgb, tol=1e-4)


def _e57_scan(xyz, rgb, invalid=None) -> dict:
    d = {"cartesianX": xyz[:, 0].copy(), "cartesianY": xyz[:, 1].copy(), "cartesianZ": xyz[:, 2].copy(),
         "colorRed": rgb[:, 0].copy(), "colorGreen": rgb[:, 1].copy(), "colorBlue": rgb[:, 2].copy()}
    if invalid is not None:
        d["cartesianInvalidState"] = invalid.astype(np.int8)
    return d


def test_e57_two_scans_with_poses_and_invalid_points(tmp_path):
    import pye57
    from scipy.spatial.transform import Rotation

    a_xyz, a_rgb = _cloud(300)
    b_xyz, b_rgb = _cloud(200)
    invalid = np.zeros(len(b_xyz), np.int8)
    invalid[::10] = 2  # every tenth point of scan b flagged invalid
    rot = Rotation.from_euler("z", 90, degrees=True)
    q_xyzw = rot.as_quat()
    t = np.array([10.0, -3.0, 1.5])
    with pye57.E57(str(tmp_path / "two.e57"), mode="w") as e:
        e.write_scan_raw(_e57_scan(a_xyz, a_rgb))  # identity pose
        e.write_scan_raw(_e57_scan(b_xyz, b_rgb, invalid),
                         rotation=np.array([q_xyzw[3], *q_xyzw[:3]]), translation=t)
    cloud = read_scan(tmp_path / "two.e57")
    keep = invalid == 0
    expected_xyz = np.vstack([a_xyz, rot.apply(b_xyz[keep]) + t])
    expected_rgb = np.vstack([a_rgb, b_rgb[keep]])
    _check(cloud, expected_xyz, expected_rgb, tol=1e-4)
    assert len(cloud) == 300 + 180


def test_read_scans_merges_with_one_origin(tmp_path):
    a, ca = _cloud(100, offset=100.0)
    b, cb = _cloud(50, offset=-40.0)
    write_ply(tmp_path / "a.ply", a, ca, double=True)
    np.savetxt(tmp_path / "b.xyz", np.column_stack([b, cb]), fmt="%.6f %.6f %.6f %d %d %d")
    cloud = read_scans([tmp_path / "a.ply", tmp_path / "b.xyz"])
    _check(cloud, np.vstack([a, b]), np.vstack([ca, cb]), tol=2e-5)
    np.testing.assert_array_equal(cloud.origin, read_scan(tmp_path / "a.ply").origin)
    assert cloud.sources == (str(tmp_path / "a.ply"), str(tmp_path / "b.xyz"))


def test_colours_16_to_8_detects_range():
    np.testing.assert_array_equal(colours_16_to_8(np.array([[0, 128, 255]], np.uint16)), [[0, 128, 255]])
    np.testing.assert_array_equal(colours_16_to_8(np.array([[0, 257 * 128, 65535]], np.uint16)), [[0, 128, 255]])


# --------------------------------------------------------------------------- refusals


def _expect_error(path: Path, fragment: str) -> None:
    with pytest.raises(InputError) as info:
        read_scan(path)
    msg = str(info.value)
    assert str(path) in msg and fragment in msg, msg
    assert "\n" not in msg


@pytest.mark.parametrize("ext", [".ply", ".e57", ".las", ".laz", ".pcd", ".xyz", ".pts", ".txt"])
def test_empty_and_garbage_files_refused(tmp_path, ext):
    (tmp_path / f"empty{ext}").write_bytes(b"")
    _expect_error(tmp_path / f"empty{ext}", "empty file")
    garbage = tmp_path / f"garbage{ext}"
    garbage.write_bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    with pytest.raises(InputError) as info:
        read_scan(garbage)
    assert str(garbage) in str(info.value)


def test_no_colour_refused(tmp_path):
    xyz, _ = _cloud(50)
    rec = np.zeros(len(xyz), [("x", "f4"), ("y", "f4"), ("z", "f4")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    _write_ply_struct(tmp_path / "nc.ply", rec, "binary_little_endian")
    _expect_error(tmp_path / "nc.ply", "no colour")
    np.savetxt(tmp_path / "nc.xyz", xyz)
    _expect_error(tmp_path / "nc.xyz", "no colour")
    _write_las(tmp_path / "nc.las", xyz + 100, None, point_format=1)
    _expect_error(tmp_path / "nc.las", "no colour")
    import open3d as o3d

    o3d.io.write_point_cloud(str(tmp_path / "nc.pcd"), o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz)))
    _expect_error(tmp_path / "nc.pcd", "no colour")


def test_non_finite_coordinates_refused(tmp_path):
    xyz, rgb = _cloud(50)
    xyz[17, 1] = np.nan
    write_ply(tmp_path / "nan.ply", xyz, rgb)
    _expect_error(tmp_path / "nan.ply", "non-finite coordinates (point 17)")
    rows = np.column_stack([xyz, rgb])
    rows[17, 1] = np.inf
    np.savetxt(tmp_path / "inf.xyz", rows)
    _expect_error(tmp_path / "inf.xyz", "non-finite")


def test_truncated_and_malformed_refused(tmp_path):
    xyz, rgb = _cloud(100)
    write_ply(tmp_path / "t.ply", xyz, rgb)
    data = (tmp_path / "t.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-7])
    _expect_error(tmp_path / "t.ply", "truncated")
    (tmp_path / "h.ply").write_bytes(data[:60])  # header cut short
    _expect_error(tmp_path / "h.ply", "end_header")
    with open(tmp_path / "short.pts", "w") as fh:
        fh.write("10\n1 2 3 0 10 20 30\n")
    _expect_error(tmp_path / "short.pts", "truncated")
    (tmp_path / "words.xyz").write_text("1 2 3 4 5 6\n1 2 three 4 5 6\n")
    _expect_error(tmp_path / "words.xyz", "bad numbers")
    (tmp_path / "zero.ply").write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
        b"property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    _expect_error(tmp_path / "zero.ply", "no points")
    (tmp_path / "comments.xyz").write_text("# nothing here\n\n")
    _expect_error(tmp_path / "comments.xyz", "no points")


def test_unknown_extension_and_missing_file(tmp_path):
    (tmp_path / "a.obj").write_text("v 0 0 0\n")
    _expect_error(tmp_path / "a.obj", "unknown scan format '.obj'")
    _expect_error(tmp_path / "missing.ply", "no such file")
    with pytest.raises(InputError, match="no scan files"):
        read_scans([])


def test_e57_without_colour_and_truncated_las_refused(tmp_path, real):
    import pye57

    REAL = real
    xyz, rgb = _cloud(50)
    with pye57.E57(str(tmp_path / "nc.e57"), mode="w") as e:
        e.write_scan_raw({k: v for k, v in _e57_scan(xyz, rgb).items() if not k.startswith("color")})
    _expect_error(tmp_path / "nc.e57", "no colour (scan 0")
    data = (REAL / "simple.las").read_bytes()
    (tmp_path / "cut.las").write_bytes(data[: len(data) // 2])
    _expect_error(tmp_path / "cut.las", "cannot read LAS file")


def _write_e57_spherical(path: Path, rae: np.ndarray, rgb16: np.ndarray, translation: np.ndarray) -> None:
    """A one-scan E57 in spherical coordinates with 16-bit colours (libE57 nodes directly)."""
    import pye57
    from pye57 import libe57

    with pye57.E57(str(path), mode="w") as e:
        imf = e.image_file
        scan = libe57.StructureNode(imf)
        scan.set("guid", libe57.StringNode(imf, "{spherical-test}"))
        limits = libe57.StructureNode(imf)
        for ch in ("Red", "Green", "Blue"):
            limits.set(f"color{ch}Minimum", libe57.IntegerNode(imf, 0))
            limits.set(f"color{ch}Maximum", libe57.IntegerNode(imf, 65535))
        scan.set("colorLimits", limits)
        pose = libe57.StructureNode(imf)
        rot = libe57.StructureNode(imf)
        for k, v in zip("wxyz", (1.0, 0.0, 0.0, 0.0), strict=True):
            rot.set(k, libe57.FloatNode(imf, v))
        tr = libe57.StructureNode(imf)
        for k, v in zip("xyz", translation, strict=True):
            tr.set(k, libe57.FloatNode(imf, float(v)))
        pose.set("rotation", rot)
        pose.set("translation", tr)
        scan.set("pose", pose)
        proto = libe57.StructureNode(imf)
        names = ["sphericalRange", "sphericalAzimuth", "sphericalElevation"]
        for name in names:
            proto.set(name, libe57.FloatNode(imf, 0.0, libe57.E57_DOUBLE, -1e9, 1e9))
        for ch in ("Red", "Green", "Blue"):
            proto.set(f"color{ch}", libe57.IntegerNode(imf, 0, 0, 65535))
        points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
        scan.set("points", points)
        e.data3d.append(scan)
        n = len(rae)
        arrays = [np.ascontiguousarray(rae[:, j]) for j in range(3)]
        arrays += [np.ascontiguousarray(rgb16[:, j]) for j in range(3)]
        buffers = libe57.VectorSourceDestBuffer()
        for name, arr in zip(names + ["colorRed", "colorGreen", "colorBlue"], arrays, strict=True):
            buffers.append(libe57.SourceDestBuffer(imf, name, arr, n, True, True))
        writer = points.writer(buffers)
        writer.write(n)
        writer.close()


def test_e57_spherical_with_16_bit_colour_limits(tmp_path):
    n = 200
    rae = np.column_stack([RNG.uniform(1, 10, n), RNG.uniform(-np.pi, np.pi, n), RNG.uniform(-1.2, 1.2, n)])
    rgb = RNG.integers(0, 256, (n, 3), dtype=np.uint8)
    t = np.array([5.0, 6.0, 1.0])
    _write_e57_spherical(tmp_path / "sph.e57", rae, rgb.astype(np.uint16) * 257, t)
    r, az, el = rae.T
    expected = np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]) + t
    _check(read_scan(tmp_path / "sph.e57"), expected, rgb, tol=1e-5)
