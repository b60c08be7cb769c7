"""A session of several cameras goes all the way: ``split-cameras`` makes one bit-exact session
per camera, the worker splits and archives them by itself, the index serves them, and nothing
reads the session of several as if it had one camera (which would find no frame)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from thermcap.api.db import make_engine, migrate
from thermcap.api.indexing import index_root
from thermcap.api.jobs.dask_jobs import DaskJobs, TaskConfig
from thermcap.api.jobs.worker import Worker
from thermcap.archive.verify import verify_session
from thermcap.cli import cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource
from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta
from thermcap.recorder.storage.segments import SegmentPolicy
from thermcap.recorder.storage.split import split_cameras


def _record(root, session="mc"):
    cams = {"front": SimSource(width=64, height=48, fps=30, frames=24, paced=False, seed=1, start_time_ns=10**18),
            "mast": SimSource(width=32, height=24, fps=15, frames=12, paced=False, seed=2, start_time_ns=10**18)}
    rec = Recorder(cams, root, session_id=session, analysis=False, policy=SegmentPolicy(max_duration_s=0.3))
    rec.mark("deer")
    assert rec.run().ok
    return rec.session_dir


def _hashes(session_dir, camera=None):
    return [(f.log_time, hashlib.sha256(np.ascontiguousarray(f.pixels).tobytes()).hexdigest(),
             hashlib.sha256(f.sidecar).hexdigest()) for f in iter_session_frames(session_dir, camera)]


def test_split_cameras_makes_bit_exact_single_camera_sessions(tmp_path):
    d = _record(tmp_path)
    before = {c: _hashes(d, c) for c in ("front", "mast")}
    assert len(list(d.glob("*.mcap"))) > 1
    res = split_cameras(d)
    assert res.frames == {"front": 24, "mast": 12}
    for cam in ("front", "mast"):
        out = tmp_path / "sessions" / f"mc.{cam}"
        assert _hashes(out) == before[cam]  # pixels, sidecar bytes and times, in order
        meta = read_session_meta(out)
        assert meta["camera"] == cam and meta["split_from"] == "mc" and "cameras" not in meta
        with open(next(out.glob("*.mcap")), "rb") as f:
            topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
        assert {"/thermal/image", "/thermal/metadata", "/recorder/events"} <= topics
        assert not any(t.startswith("/thermal/front") or t.startswith("/thermal/mast") for t in topics)
        events = json.loads((out / "events.json").read_text())["events"]
        assert any(e.get("note") == "deer" for e in events)
    again = split_cameras(d)  # idempotent
    assert sorted(again.already) == ["front", "mast"]
    assert again.frames == {"front": 24, "mast": 12}  # counted again without decoding the copies
    with pytest.raises(ThermcapError, match="one camera"):
        split_cameras(tmp_path / "sessions" / "mc.front")


def test_the_worker_splits_archives_and_indexes_a_session_of_several_cameras(tmp_path):
    d = _record(tmp_path)
    before = {c: _hashes(d, c) for c in ("front", "mast")}
    engine = make_engine(f"sqlite:///{tmp_path / 'index.db'}")
    migrate(engine)
    w = Worker(tmp_path, engine, formats=["png16"], delete_source=True, log=lambda m: None)
    jobs = DaskJobs(w, TaskConfig(str(tmp_path), ("png16",), f"sqlite:///{tmp_path / 'index.db'}", None, True),
                    local_workers=2, processes=False)
    res = jobs.run_once()
    assert res.split == {"mc": ["mc.front", "mc.mast"]}, res
    assert sorted(res.archived) == ["mc.front", "mc.mast"], res
    assert not list(d.glob("*.mcap"))  # the session's own segments went once both copies compared equal
    for cam in ("front", "mast"):
        out = tmp_path / "sessions" / f"mc.{cam}"
        assert not list(out.glob("*.mcap"))  # archived, verified, source deleted
        assert _hashes(out) == before[cam]  # now read from the archive
        checks = verify_session(out)
        assert checks and all(c.ok for c in checks.values()), checks
    report = index_root(engine, tmp_path)
    assert "mc" in report.skipped and "several cameras" in report.skipped["mc"]
    assert jobs.run_once().archived == []  # nothing left to do
    jobs.close()


def test_split_cameras_cli(tmp_path):
    _record(tmp_path)
    r = CliRunner().invoke(cli, ["split-cameras", "mc", "--root", str(tmp_path), "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["frames"] == {"front": 24, "mast": 12}
    r = CliRunner().invoke(cli, ["split-cameras", "nope", "--root", str(tmp_path)])
    assert r.exit_code == 1 and "nope: no such session" in r.output
