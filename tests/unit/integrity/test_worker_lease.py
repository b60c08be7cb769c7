"""Defect: a worker's lease had a fixed TTL and was never renewed, so a session whose archiving
took longer than the TTL (an hour-long session takes longer than 600 s) could be taken by a
second worker while the first was still on it. A worker now renews its lease while it works."""

from __future__ import annotations

import time

from api.db import make_engine, migrate
from api.jobs import worker as worker_mod
from api.jobs.worker import Worker, acquire_lease
from recorder.capture.recorder import Recorder
from recorder.capture.sources.sim import SimSource


def test_a_lease_is_kept_for_as_long_as_the_work_takes(tmp_path, monkeypatch):
    root = tmp_path / "root"
    Recorder(SimSource(width=64, height=48, frames=10, paced=False, seed=1), root, session_id="long",
             analysis=False, recover_leftovers=False).run()
    engine = make_engine(f"sqlite:///{tmp_path / 'index.sqlite'}")
    migrate(engine)
    real = worker_mod.archive_session
    stolen: list[bool] = []

    def slow_archive(*args, **kwargs):  # archiving that takes three lease lifetimes
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline:
            stolen.append(acquire_lease(engine, "long", "another-worker", 0.5))
            time.sleep(0.1)
        return real(*args, **kwargs)

    monkeypatch.setattr(worker_mod, "archive_session", slow_archive)
    w = Worker(root, engine, formats=["png16"], lease_ttl_s=0.5, owner="first-worker", log=lambda _: None)
    res = w.run_once()
    assert res.archived == ["long"] and not res.failed
    assert stolen and not any(stolen), "another worker took the lease while the first was archiving"
    assert acquire_lease(engine, "long", "another-worker", 0.5)  # released once done
