"""Defect 6: sessions emptied by --delete-source. Every archive format, alone, must be a full
source for the index, frames, analysis and export, with nothing dropped."""

from __future__ import annotations

import hashlib
import io
import json
from collections import Counter

import numpy as np
import pytest
from fastapi.testclient import TestClient
from mcap.reader import make_reader

from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.archive.archiver import archive_session
from thermcap.archive.reading.mcap_slice import export_mcap
from thermcap.recorder.analysis.offline import analyze_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.segments import SegmentPolicy

T0 = 1_800_000_000_000_000_000
N = 90


def _record(root):
    Recorder(SimSource(width=96, height=64, frames=N, paced=False, start_time_ns=T0, crossover=True,
                       first_cue_s=0.1, cue_period_s=0.5), root, session_id="s",
             policy=SegmentPolicy(max_duration_s=0.5), analysis=True, stats_interval_s=0.05).run()
    return root / "sessions" / "s"


def _all_messages(data: bytes) -> Counter:
    out: Counter = Counter()
    for _, ch, msg in make_reader(io.BytesIO(data)).iter_messages(log_time_order=False):
        out[(ch.topic, msg.log_time, hashlib.sha256(msg.data).hexdigest())] += 1
    return out


def _attachments(data: bytes) -> set:
    return {(a.name, hashlib.sha256(a.data).hexdigest()) for a in make_reader(io.BytesIO(data)).iter_attachments()}


@pytest.mark.parametrize("fmt", ["hdf5", "tiff-lzw", "png16", "jxl", "tpred"])
def test_each_format_alone_serves_indexes_analyses_and_exports_everything(tmp_path, fmt):
    session = _record(tmp_path)
    before = [(f.log_time, np.array(f.pixels), f.sidecar) for f in iter_session_frames(session)]
    export_before = b"".join(export_mcap(session, None, None, None))
    events_before = analyze_session(session)["events"]
    assert len(before) == N

    archive_session(session, [fmt], delete_source=True)
    assert not list(session.glob("*.mcap"))

    after = [(f.log_time, np.array(f.pixels), f.sidecar) for f in iter_session_frames(session)]
    assert len(after) == N
    for (t0, p0, s0), (t1, p1, s1) in zip(before, after, strict=True):
        assert t0 == t1
        assert np.array_equal(p0, p1)
        assert s0 == s1

    result = analyze_session(session)
    assert result["frames"] == N
    assert result["events"] == events_before
    assert json.loads((session / "events.json").read_text())["events"] == events_before

    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as c:
        row = c.get("/api/v1/sessions/s").json()
        assert row["frames"] == N
        for i in (0, N // 2, N - 1):
            r = c.get(f"/api/v1/sessions/s/frames/{i}", params={"format": "raw"})
            assert r.status_code == 200, r.text
            assert r.content == before[i][1].astype("<u2").tobytes()
            meta = c.get(f"/api/v1/sessions/s/frames/{i}/metadata")
            assert meta.status_code == 200
            assert meta.json() == json.loads(before[i][2])
        exported = c.get("/api/v1/sessions/s/export.mcap").content
    assert _all_messages(exported) == _all_messages(export_before)
    assert _attachments(exported) == _attachments(export_before)


def test_analyze_refuses_to_empty_events_when_no_frame_can_be_read(tmp_path):
    session = _record(tmp_path)
    analyze_session(session)
    events = (session / "events.json").read_bytes()
    archive_session(session, ["png16"], delete_source=True)
    import shutil

    shutil.rmtree(session / "archive" / "png16")  # the only copy is gone
    with pytest.raises(Exception) as exc:
        analyze_session(session)
    assert "frames" in str(exc.value)
    assert (session / "events.json").read_bytes() == events


def test_frames_read_back_from_an_archive_are_checked_and_skip_copies_marked_damaged(tmp_path):
    """Reading a session whose source is gone must never hand on damaged counts: a copy scrub
    marked damaged is passed over for a good one, and damage scrub has not seen yet is an error."""
    from thermcap.archive.exceptions import VerificationError
    from thermcap.archive.manifest import load_manifest, save_manifest

    session = _record(tmp_path)
    truth = [np.array(f.pixels) for f in iter_session_frames(session)]
    archive_session(session, ["hdf5", "png16"], delete_source=True)
    import h5py

    with h5py.File(session / "archive" / "hdf5" / "s.h5", "r+") as f:  # a silent change: one count, still valid
        f["frames"][5, 0, 0] ^= 1
    with pytest.raises(VerificationError, match="frame 5"):
        list(iter_session_frames(session))  # hdf5 is read first, and its damage is caught
    m = load_manifest(session)
    m["formats"]["hdf5"]["damaged"] = {"at": "now", "problems": ["frame 5"]}
    save_manifest(session, m)
    again = [np.array(f.pixels) for f in iter_session_frames(session)]  # png16 serves instead
    assert len(again) == len(truth)
    assert all(np.array_equal(a, b) for a, b in zip(again, truth, strict=True))
