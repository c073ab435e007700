"""The 3D scene at first sight (issue 29): wall names that do not pile up, spots sized for the
floor, readable times, no glyph a browser may lack."""

from __future__ import annotations

import time

import numpy as np
import pytest
from viser import _messages as vm

from app.viewer.backend import InMemoryBackend
from app.viewer.labels import readable_time, spread_labels
from app.viewer.manager import ViewerManager
from app.viewer.scene import SceneSettings
from app.viewer.synthetic import write_synthetic_project

FAST = SceneSettings(poll_s=0.05, fly_s=0.02, fly_steps=2, scan_delay_s=0.2, overview_points=3000)


def test_readable_time() -> None:
    assert readable_time("2026-11-28T12:34:56.789+00:00") == "2026-11-28 12:34 UTC"
    assert readable_time("2026-11-28T13:34:56+01:00") == "2026-11-28 12:34 UTC"
    assert readable_time("2026-11-28T12:34:56Z") == "2026-11-28 12:34 UTC"
    assert readable_time("2026-11-28T12:34:56") == "2026-11-28 12:34"
    assert readable_time("?") == "?"


def test_spread_labels_stacks_close_labels_only() -> None:
    pts = {"W07": np.array([0.0, 0.0, 3.0]), "W09": np.array([0.4, 0.2, 3.0]),
           "W10": np.array([0.1, 0.5, 3.0]), "W11": np.array([6.0, 0.0, 3.0])}
    out = spread_labels(pts, gap_m=1.6, step_m=0.35)
    assert out["W07"][2] == 3.0 and out["W11"][2] == 3.0  # alone: where it was
    assert sorted(out[k][2] for k in ("W07", "W09", "W10")) == pytest.approx([3.0, 3.35, 3.7])
    for k, p in out.items():
        assert np.allclose(p[:2], pts[k][:2])  # only lifted
    keys = list(out)
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            near = np.hypot(*(out[a][:2] - out[b][:2])) < 1.6
            assert not near or abs(out[a][2] - out[b][2]) >= 0.34, (a, b)


def test_label_positions_spread_faces_and_corners_along_their_walls() -> None:
    from app.viewer.labels import label_positions
    from sbsc_core.types import WallFrame

    def wall(origin, u, width):  # noqa: ANN001
        u = np.asarray(u, float)
        return WallFrame(origin=np.asarray(origin, float), axis_u=u, axis_v=np.array([0.0, 0.0, 1.0]),
                         normal=np.cross(u, [0.0, 0.0, 1.0]), width_m=width, height_m=3.0)

    frames = {"A": wall([0, 0, 0], [1, 0, 0], 8.4), "B": wall([8.4, 0.15, 0], [-1, 0, 0], 8.4),  # two faces
              "C": wall([20, 0, 0], [1, 0, 0], 4.0)}
    u = label_positions(frames, 1.6)
    assert u["C"] == pytest.approx(2.0)  # alone: the middle
    a, b = (frames[k].to_world(u[k], 3.0)[:2] for k in ("A", "B"))
    assert np.hypot(*(a - b)) == pytest.approx(8.4 / 3, abs=0.05)  # a third of the wall apart


@pytest.mark.slow
def test_scene_of_a_floor_stacks_wall_names_and_sizes_spots(tmp_path) -> None:
    sp = write_synthetic_project(tmp_path / "out", rooms=6, columns=3, walls_per_room=4, objects_per_wall=1,
                                 points=20_000, room_size=(7.6, 9.7), height_m=3.0)
    backend = InMemoryBackend()
    backend.add_detection_dir(1, sp.out_dir, scans=[sp.scan])
    manager = ViewerManager(backend, settings=FAST)
    try:
        scene = manager.wait_ready(1, 60)
        # 22.8 m x 19.4 m: spots of 9 cm, not 5 cm lost at the default zoom
        assert scene.spot_radius == pytest.approx(0.004 * max(scene._extent(), 1.0))
        assert 0.08 < scene.spot_radius < 0.12
        tops = list(scene.label_at.values())
        assert len(tops) == len(scene.frames) == 24
        for i, a in enumerate(tops):  # no two wall names at one place
            for b in tops[i + 1:]:
                assert np.hypot(*(a[:2] - b[:2])) >= 1.6 or abs(a[2] - b[2]) >= 0.34
        # the rooms' shared partitions (two faces, middles at one place): names spread along the
        # walls, apart in plan, as a view from above shows them (not only raised)
        assert min(np.hypot(*(a[:2] - b[:2])) for i, a in enumerate(tops) for b in tops[i + 1:]) >= 1.6
        scene.locked, scene.signoff = True, {"by": "max", "at": "2026-11-28T12:34:56+00:00"}
        text = scene.status_text()
        assert "on 2026-11-28 12:34 UTC" in text and "🔒" not in text
    finally:
        manager.stop_all()


def test_spot_labels_use_the_librarys_names() -> None:
    from app.viewer.labels import class_names, spot_label
    from sbsc_core.paths import bundled_models_dir

    names = class_names(bundled_models_dir())
    assert names["fire_alarm_switch_sign"] == "Fire alarm switch sign"
    det = {"class": "socket_x1", "confidence": 0.93}
    assert spot_label(det, names) == "Socket x1 0.93"
    assert spot_label({"class": "mystery", "alpha": 0.5}, names) == "mystery α 0.50"  # unknown: its id
    assert class_names(None) == {}


def test_class_choices_show_names_and_keep_ids() -> None:
    from app.viewer.labels import class_choices

    names = {"socket_x1": "Socket x1", "switch": "Switch", "a": "Same", "b": "Same", "c": "switch"}
    got = class_choices(["socket_x1", "switch", "mystery", "a", "b", "c"], names)
    assert got == {"Socket x1": "socket_x1", "Switch": "switch", "mystery": "mystery",
                   "Same (a)": "a", "Same (b)": "b", "switch (c)": "c"}  # every option names one class


@pytest.mark.slow
def test_class_dropdowns_show_the_librarys_names_and_decide_by_id(tmp_path) -> None:
    from sbsc_core.paths import bundled_models_dir

    from .viewer_support import FakeTab, wait_for

    sp = write_synthetic_project(tmp_path / "out", rooms=1, walls_per_room=2, objects_per_wall=3, points=4000)
    backend = InMemoryBackend()
    backend.add_user("tok-alice", "alice", "reviewer")
    backend.add_detection_dir(1, sp.out_dir, scans=[sp.scan], models_dir=bundled_models_dir())
    manager = ViewerManager(backend, settings=FAST)
    tab = None
    try:
        scene = manager.wait_ready(1, 60)
        tab = FakeTab(manager.viewer(1).port)
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        opts = list(session.ui_class.options)
        assert "Socket x1" in opts and "Fire alarm switch sign" in opts and "Switch" in opts
        assert not {"socket_x1", "fire_alarm_switch_sign", "switch"} & set(opts)  # names, not ids
        assert opts == sorted(opts, key=str.casefold) and list(session.ui_add_class.options) == opts
        det = next(d for d in sp.detections["detections"] if d["class"] == "socket_x1")
        tab.click_node(f"/spots/{det['id']}")
        wait_for(lambda: session.selected == det["id"] and session.ui_class.value == "Socket x1", what="select")
        assert "Socket x1" in session.ui_info.content and "socket_x1" not in session.ui_info.content
        tab.set_gui(session.ui_token, "tok-alice")
        tab.press(session.ui_sign_in)
        wait_for(lambda: session.user is not None and not session.ui_relabel.disabled, what="sign-in")
        session.ui_auto.value = False
        tab.set_gui(session.ui_class, "Fire alarm switch sign")
        wait_for(lambda: session.ui_class.value == "Fire alarm switch sign", what="class chosen")
        tab.press(session.ui_relabel)
        got = wait_for(lambda: (d := next(x for x in backend.project_data(1).detections["detections"]
                                         if x["id"] == det["id"]))["class"] != "socket_x1" and d, what="relabel")
        assert got["class"] == "fire_alarm_switch_sign"  # the id is what is recorded
        wall = det["wall"]
        tab.set_gui(session.ui_add_class, "Switch")
        wait_for(lambda: session.ui_add_class.value == "Switch", what="class to add")
        f = scene.frames[wall]  # a shift-click straight at the wall, from 1 m in front of it
        origin = f.to_world(0.5, 1.0, 1.0) - scene.centre
        added = session.add_at_ray(origin, -np.asarray(f.normal, float))
        assert added is not None and added["class"] == "switch" and added["wall"] == wall
    finally:
        if tab is not None:
            tab.close()
        manager.stop_all()


@pytest.mark.slow
def test_the_scan_comes_after_the_first_frame_in_batches(tmp_path) -> None:
    """A tab that has not drawn yet gets no scan; once it answers its render request it gets
    the scan in batches of about ``scan_batch_points``, a pause apart."""
    from .viewer_support import FakeTab, wait_for

    sp = write_synthetic_project(tmp_path / "out", rooms=2, walls_per_room=4, objects_per_wall=1, points=40_000,
                                 room_size=(9.0, 9.0))
    backend = InMemoryBackend()
    backend.add_detection_dir(1, sp.out_dir, scans=[sp.scan])
    settings = SceneSettings(poll_s=0.05, scan_delay_s=0.0, overview_points=20_000, tile_m=3.0,
                             scan_batch_points=4000, scan_batch_pause_s=0.3, first_frame_wait_s=30.0)
    manager = ViewerManager(backend, settings=settings)
    tab = None
    try:
        scene = manager.wait_ready(1, 60)
        tab = FakeTab(manager.viewer(1).port)
        answer, tab.frame = tab.frame, None  # a tab still busy drawing: no answer yet
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        req = wait_for(lambda: next((m for _, m in list(tab.received) if m.get("type") == "GetRenderRequestMessage"),
                                    None), what="render request")
        time.sleep(1.0)
        assert session.scan_points_sent() == 0  # nothing of the scan before the first frame
        tab.send(vm.GetRenderResponseMessage(payload=answer, render_uuid=req["render_uuid"]))
        tiles = scene.scan_tiles["scan_overview"]
        total = sum(len(t.points) for t in tiles)
        wait_for(lambda: session.scan_points_sent() == total, 30.0, "the whole overview")
        def clouds() -> list[float]:
            return [t for t, m in list(tab.received) if m.get("type") == "PointCloudMessage"]

        wait_for(lambda: len(clouds()) == len(tiles), 10.0, "every tile received")
        times = clouds()
        assert len(tiles) > 3
        gaps = np.diff(times)
        assert (gaps > 0.2).sum() >= total // 4000 - 2  # batches a pause apart, not one burst
    finally:
        if tab is not None:
            tab.close()
        manager.stop_all()
