"""Ceilings and columns in the 3D review scene (issue 11, point 5): a ceiling seen from below,
columns as boxes and cylinders with their objects, decisions and added objects on them."""

from __future__ import annotations

import math

import numpy as np
import pytest
import viser.transforms as vtf
from viser import _messages as vm

from app.viewer.backend import InMemoryBackend
from app.viewer.geometry import column_meshes, surface_hit
from app.viewer.labels import STATUS_RGB
from app.viewer.manager import ViewerManager
from sbsc_core.types import WallFrame

from .surfaces_output import CEILING, ROOM_H, SURFACE_OBJECTS, surfaces, write_surfaces_output
from .viewer_support import FAST, FakeTab, wait_for


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    out = tmp_path_factory.mktemp("viewer_surfaces") / "detect_out"
    write_surfaces_output(out)
    return out


@pytest.fixture()
def setup(out):
    backend = InMemoryBackend()
    backend.add_user("tok-alice", "alice", "reviewer")
    backend.add_detection_dir(1, out, name="Ceilings and columns")
    manager = ViewerManager(backend, settings=FAST)
    yield backend, manager
    manager.stop_all()


def camera(tab: FakeTab, position, look_at) -> None:
    tab.send(vm.ViewerCameraMessage(
        wxyz=(1.0, 0.0, 0.0, 0.0), position=tuple(float(x) for x in position), fov=1.0, near=0.01,
        far=1000.0, image_height=600, image_width=800, look_at=tuple(float(x) for x in look_at),
        up_direction=(0.0, 0.0, 1.0)))


def test_column_meshes_and_hits() -> None:
    meshes = column_meshes(surfaces())
    assert set(meshes) == {"COL1", "COL2"}
    v, f = meshes["COL1"]
    assert v[:, 0].min() == pytest.approx(0.8, abs=0.01) and v[:, 0].max() == pytest.approx(1.2, abs=0.01)
    assert v[:, 1].min() == pytest.approx(1.0, abs=0.01) and v[:, 1].max() == pytest.approx(1.4, abs=0.01)
    assert v[:, 2].min() == 0.0 and v[:, 2].max() == pytest.approx(ROOM_H) and f.max() < len(v)
    v, _ = meshes["COL2"]
    r = np.hypot(v[:, 0] - 3.0, v[:, 1] - 2.0)
    assert np.allclose(r[np.isfinite(r) & (r > 0.1)], 0.25, atol=0.005)
    frames = {sf["id"]: WallFrame.from_dict(sf) for sf in surfaces() if "radius_m" not in sf}
    rounds = {sf["id"]: sf for sf in surfaces() if "radius_m" in sf}
    # from below, straight up: the ceiling, at (u, v) of the point above
    hit = surface_hit(frames, rounds, np.array([2.5, 0.5, 1.6]), np.array([0.0, 0.0, 1.0]))
    assert hit[0] == "C01" and hit[1] == pytest.approx(2.5) and hit[2] == pytest.approx(2.5)
    # from above, straight down: not the ceiling (it is seen from below only)
    assert surface_hit(frames, rounds, np.array([2.5, 0.5, 5.0]), np.array([0.0, 0.0, -1.0])) is None
    # towards -x at y = 2: the round column's +x side first, at u = 0
    hit = surface_hit(frames, rounds, np.array([3.9, 2.0, 1.0]), np.array([-1.0, 0.0, 0.0]))
    assert hit[0] == "COL2" and hit[1] == pytest.approx(0.0, abs=1e-6) and hit[2] == pytest.approx(1.0)
    # towards +y at x = 1: the rectangular column's south face
    hit = surface_hit(frames, rounds, np.array([1.0, 0.2, 1.0]), np.array([0.0, 1.0, 0.0]))
    assert hit[0] == "COL1-S" and hit[1] == pytest.approx(0.2) and hit[2] == pytest.approx(1.0)


@pytest.mark.slow
def test_scene_draws_ceilings_and_columns(setup) -> None:
    backend, manager = setup
    scene = manager.wait_ready(1, 30)
    c = scene.centre
    assert "ceilings/C01" in scene.nodes and {"columns/COL1", "columns/COL2"} <= set(scene.nodes)
    body = scene.nodes["columns/COL2"].vertices.astype(np.float64) + c
    assert np.allclose(np.hypot(body[:-2, 0] - 3.0, body[:-2, 1] - 2.0), 0.247, atol=0.005)
    # the rectangular column's faces carry their orthoimages, outwards
    f = WallFrame.from_dict(next(sf for sf in surfaces() if sf["id"] == "COL1-S"))
    img = scene.nodes["images_colour/COL1-S"]
    assert np.allclose(vtf.SO3(img.wxyz).as_matrix()[:, 0], f.axis_u)
    assert 0 < f.to_uvd((img.position + c)[None])[0][2] < 0.02
    # the ceiling's image is not in the shared scene: it would hide the floor seen from above
    assert "images_colour/C01" not in scene.nodes and "images_colour/COL1-S" in scene.nodes
    assert "images_colour/COL2" in scene.nodes  # the round column's image, wrapped round it
    for did, *_ in SURFACE_OBJECTS:
        det = scene.detections[did]
        assert np.allclose(scene.spots[did].position + c, det["position"])
    # a ceiling object's label hangs below it
    lab = scene.spot_labels["D0101"].position + c
    assert lab[2] < ROOM_H - 0.05 and "ceiling tile" in scene.status_text() and "2 column(s)" in scene.status_text()


@pytest.mark.slow
def test_ceiling_seen_from_below_reviewed_in_the_scene(setup) -> None:
    backend, manager = setup
    scene = manager.wait_ready(1, 30)
    tab = FakeTab(manager.viewer(1).port)
    try:
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        c = scene.centre
        z_ceiling = ROOM_H - c[2]
        camera(tab, (0.0, -10.0, 10.0), (0.0, 0.0, 0.0))  # above the floor: no ceiling image
        wait_for(lambda: session.camera_z() is not None and session.camera_z() > z_ceiling, what="camera")
        session.update_ceilings()
        assert session.ceiling_images_shown() == []
        camera(tab, (0.0, 0.0, z_ceiling - 1.0), (0.0, 0.5, z_ceiling))  # in the room, looking up
        wait_for(lambda: session.ceiling_images_shown() == ["colour/C01"], what="ceiling image from below")
        node = session.ceiling_nodes["colour/C01"]
        f = WallFrame.from_dict(CEILING)
        rot = vtf.SO3(node.wxyz).as_matrix()
        assert np.allclose(rot[:, 0], f.axis_u) and np.allclose(rot[:, 1], -f.axis_v)
        assert node.position[2] + c[2] == pytest.approx(ROOM_H - FAST.image_offset_m)
        assert node.render_width == pytest.approx(4.0, abs=0.01)
        # select the smoke detector on the ceiling: the camera goes below it, looking up
        tab.click_node("/spots/D0101")
        wait_for(lambda: session.selected == "D0101" and "ceiling C01 (seen from below)" in session.ui_info.content,
                 what="selection")
        eye = session.view_point(scene.detections["D0101"])
        target = scene.local(scene.detections["D0101"]["position"])
        assert eye[2] < target[2] - 0.5 and np.hypot(*(eye - target)[:2]) > 0.3
        # crops of the ceiling's images (set after the info text, in the scene's thread)
        wait_for(lambda: session.ui_colour.visible and session.ui_depth.visible, what="crops")
        tab.set_gui(session.ui_token, "tok-alice")
        tab.press(session.ui_sign_in)
        wait_for(lambda: session.user is not None and not session.ui_accept.disabled, what="sign-in")
        session.ui_auto.value = False  # stay on the object (no race with the selection below)
        tab.press(session.ui_accept)
        det = wait_for(lambda: (d := next(x for x in backend.project_data(1).detections["detections"]
                                         if x["id"] == "D0101"))["review"]["status"] == "accepted" and d,
                       what="decision")
        assert det["review"]["by"] == "alice" and det["surface"] == "ceiling"
        wait_for(lambda: tuple(scene.spots["D0101"].color) == STATUS_RGB["accepted"], what="spot colour")
        # the round column's object: its panel names the column
        session.select("D0103", fly=False)
        assert "round column COL2 (unrolled)" in session.ui_info.content
        n = scene.normal_at(scene.detections["D0103"])
        assert n == pytest.approx([0.0, 1.0, 0.0], abs=1e-3)
    finally:
        tab.close()


@pytest.mark.slow
def test_shift_click_adds_on_a_ceiling_and_a_round_column(setup) -> None:
    backend, manager = setup
    scene = manager.wait_ready(1, 30)
    tab = FakeTab(manager.viewer(1).port)
    try:
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        session.sign_in("tok-alice")
        session.ui_add_class.value = session.ui_add_class.options[0]
        c = scene.centre
        det = session.add_at_ray(np.array([3.0, 0.7, 1.5]) - c, np.array([0.0, 0.0, 1.0]))
        assert det is not None and det["wall"] == "C01" and det["surface"] == "ceiling"
        assert det["position"] == pytest.approx([3.0, 0.7, ROOM_H])
        assert det["id"] in scene.spots
        det = session.add_at_ray(np.array([3.0, 3.5, 1.0]) - c, np.array([0.0, -1.0, 0.0]))
        assert det is not None and det["wall"] == "COL2" and det["surface"] == "column"
        assert det["u"] == pytest.approx(0.25 * math.pi / 2, abs=1e-3)
        assert det["position"] == pytest.approx([3.0, 2.25, 1.0], abs=1e-4)
    finally:
        tab.close()
