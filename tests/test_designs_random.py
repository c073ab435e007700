"""Random design families (``sbsc simulate --designs random``): determinism, envelopes, and
that the scene, its truth and the model library agree on every object's size."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sbsc_core.errors import InputError
from sbsc_core.paths import sample_projects_dir
from sbsc_core.simulate.building import build_building, sized_for
from sbsc_core.simulate.catalogue import CATALOGUE, CLASS_ORDER
from sbsc_core.simulate.designs import design_builder, library_builder
from sbsc_core.simulate.designs_random import random_family, sibling_family
from sbsc_core.simulate.library import write_model_library
from sbsc_core.simulate.scenarios import scenario_description
from sbsc_core.simulate.scene import load_scene, parse_scene, validate_scene

SEEDS = range(24)

# Realistic envelopes, metres: (width lo, hi), (height lo, hi), (depth lo, hi). Written from
# product ranges (not read from the module): a family outside them is not plausible.
ENVELOPES = {
    "electrical_panel": ((0.30, 0.60), (0.35, 0.75), (0.08, 0.16)),
    "socket_x1": ((0.070, 0.095), (0.070, 0.095), (0.008, 0.016)),
    "socket_x2": ((0.12, 0.19), (0.070, 0.095), (0.008, 0.016)),
    "socket_x4": ((0.22, 0.37), (0.070, 0.095), (0.008, 0.016)),
    "builtin_socket": ((0.08, 0.13), (0.08, 0.13), (0.0015, 0.006)),
    "switch": ((0.070, 0.095), (0.070, 0.095), (0.008, 0.016)),
    "fire_extinguisher": ((0.15, 0.26), (0.42, 0.68), (0.12, 0.20)),
    "radiator": ((0.40, 1.20), (0.30, 0.70), (0.06, 0.12)),
    "fire_alarm_switch": ((0.085, 0.135), (0.08, 0.14), (0.025, 0.06)),
    "smoke_detector": ((0.09, 0.13), (0.09, 0.13), (0.035, 0.065)),
    "exit_light": ((0.25, 0.45), (0.10, 0.17), (0.03, 0.07)),
    "extinguisher_sign": ((0.15, 0.30), (0.15, 0.30), (0.0015, 0.004)),
    "fire_alarm_switch_sign": ((0.15, 0.30), (0.15, 0.30), (0.0015, 0.004)),
}


def _mesh_key(mesh) -> tuple:
    return (mesh.vertices.tobytes(), mesh.triangles.tobytes(), mesh.tri_colour.tobytes(),
            b"".join(t.tobytes() for t in mesh.textures))


def test_a_family_is_deterministic_per_seed_and_seeds_differ():
    a, b, c = random_family(11), random_family(11), random_family(12)
    assert a.specs == b.specs
    for cls in CLASS_ORDER:
        assert _mesh_key(a(cls)) == _mesh_key(b(cls)), cls
        assert _mesh_key(a(cls)) == _mesh_key(a(cls)), cls  # building twice gives the same mesh
    assert a.specs != c.specs
    assert sum(_mesh_key(a(cls)) != _mesh_key(c(cls)) for cls in CLASS_ORDER) == len(CLASS_ORDER)
    # the CLI's builder is the same family
    assert design_builder("random", 11).specs == a.specs


def test_every_class_within_its_envelope_and_its_mesh_within_its_size():
    for seed in SEEDS:
        fam = random_family(seed)
        assert list(fam.designs) == list(CLASS_ORDER)
        for cls, spec in fam.specs.items():
            (wl, wh), (hl, hh), (dl, dh) = ENVELOPES[cls]
            where = f"seed {seed} {cls} {spec.width_m} x {spec.height_m} x {spec.depth_m}"
            assert wl <= spec.width_m <= wh and hl <= spec.height_m <= hh and dl <= spec.depth_m <= dh, where
            base = CATALOGUE[cls]
            assert (spec.ifc_class, spec.mount, spec.mount_height_m) == (base.ifc_class, base.mount, base.mount_height_m)
            mesh = fam(cls)
            assert mesh.n_triangles > 0
            lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
            assert np.all(lo >= [-spec.width_m / 2 - 1e-6, -spec.height_m / 2 - 1e-6, -1e-9]), where
            assert np.all(hi <= [spec.width_m / 2 + 1e-6, spec.height_m / 2 + 1e-6, spec.depth_m + 0.0005]), where
            assert hi[2] >= 0.9 * spec.depth_m, where  # the depth is the object's, not a bound
        s = fam.specs  # one socket series: the gangs add up, one height
        assert s["socket_x1"].width_m < s["socket_x2"].width_m < s["socket_x4"].width_m
        assert s["socket_x1"].height_m == s["socket_x2"].height_m == s["socket_x4"].height_m


def test_a_sibling_family_has_the_scene_sizes_and_its_own_designs():
    """A sibling (the library of a random cross) has every object's size of the scene's family,
    its mesh fills that footprint, and its reliefs are another family's: depth models differ."""
    from sbsc_core.simulate.library import render_model

    fam = random_family(3)
    sib = sibling_family(fam, 11)
    other = random_family(11)
    differ = 0
    for cls in CLASS_ORDER:
        spec = sib.specs[cls]
        assert spec == fam.specs[cls], cls
        lo, hi = sib(cls).vertices.min(axis=0), sib(cls).vertices.max(axis=0)
        assert np.all(np.abs(hi[:2] - lo[:2] - [spec.width_m, spec.height_m]) <= 0.02 * np.array([spec.width_m,
                                                                                                  spec.height_m])), cls
        assert hi[2] == pytest.approx(other(cls).vertices[:, 2].max() * spec.depth_m / other.specs[cls].depth_m), cls
    for cls in ("switch", "socket_x1", "builtin_socket", "smoke_detector"):
        a, b = render_model(cls, object_builder=fam).depth, render_model(cls, object_builder=sib).depth
        assert a.shape == b.shape
        differ += float(np.abs(a - b).mean()) > 0.0005
    assert differ >= 2
    with pytest.raises(InputError, match="library-design-seed"):
        sibling_family(fam, 3)
    assert library_builder("sibling", fam, 3).seed == 4  # default: the scene's seed + 1
    assert library_builder(None, fam, 3) is fam
    with pytest.raises(InputError, match="library-designs"):
        library_builder("sibling", design_builder("standard"), 3)


def test_reliefs_and_look_alikes_arise_across_families():
    fams = [random_family(seed) for seed in range(40)]
    reliefs = {c: {f.designs[c].relief for f in fams} for c in CLASS_ORDER}
    assert {"tilted rocker", "two tilted rockers", "flat push button"} <= reliefs["switch"]
    assert {"recessed cup", "square well", "flat face"} <= reliefs["socket_x1"]
    assert {"dome", "stacked discs", "square"} <= reliefs["smoke_detector"]
    # by chance, as between manufacturers: a switch on the socket's plate, signs of one format
    assert any(f.specs["switch"].width_m == f.specs["socket_x1"].width_m for f in fams)
    assert any(f.specs["switch"].width_m != f.specs["socket_x1"].width_m for f in fams)
    same = [(f.specs["extinguisher_sign"].width_m, f.specs["extinguisher_sign"].height_m)
            == (f.specs["fire_alarm_switch_sign"].width_m, f.specs["fire_alarm_switch_sign"].height_m) for f in fams]
    assert any(same) and not all(same)
    # a rocker tilts: its front is not parallel to the wall
    fam = next(f for f in fams if f.designs["switch"].relief == "tilted rocker")
    m = fam("switch")
    v = m.vertices[m.triangles]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    assert np.any((np.abs(n[:, 2]) > 0.9) & (np.abs(n[:, 2]) < 0.9999))


@pytest.mark.slow
def test_bundled_scenes_take_every_family():
    scenes = [load_scene(sample_projects_dir() / "one_room.yaml"),
              parse_scene(scenario_description("I"), "Scenario I")]
    for seed in SEEDS:
        fam = random_family(seed)
        for scene in scenes:
            validate_scene(sized_for(scene, fam))  # raises if objects overlap or leave their wall


def test_scene_truth_and_library_agree_on_sizes(tmp_path):
    fam = random_family(5)
    scene = load_scene(sample_projects_dir() / "one_room.yaml")
    building = build_building(scene, fam)
    assert building.scene.specs == fam.specs and scene.specs is CATALOGUE  # the input is not changed
    for o in building.truth_document()["objects"]:
        assert (o["width_m"], o["height_m"]) == (fam.specs[o["class"]].width_m, fam.specs[o["class"]].height_m)
    classes = ["switch", "smoke_detector", "extinguisher_sign"]
    write_model_library(tmp_path / "models", classes=classes, object_builder=fam, n_views=1)
    for cls in classes:
        spec = fam.specs[cls]
        meta = json.loads((tmp_path / "models" / cls / "model.json").read_text())
        assert (meta["width_m"], meta["height_m"], meta["depth_m"]) == (spec.width_m, spec.height_m, spec.depth_m)
        depth = np.load(tmp_path / "models" / cls / "depth.npy")
        assert depth.shape == (round(spec.height_m / 0.002), round(spec.width_m / 0.002))
        assert abs(float(np.percentile(depth, 99.5)) - spec.depth_m) < 0.003, cls


def test_fixed_sets_keep_the_catalogue():
    scene = load_scene(sample_projects_dir() / "one_room.yaml")
    for name in ("standard", "alt", "third"):
        assert sized_for(scene, design_builder(name)) is scene
    b = build_building(scene, design_builder("third"))
    assert all((o.width_m, o.height_m) == (CATALOGUE[o.class_id].width_m, CATALOGUE[o.class_id].height_m)
               for o in b.objects)


@pytest.mark.parametrize("seed", [-1, 2**63, 1.5, True])
def test_bad_seed_is_refused(seed):
    with pytest.raises(InputError, match="design-seed"):
        random_family(seed)


@pytest.mark.slow
def test_simulated_scene_writes_the_family_library(tmp_path):
    """``sbsc simulate --designs random``: the library of the scene's family, or of another."""
    from sbsc_core.cli import main

    out = tmp_path / "scan"
    assert main(["-q", "simulate", "--scene", "one_room", "--designs", "random", "--seed", "4",
                 "--step", "0.6", "--out", str(out)]) == 0
    truth = json.loads((out / "ground_truth.json").read_text())
    fam = random_family(4)
    for o in truth["objects"]:
        meta = json.loads((out / "models" / o["class"] / "model.json").read_text())
        assert (meta["width_m"], meta["height_m"]) == (o["width_m"], o["height_m"]) == (
            fam.specs[o["class"]].width_m, fam.specs[o["class"]].height_m)
    cross = tmp_path / "cross"
    assert main(["-q", "simulate", "--scene", "one_room", "--designs", "random", "--seed", "4",
                 "--library-designs", "random", "--library-design-seed", "9", "--step", "0.6",
                 "--out", str(cross)]) == 0
    assert json.loads((cross / "ground_truth.json").read_text())["objects"] == truth["objects"]
    meta = json.loads((cross / "models" / "radiator" / "model.json").read_text())
    assert meta["width_m"] == random_family(9).specs["radiator"].width_m != fam.specs["radiator"].width_m

