"""The 3D review scene driven from Python: nodes, clicks, decisions, sync, sign-off, projects.

A small websocket client speaks viser's protocol like a browser tab does (camera message,
scene-node click, GUI updates), so the scene's own callbacks run exactly as in a browser.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import viser.transforms as vtf

from app.viewer.backend import (
    Forbidden,
    InMemoryBackend,
    Locked,
    NotFound,
    StaleVersion,
)
from app.viewer.geometry import rect_segments
from app.viewer.labels import COLOUR_ROI_RGB, DEPTH_ROI_RGB, STATUS_RGB
from app.viewer.manager import ViewerManager
from app.viewer.synthetic import write_synthetic_project
from sbsc_core.types import WallFrame

from .viewer_support import FAST, FakeTab, wait_for


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("viewer") / "detect_out"
    sp = write_synthetic_project(out, rooms=1, walls_per_room=2, objects_per_wall=2, points=6000)
    return out, sp


@pytest.fixture()
def setup(project):
    out, sp = project
    backend = InMemoryBackend()
    backend.add_user("tok-alice", "alice", "reviewer")
    backend.add_user("tok-guest", "guest", "guest")
    backend.add_user("tok-boss", "boss", "manager")
    backend.add_detection_dir(1, out, scans=[sp.scan])
    manager = ViewerManager(backend, settings=FAST)
    yield backend, manager, sp
    manager.stop_all()


@pytest.mark.slow
def test_scene_nodes_match_detections(setup):
    backend, manager, sp = setup
    scene = manager.wait_ready(1, 30)
    doc, rois = sp.detections, sp.rois
    # the scan: recentred, nothing far from the scene's origin, centre applied to everything
    assert np.allclose(scene.centre, np.round(scene.centre, 3))
    assert abs(scene.centre[0] - 500.0) < 10 and abs(scene.centre[1] - 200.0) < 10
    tiles = scene.scan_tiles["scan_overview"]
    assert tiles and not scene.scan_tiles["ceiling_overview"] == []
    for t in tiles:  # float16 offsets from each tile's centre, back to world coordinates
        world = t.points.astype(np.float64) + t.position + scene.centre
        assert world[:, 2].min() > 10.0 - 0.02 and world[:, 2].max() < 10.0 + 2.7 - 0.05
        assert np.abs(t.points).max() <= FAST.tile_m
    ceiling = scene.scan_tiles["ceiling_overview"][0]
    assert (ceiling.points[:, 2].astype(float) + ceiling.position[2] + scene.centre[2] > 12.6).all()
    assert not any(n.startswith(("scan_", "ceiling_")) for n in scene.nodes)  # sent per tab

    for w in doc["walls"]:
        f = WallFrame.from_dict(w)
        outline = scene.nodes[f"walls/{w['id']}/outline"]
        corners = outline.points.reshape(-1, 3).astype(np.float64) + scene.centre
        expected = rect_segments(f, 0, f.width_m, 0, f.height_m).reshape(-1, 3)
        assert np.allclose(corners, expected, atol=1e-3)
        assert scene.nodes[f"walls/{w['id']}/label"].text.startswith(w["id"])
        img = scene.nodes[f"images_colour/{w['id']}"]
        rot = vtf.SO3(img.wxyz).as_matrix()
        assert np.allclose(rot[:, 0], f.axis_u) and np.allclose(rot[:, 1], -f.axis_v)
        centre = img.position + scene.centre
        uvd = f.to_uvd(centre[None])[0]
        assert abs(uvd[0] - f.width_m / 2) < 0.01 and abs(uvd[1] - f.height_m / 2) < 0.01
        assert 0 < uvd[2] < 0.02  # just in front of the wall
        assert abs(img.render_width - f.width_m) < 0.01 and abs(img.render_height - f.height_m) < 0.01
        for kind, rgb in (("depth", DEPTH_ROI_RGB), ("colour", COLOUR_ROI_RGB)):
            boxes = rois["walls"][w["id"]][kind]
            node = scene.nodes.get(f"rois_{kind}/{w['id']}")
            if not boxes:
                assert node is None
                continue
            assert node.points.shape == (4 * len(boxes), 2, 3)
            assert tuple(node.colors) == rgb
            uv = f.to_uvd(node.points.reshape(-1, 3).astype(np.float64) + scene.centre)
            assert np.isclose(uv[:, 0].min(), min(b["u_min"] for b in boxes), atol=1e-3)
            assert np.isclose(uv[:, 1].max(), max(b["v_max"] for b in boxes), atol=1e-3)
    assert "images_depth/W01" not in scene.nodes  # depth planes only when switched to
    scene.set_image_mode("depth")
    assert scene.groups["images_depth"].visible and not scene.groups["images_colour"].visible
    assert "images_depth/W01" in scene.nodes
    opening = doc["openings"][0]
    assert scene.nodes[f"openings/{opening['wall']}"].points.shape == (4, 2, 3)

    assert set(scene.spots) == {d["id"] for d in doc["detections"]}
    for d in doc["detections"]:
        spot = scene.spots[d["id"]]
        assert np.allclose(spot.position + scene.centre, d["position"], atol=1e-6)
        assert tuple(spot.color) == STATUS_RGB["pending"]
        label = scene.spot_labels[d["id"]].text
        assert d["class"] in label and f"{d['alpha']:.2f}" in label
    assert "4 pending" in scene.status_text().replace("*", "")


@pytest.mark.slow
def test_click_accept_records_decision_and_syncs(setup):
    backend, manager, sp = setup
    scene = manager.wait_ready(1, 30)
    tab = FakeTab(manager.viewer(1).port)
    try:
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        did = sp.detections["detections"][0]["id"]
        tab.click_node(f"/spots/{did}")
        wait_for(lambda: session.selected == did and did in session.ui_info.content
                 and session.ui_colour.visible, what="selection")
        assert "pending" in session.ui_info.content
        assert session.ui_accept.disabled  # nobody signed in yet
        tab.set_gui(session.ui_token, "tok-alice")
        tab.press(session.ui_sign_in)
        wait_for(lambda: session.user is not None and not session.ui_accept.disabled, what="sign-in")
        assert session.user.name == "alice"
        assert session.ui_token.value == ""  # the token does not stay on screen
        tab.press(session.ui_accept)
        det = wait_for(lambda: (d := backend.project_data(1).detections["detections"][0])
                       ["review"]["status"] == "accepted" and d, what="decision")
        assert det["review"]["by"] == "alice" and det["review"]["version"] == 2
        wait_for(lambda: tuple(scene.spots[did].color) == STATUS_RGB["accepted"], what="spot colour")
        # "go to next pending" moved the selection on
        wait_for(lambda: session.selected not in (None, did), what="next pending")

        # a decision made elsewhere (the REST API) shows in the scene within a second
        other = sp.detections["detections"][2]["id"]
        t0 = time.monotonic()
        backend.decide(1, other, "rejected", None, 1, backend.resolve_token("tok-boss"))
        wait_for(lambda: tuple(scene.spots[other].color) == STATUS_RGB["rejected"], 1.0,
                 "REST change in the scene")
        wait_for(lambda: any(m.get("type") == "SceneNodeUpdateMessage"
                             and m.get("name") == f"/spots/{other}" and t > t0
                             for t, m in list(tab.received)), 1.0, "update sent to the tab")
        assert time.monotonic() - t0 < 1.0
        assert "2 pending" in scene.status_text().replace("*", "")

        # next / previous pending walk only pending objects
        tab.press(session.ui_next)
        wait_for(lambda: session.selected is not None
                 and scene.detections[session.selected]["review"]["status"] == "pending")

        # sign-off: read-only, and it says so
        backend.sign_off(1, backend.resolve_token("tok-boss"), "done")
        wait_for(lambda: scene.locked, 1.0, "lock")
        assert "read-only" in scene.status_text()
        wait_for(lambda: session.ui_accept.disabled and session.ui_reject.disabled)
        wait_for(lambda: "read-only" in session.ui_who.content, 1.0, "read-only notice")
        assert "🔒" not in session.ui_who.content + session.ui_info.content  # a glyph fonts may lack
        before = backend.project_data(1).detections
        tab.press(session.ui_accept)
        time.sleep(0.3)
        assert backend.project_data(1).detections == before
    finally:
        tab.close()


@pytest.mark.slow
def test_scan_is_sent_per_tab_after_the_scene(setup):
    backend, manager, sp = setup
    scene = manager.wait_ready(1, 30)
    tab = FakeTab(manager.viewer(1).port)
    try:
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        wait_for(lambda: session.scan_points_sent() > 0, 5.0, "scan")
        sent = sum(len(t.points) for t in scene.scan_tiles["scan_overview"])
        assert session.scan_points_sent() == sent and set(session.scan_nodes) == {"scan_overview"}
        names = wait_for(lambda: [m.get("name") for _, m in list(tab.received)
                                  if m.get("type") == "PointCloudMessage"], what="clouds received")
        assert all(n.startswith("/scan_overview/") for n in names)
        first_cloud = next(t for t, m in tab.received if m.get("type") == "PointCloudMessage")
        status = [t for t, m in tab.received if m.get("type") == "GuiMarkdownMessage"]
        assert status and min(status) <= first_cloud  # the panel came before the scan
        asked = [t for t, m in tab.received if m.get("type") == "GetRenderRequestMessage"]
        assert asked and asked[0] < first_cloud  # ... and the tab drew its first frame before it too
        tab.set_gui(session.ui_ceiling, True)
        wait_for(lambda: "ceiling_overview" in session.scan_nodes, what="ceiling")
        assert "scan_full" not in scene.scan_tiles  # the full level's tiles: made when first asked for
        tab.set_gui(session.ui_scan, "full")
        wait_for(lambda: session.scan_nodes.get("scan_full") and session.scan_nodes.get("ceiling_full")
                 and len(session.scan_nodes["scan_full"]) == len(scene.scan_tiles["scan_full"]), what="full")
        assert sum(len(t.points) for k in ("scan_full", "ceiling_full") for t in scene.scan_tiles[k]) == len(scene.lod)
        tab.set_gui(session.ui_scan, "off")
        wait_for(lambda: not any(g.visible for g in session.scan_groups.values()), what="scan off")
        assert "scan_overview" not in session.wanted_scan_layers()
    finally:
        tab.close()


@pytest.mark.slow
def test_backend_rules(setup):
    backend, _, sp = setup
    alice, guest = backend.resolve_token("tok-alice"), backend.resolve_token("tok-guest")
    assert backend.resolve_token("nope") is None
    did = sp.detections["detections"][1]["id"]
    with pytest.raises(Forbidden):
        backend.decide(1, did, "accepted", None, 1, guest)
    backend.decide(1, did, "accepted", "switch", 1, alice)
    with pytest.raises(StaleVersion) as exc:
        backend.decide(1, did, "rejected", None, 1, alice)
    assert exc.value.current["review"]["version"] == 2 and exc.value.current["class"] == "switch"
    with pytest.raises(NotFound):
        backend.decide(1, "D9999", "accepted", None, 1, alice)
    with pytest.raises(NotFound):
        backend.project_data(99)
    ch = backend.changes_since(1, 0)
    assert [d["id"] for d in ch.detections] == [did] and not ch.locked
    backend.sign_off(1, alice)
    with pytest.raises(Locked):
        backend.decide(1, did, "rejected", None, 2, alice)


@pytest.mark.slow
def test_stale_decision_in_scene_refreshes(setup):
    backend, manager, sp = setup
    scene = manager.wait_ready(1, 30)
    tab = FakeTab(manager.viewer(1).port)
    try:
        session = wait_for(lambda: next(iter(scene.sessions.values()), None), what="session")
        session.sign_in("tok-alice")
        did = sp.detections["detections"][3]["id"]
        session.select(did, fly=False)
        scene.close()  # stop syncing so the scene still believes version 1
        backend.decide(1, did, "rejected", None, 1, backend.resolve_token("tok-boss"))
        assert session.decide("accepted") is None  # 409: refreshed, not overwritten
        assert scene.detections[did]["review"]["status"] == "rejected"
        assert backend.project_data(1).detections["detections"][3]["review"]["by"] == "boss"
    finally:
        tab.close()


@pytest.mark.slow
def test_projects_are_separate(project, tmp_path):
    out, sp = project
    out2 = write_synthetic_project(tmp_path / "p2", rooms=1, walls_per_room=1, objects_per_wall=1,
                                   points=2000, seed=3, origin=(0.0, 0.0, 0.0))
    backend = InMemoryBackend()
    backend.add_detection_dir(1, out, scans=[sp.scan])
    backend.add_detection_dir(2, out2.out_dir, scans=[out2.scan])
    manager = ViewerManager(backend, settings=FAST)
    try:
        u1, u2 = manager.url_for(1), manager.url_for(2)
        assert u1 != u2 and u1.startswith("http://127.0.0.1:")
        s1, s2 = manager.wait_ready(1, 30), manager.wait_ready(2, 30)
        assert set(s2.spots) == {"D0001"} and len(s1.spots) == 4
        assert s1.server is not s2.server
        tab = FakeTab(manager.viewer(2).port)
        try:
            wait_for(lambda: s2.sessions, what="session on project 2")
            assert not s1.sessions  # a tab on project 2 is not a client of project 1
        finally:
            tab.close()
        with pytest.raises(NotFound):
            manager.url_for(3)
        assert manager.running() == [1, 2]
    finally:
        manager.stop_all()
    assert manager.running() == []


@pytest.mark.slow
def test_wildcard_host_uses_request_host(project):
    out, sp = project
    backend = InMemoryBackend()
    backend.add_detection_dir(1, out)
    manager = ViewerManager(backend, host="0.0.0.0", settings=FAST)
    try:
        url = manager.url_for(1, request_host="review.example.org")
        assert url.startswith("http://review.example.org:") and url.endswith("/")
        assert manager.url_for(1).startswith("http://localhost:")
    finally:
        manager.stop_all()


def test_crops_and_textures(project):
    out, sp = project
    from app.viewer.images import WallImages, read_rgb, texture

    images = WallImages(out / "orthoimages", 0.005)
    d = sp.detections["detections"][0]
    wall = next(w for w in sp.detections["walls"] if w["id"] == d["wall"])
    full = read_rgb(out / "orthoimages" / f"{d['wall']}_colour.png")
    r = int((wall["height_m"] - d["v"]) / 0.005)
    c = int(d["u"] / 0.005)
    crop = images.crop(d["wall"], "colour", wall["height_m"], d["u"], d["v"], d["width_m"],
                       d["height_m"], 2.5, 0.25, 160)
    assert crop.shape == (160, 160, 3)
    assert np.abs(crop[80, 80].astype(int) - full[r, c]).max() <= 2  # the object in the middle
    assert tuple(crop[0, 0]) != tuple(full[r, c])
    assert images.image("W99", "colour") is None
    tex = texture(full, 0.005, 0.01, 2048)
    assert tex.shape[0] == full.shape[0] // 2 and tex.shape[1] == full.shape[1] // 2
