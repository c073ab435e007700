"""The model library's ``mount`` (contract 2): which surfaces a class may be on."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.io.models import load_model_library
from sbsc_core.paths import bundled_models_dir
from sbsc_core.pipeline.walls import search_classes
from sbsc_core.simulate.catalogue import CATALOGUE
from sbsc_core.simulate.library import model_json


def _class(root: Path, class_id: str, **extra) -> None:
    d = root / class_id
    d.mkdir(parents=True)
    meta = {"name": class_id, "ifc_class": "IfcSensor", "width_m": 0.1, "height_m": 0.1, **extra}
    (d / "model.json").write_text(json.dumps(meta))
    cv2.imwrite(str(d / "colour.png"), np.full((8, 8, 3), 200, np.uint8))


def test_mount_defaults_to_every_surface_and_is_read(tmp_path):
    _class(tmp_path, "any_where")
    _class(tmp_path, "smoke", mount=["ceiling", "wall"])
    _class(tmp_path, "ceiling_only", mount=["ceiling"])
    lib = load_model_library(tmp_path)
    assert lib["any_where"].mount == ("wall", "ceiling", "column")
    assert lib["smoke"].mount == ("wall", "ceiling")  # kept in the canonical order
    assert "mount" not in lib["smoke"].extra
    assert lib.classes_on("wall") == ["any_where", "smoke"]
    assert lib.classes_on("ceiling") == ["any_where", "ceiling_only", "smoke"]
    assert lib.classes_on("column") == ["any_where"]
    # walls search only wall-mounted classes, with or without expected counts
    assert search_classes(lib, None) == ["any_where", "smoke"]
    assert search_classes(lib, {"ceiling_only": 2, "smoke": 1}) == ["smoke"]
    assert search_classes(lib, {"ceiling_only": 2}, kind="ceiling") == ["ceiling_only"]


@pytest.mark.parametrize("mount, fragment", [
    ([], "'mount' must be a non-empty list"),
    ("wall", "'mount' must be a non-empty list"),
    (["wall", "floor"], "unknown surface \"floor\""),
    (["wall", 3], "unknown surface 3"),
    (["wall", "wall"], "names a surface twice"),
])
def test_bad_mount_is_one_line_naming_the_file(tmp_path, mount, fragment):
    _class(tmp_path, "smoke", mount=mount)
    with pytest.raises(InputError) as info:
        load_model_library(tmp_path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(tmp_path / "smoke" / "model.json")) and fragment in msg, msg


def test_simulator_and_bundled_library_say_where_classes_hang():
    assert model_json("smoke_detector")["mount"] == ["wall", "ceiling"]
    assert model_json("exit_light")["mount"] == ["wall", "ceiling"]
    assert model_json("fire_extinguisher")["mount"] == ["wall", "column"]
    assert model_json("radiator")["mount"] == ["wall"]
    lib = load_model_library(bundled_models_dir())
    for cls, model in lib.models.items():
        assert model.mount == CATALOGUE[cls].mount
    assert lib.classes_on("wall") == lib.class_ids  # every bundled class is still searched on walls
