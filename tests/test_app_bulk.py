"""Bulk decisions in bounded batches (issue 30): each batch its own short write transaction,
the result and the audit trail as of one request, decisions made between batches respected."""

from __future__ import annotations

import contextlib

import pytest
from sqlalchemy import select

from app import bulk
from app.auth import Principal, create_user
from app.config import AppSettings
from app.db import Database, upgrade
from app.errors import Locked
from app.models import DetectionRow, Project, ReviewDecision
from app.review_service import Change, Filter, decide
from app.sample import ensure_sample_project

from .app_support import _fake_output, write_small_ply


@pytest.fixture()
def project(tmp_path):
    settings = AppSettings(data_dir=tmp_path / "d", viewer=False)
    _fake_output(tmp_path / "out", 12, lambda s, f: None, 0.0)
    pid = ensure_sample_project(write_small_ply(tmp_path / "scan.ply", n=100), tmp_path / "out", settings=settings)
    db = Database(settings.db_url)
    upgrade(db)
    with db.write() as s:
        u = create_user(s, "rita", "reviewer")[0]
        user = Principal(u.id, u.name, u.role)
        ids = list(s.scalars(select(DetectionRow.id).where(DetectionRow.project_id == pid).order_by(DetectionRow.id)))
    yield db, pid, user, ids
    db.dispose()


class CountingWrites:
    """``db.write`` that counts its transactions and runs ``after(n)`` after the n-th one."""

    def __init__(self, db: Database, after=None) -> None:  # noqa: ANN001
        self.db, self.after, self.n, self.inner = db, after, 0, db.write

    @contextlib.contextmanager
    def __call__(self):  # noqa: ANN204
        with self.inner() as s:
            yield s
        self.n += 1
        if self.after:
            self.after(self.n)


def test_bulk_writes_in_batches_and_reads_as_one_request(project, monkeypatch):
    db, pid, user, ids = project
    late = ids[-1]

    def meanwhile(n: int) -> None:  # another reviewer accepts the last one after the first batch
        if n == 1:
            with db.inner_write() as s:
                decide(s, late, Change(version=1, status="accepted"), user)

    db.inner_write = db.write
    writes = CountingWrites(db, meanwhile)
    monkeypatch.setattr(db, "write", writes)
    out = bulk.bulk_decide(db, pid, "accepted", user, ids=[*ids, "x", ids[0], 10**9], batch_size=5)
    assert writes.n == 3  # 12 detections in batches of 5: three short transactions, not one long one
    assert out["matched"] == 12 and out["changed"] == 11 and out["ids"] == [str(d) for d in ids[:-1]]
    assert out["skipped"] == [{"id": "x", "reason": "not a detection id"},
                              {"id": str(10**9), "reason": "not found in this project"},
                              {"id": str(late), "reason": "already accepted"}]
    with db.read() as s:
        rows = list(s.scalars(select(ReviewDecision).where(ReviewDecision.batch == out["batch"])))
        assert len(rows) == 11 and len({r.at for r in rows}) == 1  # one batch id, one time
        assert all(r.before["status"] == "pending" and r.after["status"] == "accepted"
                   and (r.version_from, r.version_to) == (1, 2) and r.user_name == "rita" for r in rows)
        assert {d.status for d in s.scalars(select(DetectionRow).where(DetectionRow.project_id == pid))} == {"accepted"}
        assert s.scalar(select(DetectionRow.version).where(DetectionRow.id == late)) == 2  # decided once


def test_bulk_by_filter_dry_run_expect_and_lock(project):
    db, pid, user, ids = project
    dry = bulk.bulk_decide(db, pid, "rejected", user, flt=Filter(), dry_run=True)
    assert dry["matched"] == 12 and dry["changed"] == 0 and dry["batch"] is None
    with pytest.raises(bulk.Conflict):
        bulk.bulk_decide(db, pid, "rejected", user, flt=Filter(), expect=11)
    out = bulk.bulk_decide(db, pid, "rejected", user, flt=Filter(), expect=12, batch_size=4)
    assert out["changed"] == 12 and len(out["ids"]) == 12
    with db.write() as s:
        s.get(Project, pid).status = "signed_off"
    with pytest.raises(Locked):
        bulk.bulk_decide(db, pid, "pending", user, ids=ids)
