"""Streaming scan readers: per format, the chunks put together are the whole file; reading
keeps a few bytes per point of the chunk in flight; ranges of binary files."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.io import scan_e57, scan_las, scan_pcd, scan_ply, scan_source, scan_text, scans
from sbsc_core.io.ply import write_ply
from sbsc_core.io.scans import iter_scan, open_scan, read_scan, scan_point_count, scan_readers

RNG = np.random.default_rng(11)
N = 5_000


def _cloud(n: int = N, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    return RNG.uniform(-5, 5, (n, 3)) + offset, RNG.integers(0, 256, (n, 3), dtype=np.uint8)


def _write(path: Path, xyz: np.ndarray, rgb: np.ndarray) -> None:
    ext = path.suffix
    if ext == ".ply":
        write_ply(path, xyz, rgb, double=True)
    elif ext == ".xyz":
        np.savetxt(path, np.column_stack([xyz, rgb]), fmt="%.6f %.6f %.6f %d %d %d")
    elif ext == ".pts":
        with open(path, "w") as fh:
            fh.write(f"{len(xyz)}\n")
            np.savetxt(fh, np.column_stack([xyz, np.zeros(len(xyz)), rgb]), fmt="%.6f %.6f %.6f %d %d %d %d")
    elif ext in (".las", ".laz"):
        import laspy

        las = laspy.create(point_format=3, file_version="1.2")
        las.header.offsets = np.floor(xyz.min(axis=0))
        las.header.scales = [1e-5] * 3
        las.x, las.y, las.z = xyz.T
        las.red, las.green, las.blue = (rgb.astype(np.uint16) * 257).T
        las.write(path)
    elif ext == ".e57":
        import pye57

        with pye57.E57(str(path), mode="w") as e:
            half = len(xyz) // 2
            for a, b in ((0, half), (half, len(xyz))):
                e.write_scan_raw({"cartesianX": xyz[a:b, 0].copy(), "cartesianY": xyz[a:b, 1].copy(),
                                  "cartesianZ": xyz[a:b, 2].copy(), "colorRed": rgb[a:b, 0].copy(),
                                  "colorGreen": rgb[a:b, 1].copy(), "colorBlue": rgb[a:b, 2].copy()})
    elif ext == ".pcd":
        _write_pcd(path, xyz, rgb, ascii_=path.stem.endswith("ascii"))


def _write_pcd(path: Path, xyz: np.ndarray, rgb: np.ndarray, ascii_: bool) -> None:
    """PCL's layout: x y z float32 and the colour packed in a float field, plus an extra field."""
    n = len(xyz)
    packed = (rgb[:, 0].astype(np.uint32) << 16) | (rgb[:, 1].astype(np.uint32) << 8) | rgb[:, 2]
    rec = np.empty(n, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<f4"), ("normal", "<f4", (3,))])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["rgb"] = packed.view(np.float32)
    rec["normal"] = 0.0
    head = (f"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb normal\nSIZE 4 4 4 4 4\nTYPE F F F F F\nCOUNT 1 1 1 1 3\n"
            f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {'ascii' if ascii_ else 'binary'}\n")
    with open(path, "wb") as fh:
        fh.write(head.encode())
        if ascii_:
            for r in range(n):
                fh.write(f"{float(rec['x'][r])!r} {float(rec['y'][r])!r} {float(rec['z'][r])!r} {int(packed[r])} 0 0 0\n".encode())
        else:
            rec.tofile(fh)


def _blocks_of_at_most(monkeypatch, n: int) -> None:
    """Every reader converts at most ``n`` points at once (``BLOCK_POINTS`` of each module)."""
    for mod in (scan_source, scan_ply, scan_text, scan_las, scan_e57, scan_pcd):
        monkeypatch.setattr(mod, "BLOCK_POINTS", n)


FORMATS = ["a.ply", "a.xyz", "a.pts", "a.las", "a.laz", "a.e57", "a.pcd", "a_ascii.pcd"]


@pytest.mark.parametrize("name", FORMATS)
def test_chunks_put_together_are_the_whole_file(tmp_path, monkeypatch, name):
    xyz, rgb = _cloud(offset=1000.0)
    path = tmp_path / name
    _write(path, xyz, rgb)
    _blocks_of_at_most(monkeypatch, 700)  # many blocks, not aligned with the chunks
    chunks = list(iter_scan(path, chunk_points=1_000))
    assert len(chunks) == 5
    assert [c.start for c in chunks] == list(range(0, N, 1_000))
    assert all(c.xyz.dtype == np.float32 and c.rgb.dtype == np.uint8 for c in chunks)
    assert all(np.array_equal(c.origin, chunks[0].origin) for c in chunks)
    whole = read_scan(path)
    np.testing.assert_array_equal(np.concatenate([c.xyz for c in chunks]), whole.xyz)
    np.testing.assert_array_equal(np.concatenate([c.rgb for c in chunks]), whole.rgb)
    np.testing.assert_allclose(whole.world(), xyz, atol=2e-4)
    np.testing.assert_array_equal(whole.rgb, rgb)
    text = name.endswith((".xyz", ".pts"))
    assert scan_point_count(path) == (None if text else N)


def test_every_format_has_a_registered_reader():
    # contract 1's formats, in the order every list of them shows (CLI help, upload page)
    assert scans.scan_extensions() == (".ply", ".e57", ".las", ".laz", ".pcd", ".xyz", ".pts", ".txt")
    assert tuple(scan_readers()) == scans.scan_extensions()


def test_ranges_of_a_mapped_file_and_errors_name_the_point(tmp_path):
    xyz, rgb = _cloud()
    write_ply(tmp_path / "a.ply", xyz, rgb)
    src = open_scan(tmp_path / "a.ply")
    assert src.seekable and src.count == N
    whole = read_scan(tmp_path / "a.ply")
    parts = [list(iter_scan(src, whole.origin, start=a, stop=b)) for a, b in ((0, 1234), (1234, 4000), (4000, None))]
    got = np.concatenate([c.xyz for p in parts for c in p])
    np.testing.assert_array_equal(got, whole.xyz)
    assert parts[1][0].start == 1234
    xyz[3000, 2] = np.inf
    write_ply(tmp_path / "b.ply", xyz, rgb)
    with pytest.raises(InputError, match=r"non-finite coordinates \(point 3000\)"):
        list(iter_scan(tmp_path / "b.ply", start=2000, stop=4000))
    write_ply(tmp_path / "c.xyz.ply", xyz[:10], rgb[:10])
    (tmp_path / "t.xyz").write_text("1 2 3 4 5 6\n")
    with pytest.raises(ValueError, match="fixed-size records"):
        list(iter_scan(tmp_path / "t.xyz", start=1))


def test_first_block_decides_16_bit_colours(tmp_path):
    xyz, rgb = _cloud(300)
    wide = rgb.astype(np.uint16) * 257
    _write(tmp_path / "w.las", xyz, rgb)  # written with * 257: the full 16-bit range
    np.testing.assert_array_equal(read_scan(tmp_path / "w.las").rgb, rgb)
    assert int(wide.max()) > 255


@pytest.mark.slow
@pytest.mark.parametrize("name", ["a.ply", "a.las", "a.e57", "a.pcd", "a.xyz"])
def test_reading_costs_at_most_20_bytes_a_point_beyond_the_chunk(tmp_path, monkeypatch, name):
    """Memory allocated while a chunk is read, beyond the chunk itself (15 bytes a point)."""
    n = 400_000
    xyz, rgb = _cloud(n, offset=500_000.0)
    path = tmp_path / name
    _write(path, xyz, rgb)
    chunk = 200_000
    _blocks_of_at_most(monkeypatch, 1 << 14)
    it = iter_scan(path, chunk_points=chunk)
    first = next(it)  # libraries imported, files opened
    del first
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        c = next(it)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    it.close()
    own = c.xyz.nbytes + c.rgb.nbytes
    assert len(c) == chunk
    assert peak - own <= 20 * chunk, f"{(peak - own) / chunk:.1f} bytes a point beyond the chunk"


def test_sample_of_a_binary_file_converts_every_kth_point(tmp_path, monkeypatch):
    from sbsc_core.io.scans import sample_scan

    xyz, rgb = _cloud()
    write_ply(tmp_path / "a.ply", xyz, rgb)
    _blocks_of_at_most(monkeypatch, 333)
    whole = read_scan(tmp_path / "a.ply")
    got_xyz, got_rgb, n = sample_scan(open_scan(tmp_path / "a.ply"), whole.origin, 7, first=3, start=100, stop=4000)
    pick = np.flatnonzero((3 + np.arange(3900)) % 7 == 0) + 100
    assert n == 3900
    np.testing.assert_array_equal(got_xyz, whole.xyz[pick])
    np.testing.assert_array_equal(got_rgb, whole.rgb[pick])
