"""A corpus of hostile inputs for every command (no tests here; see test_hostile_cli.py).

Each case is written by :func:`build_corpus` into a fresh directory (nothing big is
committed) and is a command line that must fail with exit 2 and one line on stderr,
leave no output behind and print no traceback.
"""

from __future__ import annotations

import copy
import json
import shutil
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sbsc_core.paths import bundled_models_dir

from .bim_fixtures import detections_document, truth_document


@dataclass
class Case:
    name: str
    argv: list[str]  # the command line (after ``sbsc``)
    out: Path  # must not exist afterwards


def _ply_header(n: int, fmt: str = "ascii", props: str = "float x\nproperty float y\nproperty float z\n"
                "property uchar red\nproperty uchar green\nproperty uchar blue") -> bytes:
    return (f"ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty {props}\nend_header\n").encode()


def _points(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 4, (n, 3))


def _ascii_rows(xyz: np.ndarray, rgb: bool = True) -> bytes:
    if rgb:
        return "".join(f"{x:.6g} {y:.6g} {z:.6g} 120 130 140\n" for x, y, z in xyz).encode()
    return "".join(f"{x:.6g} {y:.6g} {z:.6g}\n" for x, y, z in xyz).encode()


def _binary_rows(xyz: np.ndarray) -> bytes:
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    arr = np.zeros(len(xyz), dt)
    arr["x"], arr["y"], arr["z"] = xyz.T
    arr["r"] = 100
    return arr.tobytes()


def scan_files() -> dict[str, bytes]:
    """Hostile scan files by name (contract 1 formats)."""
    p = _points(1000)
    far = p.copy()
    far[7] = [1e30, -1e30, 1e30]  # one stray point very far away
    huge = p * 1e38
    files: dict[str, bytes] = {}
    for ext in (".ply", ".e57", ".las", ".laz", ".pcd", ".xyz", ".pts", ".txt"):
        files[f"empty{ext}"] = b""
        files[f"random{ext}"] = np.random.default_rng(3).bytes(4096)
        files[f"nul{ext}"] = b"\x00" * 2048
    files.update({
        "ply_says_10_has_1000.ply": _ply_header(10, "binary_little_endian") + _binary_rows(p),
        "ply_says_1000_has_10.ply": _ply_header(1000, "binary_little_endian") + _binary_rows(p[:10]),
        "ply_ascii_says_1000_has_10.ply": _ply_header(1000) + _ascii_rows(p[:10]),
        "ply_count_2e18.ply": _ply_header(2 * 10 ** 18, "binary_little_endian") + _binary_rows(p),
        "ply_count_negative.ply": _ply_header(-5) + _ascii_rows(p[:5]),
        "ply_count_word.ply": b"ply\nformat ascii 1.0\nelement vertex many\nproperty float x\nend_header\n",
        "ply_no_colour.ply": _ply_header(1000, props="float x\nproperty float y\nproperty float z")
        + _ascii_rows(p, rgb=False),
        "ply_nan.ply": _ply_header(3) + b"nan 0 0 1 2 3\n0 0 0 1 2 3\n1 1 1 1 2 3\n",
        "ply_inf.ply": _ply_header(3) + b"inf 0 0 1 2 3\n0 0 0 1 2 3\n1 1 1 1 2 3\n",
        "ply_1e38.ply": _ply_header(1000) + _ascii_rows(huge),
        "ply_far_outlier.ply": _ply_header(1000, "binary_little_endian") + _binary_rows(far),
        "ply_one_point.ply": _ply_header(1) + b"1 2 3 4 5 6\n",
        "ply_all_same.ply": _ply_header(1000) + b"1 1 1 9 9 9\n" * 1000,
        "ply_no_end_header.ply": b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n" + b"1\n" * 3,
        "ply_bad_format.ply": _ply_header(3, "binary_middle_endian") + b"\x00" * 45,
        "ply_bad_type.ply": _ply_header(3, props="float128 x\nproperty float y\nproperty float z")
        + b"1 2 3\n" * 3,
        "ply_list_vertex.ply": _ply_header(2, props="list uchar int x\nproperty float y\nproperty float z")
        + b"2 1 1 0 0\n2 1 1 0 0\n",
        "ply_latin1_header.ply": "ply\nformat ascii 1.0\ncomment é\xff\n".encode("latin-1") + b"end_header\n",
        "ply_words.ply": _ply_header(3) + b"a b c d e f\n" * 3,
        "ply_rgb_300.ply": _ply_header(3) + b"0 0 0 300 -4 9999\n" * 3,
        "ply_huge_header.ply": b"ply\nformat ascii 1.0\n" + b"comment " + b"x" * 2_000_000 + b"\nend_header\n",
        "xyz_three_columns.xyz": _ascii_rows(p, rgb=False),
        "xyz_words.xyz": b"x y z r g b\n" * 100,
        "xyz_nan.xyz": b"nan nan nan 1 2 3\n" * 100,
        "xyz_1e38.xyz": _ascii_rows(huge),
        "xyz_far_outlier.xyz": _ascii_rows(far),
        "xyz_1e400.xyz": b"1e400 0 0 1 2 3\n" * 10,
        "xyz_mixed_columns.xyz": b"1 2 3 4 5 6\n1 2 3\n1 2 3 4 5 6 7 8 9\n",
        "xyz_one_long_line.xyz": b"1 " * 500_000,
        "txt_binary_garbage.txt": bytes(range(256)) * 64,
        "pts_count_mismatch.pts": b"1000\n" + b"1 2 3 50 4 5 6\n" * 10,
        "pts_count_negative.pts": b"-3\n" + b"1 2 3 50 4 5 6\n" * 3,
        "pts_count_huge.pts": b"99999999999999999999\n" + b"1 2 3 50 4 5 6\n" * 3,
        "pts_no_count.pts": b"1 2 3 50 4 5 6\n" * 3,
        "las_truncated.las": b"LASF" + b"\x00" * 100,
        "las_claims_many.las": _las_claiming(10 ** 12),
        "e57_not_xml.e57": b"ASTM-E57" + b"\x00" * 2000,
        "pcd_bad_header.pcd": b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nPOINTS -1\nDATA ascii\n",
        "pcd_says_many.pcd": b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\n"
                             b"COUNT 1 1 1 1\nWIDTH 100000000\nHEIGHT 1\nPOINTS 100000000\nDATA binary\n"
                             + b"\x00" * 160,
    })
    return files


def _las_claiming(n: int) -> bytes:
    """A LAS 1.2 header (point format 2) that claims ``n`` points and holds none."""
    head = bytearray(227)
    head[0:4] = b"LASF"
    head[24], head[25] = 1, 2  # version 1.2
    struct.pack_into("<H", head, 94, 227)  # header size
    struct.pack_into("<I", head, 96, 227)  # offset to point data
    head[104] = 2  # point data format
    struct.pack_into("<H", head, 105, 26)  # record length
    struct.pack_into("<I", head, 107, min(n, 2 ** 32 - 1))
    struct.pack_into("<ddd", head, 131, 0.001, 0.001, 0.001)
    return bytes(head)


def _model_json(**over) -> dict:
    return {"name": "Thing", "ifc_class": "IfcOutlet", "predefined_type": "POWEROUTLET",
            "width_m": 0.08, "height_m": 0.08, **over}


def model_libraries() -> dict[str, Callable[[Path], None]]:
    """Hostile model libraries: name -> writer of the library into a directory."""
    src = bundled_models_dir() / "socket_x1"

    def lib(meta: dict | str | None = None, *, cls: str = "thing", colour: bytes | None = None,
            depth: np.ndarray | bytes | None = None, keep_colour: bool = True) -> Callable[[Path], None]:
        def write(root: Path) -> None:
            d = root / cls
            d.mkdir(parents=True)
            if meta is not None:
                (d / "model.json").write_text(meta if isinstance(meta, str) else json.dumps(meta))
            if colour is not None:
                (d / "colour.png").write_bytes(colour)
            elif keep_colour:
                shutil.copy(src / "colour.png", d / "colour.png")
            if isinstance(depth, bytes):
                (d / "depth.npy").write_bytes(depth)
            elif depth is not None:
                np.save(d / "depth.npy", depth, allow_pickle=True)
        return write

    deep = "[" * 100_000 + "]" * 100_000
    return {
        "model_json_missing": lib(None),
        "model_json_invalid": lib("{not json"),
        "model_json_deep": lib(deep),
        "model_json_deep_object": lib('{"name": ' + "{\"a\": " * 50_000 + "1" + "}" * 50_000 + "}"),
        "model_json_list": lib("[1, 2]"),
        "model_width_1e5": lib(_model_json(width_m=1e5, height_m=1e5)),
        "model_width_1e308": lib(_model_json(width_m=1e308)),
        "model_width_zero": lib(_model_json(width_m=0)),
        "model_width_negative": lib(_model_json(height_m=-1)),
        "model_width_string": lib(_model_json(width_m="wide")),
        "model_width_nan": lib(json.dumps(_model_json()).replace("0.08,", "NaN,", 1)),
        "model_width_tiny": lib(_model_json(width_m=1e-9, height_m=1e-9)),
        "model_name_nul": lib(_model_json(name="a\u0000b")),
        "model_bad_class_dir": lib(_model_json(), cls="Bad Name"),
        "model_colour_garbage": lib(_model_json(), colour=b"\x89PNG garbage"),
        "model_colour_missing": lib(_model_json(), keep_colour=False),
        "model_depth_garbage": lib(_model_json(), depth=b"\x93NUMPY garbage"),
        "model_depth_object": lib(_model_json(), depth=np.array([{"a": 1}], dtype=object)),
        "model_depth_3d": lib(_model_json(), depth=np.zeros((2, 3, 4), np.float32)),
        "model_depth_huge_header": lib(_model_json(), depth=b"\x93NUMPY\x01\x00\xff\xff" + b"{" * 70000),
    }


def expected_files() -> dict[str, str]:
    def doc(counts) -> str:  # noqa: ANN001
        return json.dumps({"schema": "sbsc.expected/1", "counts": counts})
    return {
        "expected_deep.json": "[" * 100_000 + "]" * 100_000,
        "expected_deep_counts.json": '{"schema": "sbsc.expected/1", "counts": '
                                     + '{"a": ' * 20_000 + "1" + "}" * 20_000 + "}",
        "expected_300k_keys.json": doc({f"c{i}": 1 for i in range(300_000)}),
        "expected_negative.json": doc({"socket_x1": -1}),
        "expected_float.json": doc({"socket_x1": 2.5}),
        "expected_1e30.json": doc({"socket_x1": 10 ** 30}),
        "expected_string.json": doc({"socket_x1": "many"}),
        "expected_bad_class.json": doc({"../../etc/passwd": 1}),
        "expected_wrong_schema.json": json.dumps({"schema": "x", "counts": {}}),
        "expected_list.json": "[]",
        "expected_nan.json": '{"schema": "sbsc.expected/1", "counts": {"socket_x1": NaN}}',
        "expected_binary.json": "\udcff".encode("utf-8", "surrogateescape").decode("latin-1"),
    }


def detections_files() -> dict[str, str]:
    base = detections_document()

    def edit(fn) -> str:  # noqa: ANN001
        d = copy.deepcopy(base)
        fn(d)
        return json.dumps(d)

    def set_det(i: int, **kv):  # noqa: ANN202
        return lambda d: d["detections"][i].update(kv)

    return {
        "det_deep.json": "[" * 100_000 + "]" * 100_000,
        "det_deep_in_detection.json": json.dumps(base)[:-2] + ', "x": ' + "[" * 5000 + "]" * 5000 + "}",
        "det_1e308.json": edit(set_det(0, position=[1e308, 1e308, 1e308])),
        "det_1e308_u.json": edit(set_det(1, u=1e308)),
        "det_unknown_wall.json": edit(set_det(2, wall="W99")),
        "det_duplicate_ids.json": edit(set_det(2, id="D0001")),
        "det_class_traversal.json": edit(set_det(0, **{"class": "../../etc/passwd"})),
        "det_class_nul.json": edit(set_det(0, **{"class": "socket\u0000x"})),
        "det_id_bidi.json": edit(set_det(0, id="D\u202e0001")),
        "det_alpha_5.json": edit(set_det(0, alpha=5)),
        "det_size_zero.json": edit(set_det(0, width_m=0)),
        "det_size_1e5.json": edit(set_det(0, width_m=1e5)),
        "det_nan.json": edit(set_det(0, alpha=0.5)).replace('"alpha": 0.5', '"alpha": NaN'),
        "det_wall_1e308.json": edit(lambda d: d["walls"][0].update(width_m=1e308)),
        "det_wall_origin_1e38.json": edit(lambda d: d["walls"][0].update(origin=[1e38, 0, 0])),
        "det_empty_object.json": "{}",
        "det_list.json": "[]",
        "det_string.json": '"detections"',
        "det_truncated.json": json.dumps(base)[:500],
        "det_many_keys.json": edit(lambda d: d["detections"][0].update({f"k{i}": i for i in range(50_000)})),
        "det_opening_unknown_wall.json": edit(lambda d: d["openings"][0].update(wall="nope")),
        "det_storey_unknown.json": edit(lambda d: (d.update(storeys=[{"id": "S1", "floor_z": 0, "ceiling_z": 3}]),
                                                   d["walls"][0].update(storey="S9"))),
        "det_review_bad.json": edit(lambda d: d["detections"][0].update(review={"status": "maybe"})),
    }


def truth_files() -> dict[str, str]:
    base = truth_document()

    def edit(fn) -> str:  # noqa: ANN001
        d = copy.deepcopy(base)
        fn(d)
        return json.dumps(d)

    return {
        "truth_deep.json": "{\"a\": " * 100_000 + "1" + "}" * 100_000,
        "truth_1e308.json": edit(lambda d: d["objects"][0].update(position=[1e308, 0, 0])),
        "truth_no_objects.json": edit(lambda d: d.pop("objects")),
        "truth_bad_class.json": edit(lambda d: d["objects"][0].update({"class": "../x"})),
        "truth_list.json": "[1]",
    }


def design_files(valid_ifc: bytes) -> dict[str, bytes]:
    text = valid_ifc.decode("utf-8", "replace")
    return {
        "design_empty.ifc": b"",
        "design_html.ifc": b"<html>not a model</html>",
        "design_random.ifc": np.random.default_rng(5).bytes(5000),
        "design_truncated.ifc": text[: len(text) // 3].encode(),
        "design_header_only.ifc": b"ISO-10303-21;\nHEADER;\nFILE_SCHEMA(('IFC4'));\nENDSEC;\nEND-ISO-10303-21;\n",
        "design_schema_ifc9.ifc": text.replace("FILE_SCHEMA(('IFC4'))", "FILE_SCHEMA(('IFC9'))").encode(),
    }
