"""Review that closes the loop (issue 14), through a real server process and its REST API.

Objects added by a reviewer, bulk decisions by filter with the confirmed count, suggestions
(possible misses) promoted, jobs that keep the decisions on what they find again, job
cancellation and the one-queued-job cap, sign-off and reopening, the review summary.
"""

from __future__ import annotations

import time

import httpx
import numpy as np
import pytest

from app.snap import snap_to_relief

from .app_support import (
    auth,
    fake_control,
    pid_alive,
    project_with_job,
    wait_job,
    worker_pid,
)

RUNNER = "tests.app_support:fake_with_suggestions"




@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    from .app_support import server_with_users

    server = server_with_users(tmp_path_factory.mktemp("review_loop"),
                               [("rita", "reviewer"), ("max", "manager"), ("ada", "admin")],
                               {"SBSC_JOB_RUNNER": RUNNER, "SBSC_VIEWER": "0"})
    fake_control(server.data, delay_s=0.2, detections=8)
    yield server
    server.stop()


@pytest.fixture()
def c(srv):
    with httpx.Client(base_url=srv.url, timeout=60) as client:
        yield client


def project(c: httpx.Client, srv, name: str) -> tuple[int, dict]:  # noqa: ANN001
    pid = project_with_job(c, srv, name)
    return pid, c.get(f"/api/projects/{pid}/detections", headers=auth(srv.tokens["rita"])).json()


def test_snap_moves_a_click_onto_the_relief_of_the_model():
    px, h_m = 0.005, 1.0
    depth = np.zeros((200, 300), np.float32)
    depth[:, :5] = np.nan
    tpl = np.zeros((16, 16), np.float32)
    tpl[3:13, 3:13] = 0.01
    tpl[6:10, 6:10] = 0.02
    depth[100:116, 150:166] = tpl  # object centre: row 107.5, col 157.5
    true_u, true_v = (157.5 + 0.5) * px, h_m - (107.5 + 0.5) * px
    s = snap_to_relief(depth, px, h_m, tpl, u=true_u + 0.04, v=true_v - 0.03)
    assert s.snapped and s.rho > 0.95
    assert (s.u, s.v) == pytest.approx((true_u, true_v), abs=1e-6)
    # nothing there within the radius: the click stays
    s = snap_to_relief(depth, px, h_m, tpl, u=0.2, v=0.2)
    assert not s.snapped and (s.u, s.v) == (0.2, 0.2)


@pytest.mark.slow
def test_add_a_missed_object_and_bulk_accept_by_filter(c, srv):
    pid, doc = project(c, srv, "add_bulk")
    rita = auth(srv.tokens["rita"])
    # add as the pages do: 201, source reviewer, pending until confirmed, in the series of references, audited
    r = c.post(f"/api/projects/{pid}/detections", headers=rita,
               json={"class": "switch", "wall": "W01", "u": 2.2, "v": 1.4, "note": "behind the door",
                     "status": "pending"})
    assert r.status_code == 201, r.text
    added = r.json()
    assert added["source"] == "reviewer" and added["class"] == "switch" and added["wall"] == "W01"
    assert added["review"]["status"] == "pending" and added["review"]["by"] == "rita"
    refs = sorted(d["ref"] for d in doc["detections"])
    assert added["ref"] == f"D{int(refs[-1][1:]) + 1:04d}", (added["ref"], refs[-1])
    r = c.patch(f"/api/detections/{added['id']}", headers=rita,
                json={"status": "accepted", "version": added["review"]["version"]})  # confirmed
    assert r.status_code == 200 and r.json()["review"]["status"] == "accepted"
    assert added["note"] == "behind the door" and added["alpha"] is None
    wall = next(w for w in doc["walls"] if w["id"] == "W01")
    expect = [o + added["u"] * a + added["v"] * b
              for o, a, b in zip(wall["origin"], wall["axis_u"], wall["axis_v"], strict=True)]
    assert added["position"] == pytest.approx(expect)
    hist = c.get(f"/api/detections/{added['id']}/history", headers=rita).json()
    assert [h["action"] for h in hist] == ["add", "accept"] and hist[0]["by"] == "rita"
    for bad, word in (({"class": "nope", "wall": "W01", "u": 1, "v": 1}, "class"),
                      ({"class": "switch", "wall": "W99", "u": 1, "v": 1}, "wall"),
                      ({"class": "switch", "wall": "W01", "u": 40, "v": 1}, "outside")):
        r = c.post(f"/api/projects/{pid}/detections", headers=rita, json=bad)
        assert r.status_code == 422 and word in r.json()["detail"], r.text
    # uncertain first
    listed = c.get(f"/api/projects/{pid}/detections?order=uncertain&status=pending", headers=rita).json()
    alphas = [d["alpha"] for d in listed["detections"]]
    assert alphas == sorted(alphas) and len(alphas) == 8
    # bulk by filter: the dry run states the count, a stale count is refused, then decided
    threshold = float(np.median(alphas))
    n = sum(a >= threshold for a in alphas)
    body = {"status": "accepted", "filter": {"min_confidence": threshold, "review": "pending"}}
    r = c.post(f"/api/projects/{pid}/decisions", headers=rita, json={**body, "dry_run": True})
    assert r.status_code == 200 and r.json()["matched"] == n and r.json()["changed"] == 0
    r = c.post(f"/api/projects/{pid}/decisions", headers=rita, json={**body, "expect": n + 1})
    assert r.status_code == 409 and "changed" in r.json()["detail"]
    r = c.post(f"/api/projects/{pid}/decisions", headers=rita, json={**body, "expect": n})
    assert r.status_code == 200 and r.json()["changed"] == n, r.text
    batch = r.json()["batch"]
    after = c.get(f"/api/projects/{pid}/detections", headers=rita).json()["detections"]
    accepted = [d for d in after if d["source"] != "reviewer" and d["review"]["status"] == "accepted"]
    assert len(accepted) == n and all(d["alpha"] >= threshold for d in accepted)
    trail = c.get(f"/api/projects/{pid}/decisions", headers=rita).json()
    assert sum(t["action"] == "accept" and t["detection"] != added["id"] for t in trail) == n
    assert {d["id"] for d in accepted} == {t["detection"] for t in trail
                                           if t["action"] == "accept" and t["detection"] != added["id"]}
    # bulk by ids: already decided ones are skipped with a reason
    pending = [d["id"] for d in after if d["review"]["status"] == "pending"]
    r = c.post(f"/api/projects/{pid}/decisions", headers=rita,
               json={"status": "accepted", "ids": [pending[0], accepted[0]["id"], "999999"]})
    assert r.status_code == 200 and r.json()["changed"] == 1
    assert {s["reason"] for s in r.json()["skipped"]} == {"already accepted", "not found in this project"}
    assert c.post(f"/api/projects/{pid}/decisions", headers=rita, json={"status": "accepted"}).status_code == 422
    # the summary
    summ = c.get(f"/api/projects/{pid}/summary", headers=rita).json()
    assert summ["added"] == 1 and summ["bulk"] == n + 1 and summ["bulk_batches"] == 2
    assert summ["single"] == 2 and summ["decisions"] == n + 3 and summ["per_minute"] > 0
    assert batch


@pytest.mark.slow
def test_promote_a_suggestion(c, srv):
    pid, _ = project(c, srv, "suggest")
    rita = auth(srv.tokens["rita"])
    sugg = c.get(f"/api/projects/{pid}/suggestions", headers=rita).json()
    assert [(s["class"], s["wall"]) for s in sugg] == [("switch", "W01"), ("socket_x1", "W02")]
    r = c.post(f"/api/suggestions/{sugg[0]['id']}/promote", headers=rita)
    assert r.status_code == 201, r.text
    det = r.json()
    assert det["source"] == "reviewer" and det["class"] == "switch" and det["review"]["status"] == "accepted"
    assert (det["u"], det["v"]) == (3.5, 1.1)
    assert c.post(f"/api/suggestions/{sugg[0]['id']}/promote", headers=rita).status_code == 409
    left = c.get(f"/api/projects/{pid}/suggestions", headers=rita).json()
    assert [s["id"] for s in left] == [sugg[1]["id"]]
    hist = c.get(f"/api/detections/{det['id']}/history", headers=rita).json()
    assert hist[0]["action"] == "promote"


@pytest.mark.slow
def test_a_second_job_keeps_decisions_cancel_and_cap(c, srv):
    pid, doc = project(c, srv, "rerun")
    rita, boss = auth(srv.tokens["rita"]), auth(srv.tokens["max"])
    dets = doc["detections"]
    decided = {}
    for d, status in zip(dets[:4], ("accepted", "rejected", "accepted", "rejected"), strict=False):
        r = c.patch(f"/api/detections/{d['id']}", json={"status": status, "version": 1}, headers=rita)
        assert r.status_code == 200
        decided[d["ref"]] = status
    r = c.patch(f"/api/detections/{dets[4]['id']}", json={"status": "accepted", "class": "socket_x4",
                                                           "version": 1}, headers=rita)
    assert r.status_code == 200
    added = c.post(f"/api/projects/{pid}/detections", headers=rita,
                   json={"class": "switch", "wall": "W02", "u": 2.7, "v": 2.0, "snap": False}).json()
    assert added["review"]["status"] == "accepted"  # a script's addition (contract 7): accepted at once
    # a reviewer may not replace reviewed results; a manager may
    assert c.post(f"/api/projects/{pid}/jobs", json={}, headers=rita).status_code == 403
    fake_control(srv.data_dir, delay_s=2.0, detections=8)
    j1 = c.post(f"/api/projects/{pid}/jobs", json={}, headers=boss)
    assert j1.status_code == 202
    wait_job(c, j1.json()["id"], srv.tokens["max"], until=("running", "succeeded", "failed"))
    j2 = c.post(f"/api/projects/{pid}/jobs", json={}, headers=boss)
    assert j2.status_code == 202 and j2.json()["status"] == "queued"
    r = c.post(f"/api/projects/{pid}/jobs", json={}, headers=boss)
    assert r.status_code == 409 and "queued" in r.json()["detail"]
    # cancel the queued one (manager only)
    assert c.delete(f"/api/jobs/{j2.json()['id']}", headers=rita).status_code == 403
    r = c.delete(f"/api/jobs/{j2.json()['id']}", headers=boss)
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    assert c.delete(f"/api/jobs/{j2.json()['id']}", headers=boss).status_code == 409
    job = wait_job(c, j1.json()["id"], srv.tokens["max"])
    assert job["status"] == "succeeded"
    fake_control(srv.data_dir, delay_s=0.2, detections=8)
    new = c.get(f"/api/projects/{pid}/detections", headers=rita).json()
    assert new["job"] == j1.json()["id"]
    by_ref = {d["ref"]: d for d in new["detections"]}
    for ref, status in decided.items():  # every decision on an object found again carried over
        assert by_ref[ref]["review"]["status"] == status and by_ref[ref]["carried_from"]
        assert by_ref[ref]["review"]["by"] == "rita"
    relabelled = by_ref[dets[4]["ref"]]
    assert relabelled["class"] == "socket_x4" and relabelled["review"]["status"] == "accepted"
    kept = [d for d in new["detections"] if d["source"] == "reviewer"]
    assert len(kept) == 1 and kept[0]["u"] == added["u"] and kept[0]["review"]["status"] == "accepted"
    assert len({d["ref"] for d in new["detections"]}) == len(new["detections"])  # references stay unique
    pending = [d for d in new["detections"] if d["review"]["status"] == "pending"]
    assert len(pending) == 8 - 5
    hist = c.get(f"/api/detections/{relabelled['id']}/history", headers=rita).json()
    assert [h["action"] for h in hist] == ["carry"]
    events = c.get(f"/api/projects/{pid}/events", headers=rita).json()
    carry = [e for e in events if e["kind"] == "carry_over"][-1]
    assert carry["data"]["carried"] == 5 and carry["data"]["added_kept"] == 1
    assert any(e["kind"] == "job_cancelled" for e in events)
    # cancel a running job: its worker stops, the results stay those of the last job
    fake_control(srv.data_dir, delay_s=30.0, detections=8)
    j3 = c.post(f"/api/projects/{pid}/jobs", json={}, headers=boss).json()
    running = wait_job(c, j3["id"], srv.tokens["max"], until=("running",))
    assert "worker_pid" not in running  # no process ids in the API: read it from the database
    deadline = time.monotonic() + 10
    while not worker_pid(srv.data_dir, j3["id"]) and time.monotonic() < deadline:
        time.sleep(0.1)
    wpid = worker_pid(srv.data_dir, j3["id"])
    assert wpid
    r = c.delete(f"/api/jobs/{j3['id']}", headers=boss)
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    deadline = time.monotonic() + 15
    while pid_alive(wpid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not pid_alive(wpid)
    fake_control(srv.data_dir, delay_s=0.2, detections=8)
    final = c.get(f"/api/projects/{pid}/detections", headers=rita)
    assert final.status_code == 200 and final.json()["job"] == j1.json()["id"], final.text[:300]


@pytest.mark.slow
def test_signoff_then_admin_reopens_with_a_reason(c, srv):
    pid, _ = project(c, srv, "reopen")
    rita, boss, ada = auth(srv.tokens["rita"]), auth(srv.tokens["max"]), auth(srv.tokens["ada"])
    r = c.post(f"/api/projects/{pid}/decisions", headers=rita,
               json={"status": "accepted", "filter": {"review": "pending"}})
    assert r.json()["changed"] == 8
    assert c.post(f"/api/projects/{pid}/signoff", json={"comment": "first"}, headers=boss).status_code == 200
    d = c.get(f"/api/projects/{pid}/detections", headers=rita).json()["detections"][0]
    assert c.patch(f"/api/detections/{d['id']}", json={"status": "rejected", "version": 2},
                   headers=rita).status_code == 423
    assert c.post(f"/api/projects/{pid}/reopen", json={"reason": "wrong floor"}, headers=boss).status_code == 403
    assert c.post(f"/api/projects/{pid}/reopen", json={"reason": ""}, headers=ada).status_code == 422
    r = c.post(f"/api/projects/{pid}/reopen", json={"reason": "socket behind the radiator"}, headers=ada)
    assert r.status_code == 200 and r.json()["status"] == "open"
    assert c.post(f"/api/projects/{pid}/reopen", json={"reason": "again"}, headers=ada).status_code == 409
    assert c.get(f"/api/projects/{pid}/signoff", headers=rita).json()["signoff"] is None
    assert c.patch(f"/api/detections/{d['id']}", json={"status": "rejected", "version": 2},
                   headers=rita).status_code == 200
    r = c.post(f"/api/projects/{pid}/signoff", json={"comment": "second"}, headers=boss)
    assert r.status_code == 200 and r.json()["signoff"]["comment"] == "second"
    assert c.get(f"/api/projects/{pid}", headers=rita).json()["signoff"]["comment"] == "second"
    events = [e for e in c.get(f"/api/projects/{pid}/events", headers=rita).json()
              if not e["kind"].startswith("member_")]  # the test made max a member
    assert [e["kind"] for e in events] == ["signoff", "reopen", "signoff"]
    assert events[1]["by"] == "ada" and events[1]["comment"] == "socket behind the radiator"
    assert events[1]["data"]["signoff"]["comment"] == "first"


@pytest.mark.slow
def test_learn_exemplars_from_decisions(c, srv, tmp_path):
    import io
    import zipfile

    from sbsc_core.io.models import load_model_library

    pid, doc = project(c, srv, "learn")
    rita, boss = auth(srv.tokens["rita"]), auth(srv.tokens["max"])
    assert c.post(f"/api/projects/{pid}/exemplars", headers=boss).status_code == 409  # nothing accepted
    switches = [d for d in doc["detections"] if d["class"] == "switch"]
    for d in switches:
        assert c.patch(f"/api/detections/{d['id']}", json={"status": "accepted", "version": 1},
                       headers=rita).status_code == 200
    assert c.post(f"/api/projects/{pid}/exemplars", headers=rita).status_code == 403
    r = c.post(f"/api/projects/{pid}/exemplars", headers=boss)
    assert r.status_code == 201, r.text
    assert r.json()["views_added"] == {"switch": len(switches)}
    z = c.get(f"/api/projects/{pid}/exemplars.zip", headers=rita)
    assert z.status_code == 200
    with zipfile.ZipFile(io.BytesIO(z.content)) as zf:
        zf.extractall(tmp_path)
    lib = load_model_library(tmp_path / "models")
    views = lib.models["switch"].colour_views
    crop = views[-1]
    learnt = sorted(p.name for p in (tmp_path / "models" / "switch").glob("colour_1??.png"))
    assert learnt == ["colour_101.png"] and crop.shape[:2] == (16, 16)  # one median view; 0.08 m at 5 mm
    assert np.allclose(crop[4:12, 4:12, :3].reshape(-1, 3).mean(axis=0), (30, 30, 30), atol=3)
    relief = np.load(tmp_path / "models" / "switch" / "depth_101.npy")  # the learnt depth model
    assert np.nanmedian(relief) == pytest.approx(0.012, abs=1e-3)
    assert len(lib.models["switch"].extra_depths) == 1  # read as a further depth model
    # the next job uses the learnt library
    assert c.get(f"/api/projects/{pid}", headers=rita).json()["models"]["id"] == r.json()["library"]


@pytest.mark.slow
def test_relabel_means_accept_as_the_new_class_and_bulk_skips_relabelled(c, srv):
    """Issue 29: relabel is the same decision from every page (the gallery, the 3D scene, a
    script): the object is accepted as the new class; bulk decisions leave relabelled ones alone."""
    pid, doc = project(c, srv, "relabel")
    rita = auth(srv.tokens["rita"])
    det = doc["detections"][0]
    other = next(k for k in ("socket_x4", "switch", "socket_x1") if k != det["class"])
    r = c.patch(f"/api/detections/{det['id']}", headers=rita, json={"class": other, "version": 1})
    assert r.status_code == 200 and r.json()["class"] == other and r.json()["review"]["status"] == "accepted"
    hist = c.get(f"/api/detections/{det['id']}/history", headers=rita).json()
    assert [h["action"] for h in hist] == ["relabel+accept"]
    # reject everything accepted in bulk: the relabelled object is skipped, with its reason
    r = c.post(f"/api/projects/{pid}/decisions", headers=rita,
               json={"status": "rejected", "filter": {"review": "accepted"}})
    assert r.status_code == 200 and r.json()["changed"] == 0
    assert r.json()["skipped"] == [{"id": det["id"], "reason": "relabelled by a reviewer: decided one by one, "
                                                              "never in bulk"}]
    r = c.post(f"/api/projects/{pid}/decisions", headers=rita, json={"status": "rejected", "ids": [det["id"]]})
    assert r.json()["changed"] == 0 and "relabelled" in r.json()["skipped"][0]["reason"]
    now = c.get(f"/api/detections/{det['id']}", headers=rita).json()
    assert now["review"]["status"] == "accepted" and now["class"] == other
