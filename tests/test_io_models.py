"""Model library loading (contract 2) and safe unpacking of zipped libraries."""

from __future__ import annotations

import json
import stat
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.io import models as models_mod
from sbsc_core.io.models import library_from_zip, load_model_library


def _write_class(root: Path, class_id: str, meta: dict | None = None, *, depth: np.ndarray | None = None,
                 views: dict[str, np.ndarray] | None = None) -> Path:
    d = root / class_id
    d.mkdir(parents=True, exist_ok=True)
    meta = meta if meta is not None else {"name": class_id, "ifc_class": "IfcOutlet",
                                           "predefined_type": "POWEROUTLET", "width_m": 0.08, "height_m": 0.08}
    (d / "model.json").write_text(json.dumps(meta))
    if views is None:
        bgr = np.zeros((16, 16, 3), np.uint8)
        bgr[..., 2] = 255  # pure red, written in OpenCV's BGR order
        views = {"colour.png": bgr}
    for name, img in views.items():
        assert cv2.imwrite(str(d / name), img)
    if depth is not None:
        np.save(d / "depth.npy", depth)
    return d


@pytest.fixture
def library(tmp_path) -> Path:
    root = tmp_path / "models"
    _write_class(root, "socket_x1", depth=np.full((16, 16), 0.012))
    bgra = np.zeros((30, 10, 4), np.uint8)
    bgra[..., 0] = 200  # blue
    bgra[:, :5, 3] = 255  # left half opaque, right half background
    sign = {"name": "Extinguisher sign", "ifc_class": "IfcSign", "width_m": 0.1, "height_m": 0.3,
            "object_type": "EXTINGUISHERSIGN"}
    _write_class(root, "extinguisher_sign", sign, views={"colour.png": bgra, "colour_2.png": bgra[:, ::-1],
                                                         "colour_1.png": bgra[::-1]})
    (root / "README.txt").write_text("not a class")
    (root / ".hidden").mkdir()
    return root


def test_load_library(library):
    lib = load_model_library(library)
    assert lib.class_ids == ["extinguisher_sign", "socket_x1"]
    s = lib["socket_x1"]
    assert (s.name, s.ifc_class, s.predefined_type, s.width_m, s.height_m) == ("socket_x1", "IfcOutlet", "POWEROUTLET", 0.08, 0.08)
    assert len(s.colour_views) == 1 and s.colour_views[0].shape == (16, 16, 4)
    np.testing.assert_array_equal(s.colour_views[0][0, 0], [255, 0, 0, 255])  # RGB order, opaque alpha
    assert s.depth.dtype == np.float32 and s.depth.shape == (16, 16)
    e = lib["extinguisher_sign"]
    assert e.predefined_type is None and e.depth is None
    assert e.extra == {"object_type": "EXTINGUISHERSIGN"}
    assert len(e.colour_views) == 3
    np.testing.assert_array_equal(e.colour_views[0][0, 0], [0, 0, 200, 255])
    assert e.colour_views[0][0, 9, 3] == 0  # background alpha kept
    assert e.colour_views[2][0, 0, 3] == 0  # colour_2.png (mirrored) comes last
    assert "socket_x1" in lib and lib.root == str(library)


def _error(root: Path) -> str:
    with pytest.raises(InputError) as info:
        load_model_library(root)
    msg = str(info.value)
    assert "\n" not in msg
    return msg


def test_error_names_class_and_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _write_class(Path("models"), "socket_x1", {"name": "S", "ifc_class": "IfcOutlet", "height_m": 0.08})
    assert _error(Path("models")) == "models/socket_x1/model.json: missing key 'width_m'"


@pytest.mark.parametrize("meta, fragment", [
    ({"name": "S", "ifc_class": "IfcOutlet", "width_m": -0.1, "height_m": 0.08}, "'width_m' must be a number > 0"),
    ({"name": "S", "ifc_class": "IfcOutlet", "width_m": "8cm", "height_m": 0.08}, "'width_m' must be a number > 0"),
    ({"name": "", "ifc_class": "IfcOutlet", "width_m": 0.1, "height_m": 0.08}, "'name' must be a non-empty string"),
    ({"name": "S", "ifc_class": "Outlet", "width_m": 0.1, "height_m": 0.08}, "'ifc_class' must be an IFC entity"),
    ({"name": "S", "ifc_class": "IfcOutlet", "predefined_type": 3, "width_m": 0.1, "height_m": 0.08}, "predefined_type"),
    ({"name": "S", "ifc_class": "IfcOutlet", "width_m": 0.1, "height_m": 0.08, "order": "1"}, "'order' must be a number"),
    ([1, 2], "expected a JSON object"),
])
def test_bad_model_json(tmp_path, meta, fragment):
    _write_class(tmp_path / "m", "socket_x1", meta)
    msg = _error(tmp_path / "m")
    assert msg.startswith(str(tmp_path / "m" / "socket_x1" / "model.json")) and fragment in msg, msg


def test_library_order_and_metadata(tmp_path):
    """``order`` in model.json places a class; the others follow by id; metadata without the views."""
    meta = {"name": "S", "ifc_class": "IfcOutlet", "width_m": 0.1, "height_m": 0.08}
    for cid, order in (("b", 2), ("a", None), ("c", 1), ("d", None), ("e", 1.5)):
        _write_class(tmp_path / "m", cid, {**meta, **({"order": order} if order is not None else {})})
    expected = ["c", "e", "b", "a", "d"]
    assert list(models_mod.read_library_metadata(tmp_path / "m")) == expected
    assert models_mod.ordered_class_ids(load_model_library(tmp_path / "m")) == expected
    assert models_mod.read_library_metadata(tmp_path / "m")["b"] == {**meta, "order": 2, "mount": ("wall", "ceiling", "column")}
    (tmp_path / "m" / "a" / "colour.png").unlink()  # views are not read
    assert list(models_mod.read_library_metadata(tmp_path / "m")) == expected
    from sbsc_core.paths import bundled_models_dir

    bundled = list(models_mod.read_library_metadata(bundled_models_dir()))
    assert bundled[:3] == ["electrical_panel", "socket_x1", "socket_x2"] and len(bundled) == 13  # the paper's order


def test_library_structure_errors(tmp_path):
    assert "no such directory" in _error(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    assert "no class directories" in _error(tmp_path / "empty")
    _write_class(tmp_path / "badname", "Socket-X1")
    assert "Socket-X1: class directory name" in _error(tmp_path / "badname")
    d = _write_class(tmp_path / "nojson", "switch")
    (d / "model.json").unlink()
    assert _error(tmp_path / "nojson").endswith("switch/model.json: missing")
    d = _write_class(tmp_path / "badjson", "switch")
    (d / "model.json").write_text('{"name": "S",')
    assert "model.json: invalid JSON (line 1" in _error(tmp_path / "badjson")
    _write_class(tmp_path / "noview", "switch", views={})
    assert "switch: no front view" in _error(tmp_path / "noview")


def test_bad_images_and_depth(tmp_path):
    d = _write_class(tmp_path / "a", "switch")
    (d / "colour_1.png").write_bytes(b"\x89PNG garbage")
    assert "switch/colour_1.png: not a readable PNG image" in _error(tmp_path / "a")
    _write_class(tmp_path / "b", "switch", views={"colour.png": np.zeros((8, 8), np.uint8)})
    assert "expected an RGB or RGBA image, got 1 channel" in _error(tmp_path / "b")
    cases = [
        (np.zeros((4, 4, 2), np.float32), "expected a non-empty 2-D array"),
        (np.zeros((10, 10), np.int32), "expected a float array"),
        (np.array([[0.0, np.inf]] * 2), "infinite values"),
        (np.zeros((10, 20), np.float32), "does not match the footprint"),
    ]
    for i, (depth, fragment) in enumerate(cases):
        _write_class(tmp_path / f"d{i}", "switch", depth=depth)
        msg = _error(tmp_path / f"d{i}")
        assert "switch/depth.npy" in msg and fragment in msg, msg
    # NaN (unknown) is fine, and a one-pixel aspect mismatch is tolerated
    depth = np.full((10, 11), np.nan)
    _write_class(tmp_path / "ok", "switch", depth=depth)
    assert np.isnan(load_model_library(tmp_path / "ok")["switch"].depth).all()
    (tmp_path / "ok" / "switch" / "depth.npy").write_bytes(b"not numpy")
    assert "not a readable .npy array" in _error(tmp_path / "ok")


# --------------------------------------------------------------------------- zip


def _zip_dir(src: Path, zip_path: Path, prefix: str = "") -> None:
    with zipfile.ZipFile(zip_path, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(src.rglob("*")):
            if p.is_file() and not p.name.startswith("."):
                zf.write(p, prefix + p.relative_to(src).as_posix())


@pytest.mark.parametrize("prefix", ["", "my_library/"])
def test_zip_roundtrip(library, tmp_path, prefix):
    _zip_dir(library, tmp_path / "lib.zip", prefix)
    root = library_from_zip(tmp_path / "lib.zip", tmp_path / "out")
    assert root == (tmp_path / "out" / prefix.rstrip("/") if prefix else tmp_path / "out")
    assert load_model_library(root).class_ids == ["extinguisher_sign", "socket_x1"]


def _zip_error(zip_path: Path, dest: Path) -> str:
    with pytest.raises(InputError) as info:
        library_from_zip(zip_path, dest)
    assert not dest.exists(), "nothing may be left behind"
    assert not list(dest.parent.glob(f".{dest.name}.partial-*"))
    return str(info.value)


def test_zip_refuses_unsafe_entries(tmp_path):
    good = (tmp_path / "m.json")
    good.write_text("{}")
    for i, name in enumerate(["../evil.txt", "/etc/evil.txt", "a/../../evil.txt", "C:/evil.txt", "a\\evil.txt"]):
        z = tmp_path / f"bad{i}.zip"
        with zipfile.ZipFile(z, "w") as zf:
            zf.writestr(name, "x")
        msg = _zip_error(z, tmp_path / f"out{i}")
        assert msg.startswith(f"bad{i}.zip: {name}: "), msg
    assert not (tmp_path / "evil.txt").exists()
    z = tmp_path / "link.zip"
    with zipfile.ZipFile(z, "w") as zf:
        info = zipfile.ZipInfo("socket_x1/colour.png")
        info.external_attr = (stat.S_IFLNK | 0o777) << 16
        zf.writestr(info, "/etc/passwd")
    assert "socket_x1/colour.png: symbolic links are not allowed" in _zip_error(z, tmp_path / "outl")


def test_zip_size_and_count_caps(library, tmp_path, monkeypatch):
    _zip_dir(library, tmp_path / "lib.zip")
    monkeypatch.setattr(models_mod, "ZIP_MAX_ENTRIES", 3)
    assert "too many entries" in _zip_error(tmp_path / "lib.zip", tmp_path / "o1")
    monkeypatch.setattr(models_mod, "ZIP_MAX_ENTRIES", 2000)
    monkeypatch.setattr(models_mod, "ZIP_MAX_ENTRY_BYTES", 100)
    assert "entry too large" in _zip_error(tmp_path / "lib.zip", tmp_path / "o2")
    monkeypatch.setattr(models_mod, "ZIP_MAX_ENTRY_BYTES", 1 << 20)
    monkeypatch.setattr(models_mod, "ZIP_MAX_TOTAL_BYTES", 600)
    assert "unpacks to more than 600 bytes" in _zip_error(tmp_path / "lib.zip", tmp_path / "o3")


def test_zip_with_bad_library_or_not_a_zip(tmp_path):
    _write_class(tmp_path / "src", "socket_x1", {"name": "S", "ifc_class": "IfcOutlet", "height_m": 0.08})
    _zip_dir(tmp_path / "src", tmp_path / "lib.zip")
    assert _zip_error(tmp_path / "lib.zip", tmp_path / "o") == "lib.zip: socket_x1/model.json: missing key 'width_m'"
    (tmp_path / "fake.zip").write_bytes(b"PK not really")
    assert _zip_error(tmp_path / "fake.zip", tmp_path / "o") == "fake.zip: not a zip file"
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "x").write_text("x")
    with pytest.raises(InputError, match="destination is not empty"):
        library_from_zip(tmp_path / "lib.zip", tmp_path / "busy")


def test_further_depth_models_are_loaded_in_order(tmp_path) -> None:
    root = tmp_path / "models"
    d = _write_class(root, "socket_x1", depth=np.full((16, 16), 0.012))
    np.save(d / "depth_101.npy", np.full((16, 16), 0.010, np.float32))
    np.save(d / "depth_2.npy", np.full((16, 16), 0.008, np.float32))
    np.save(d / "depth_exemplar_1.npy", np.full((16, 16), 0.007, np.float32))  # the old exemplar name
    m = load_model_library(root).models["socket_x1"]
    assert float(m.depth[0, 0]) == pytest.approx(0.012)
    assert [float(x[0, 0]) for x in m.extra_depths] == pytest.approx([0.007, 0.008, 0.010])


def test_a_library_without_further_depth_models_reads_as_before(library) -> None:
    lib = load_model_library(library)
    assert all(m.extra_depths == [] for m in lib.models.values())


def test_further_depth_model_only_becomes_the_reference(tmp_path) -> None:
    d = _write_class(tmp_path / "models", "socket_x1")
    np.save(d / "depth_1.npy", np.full((16, 16), 0.01, np.float32))
    m = load_model_library(tmp_path / "models").models["socket_x1"]
    assert m.depth is not None and m.extra_depths == []


def test_bad_further_depth_model_names_the_file(tmp_path) -> None:
    d = _write_class(tmp_path / "models", "socket_x1", depth=np.full((16, 16), 0.012))
    np.save(d / "depth_1.npy", np.full((16, 40), 0.01, np.float32))
    with pytest.raises(InputError, match=r"depth_1\.npy.*does not match the footprint"):
        load_model_library(tmp_path / "models")
