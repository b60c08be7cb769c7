"""Issue 65: one reader of verified copies. A frame whose first copy is damaged is served from
another intact copy, through every route that reads pixels; it never answers 500 while a good
copy exists, and the damage is named on /healthz."""

from __future__ import annotations

import httpx
import numpy as np
import pytest

from tests.conftest import ApiServer
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.segments import SegmentPolicy

W, H = 96, 64


@pytest.fixture
def truncated_png16(tmp_path):
    """png16 and tiff-lzw copies, the source deleted, then png16/0000.zip cut to half its length."""
    Recorder(SimSource(width=W, height=H, frames=30, paced=False, start_time_ns=1_800_000_000_000_000_000),
             tmp_path, session_id="s", analysis=False, policy=SegmentPolicy(max_duration_s=0.15)).run()
    session = tmp_path / "sessions" / "s"
    want = [f.pixels.copy() for f in iter_session_frames(session)]
    archive_session(session, ["png16", "tiff-lzw"], delete_source=True)
    first = sorted((session / "archive" / "png16").glob("*.zip"))[0]
    with open(first, "r+b") as f:
        f.truncate(first.stat().st_size // 2)
    server = ApiServer(tmp_path)
    yield server, want
    server.stop()


def test_a_truncated_copy_beside_an_intact_one_is_never_a_500(truncated_png16):
    server, want = truncated_png16
    base = f"{server.url}/api/v1/sessions/s"
    with httpx.Client(timeout=60) as c:
        for n in (0, 1, len(want) - 1):
            raw = c.get(f"{base}/frames/{n}", params={"format": "raw"})
            assert raw.status_code == 200, (n, raw.status_code, raw.text[:300])
            assert np.array_equal(np.frombuffer(raw.content, "<u2").reshape(H, W), want[n])
            for fmt in ("png16", "preview", "tiff"):
                r = c.get(f"{base}/frames/{n}", params={"format": fmt})
                assert r.status_code == 200, (n, fmt, r.status_code, r.text[:300])
        health = c.get(f"{server.url}/healthz").json()
        assert health["status"] == "degraded", health


def test_one_numbering_when_a_kept_segment_loses_its_summary(tmp_path):
    """Defect 1: archived to hdf5 with the source kept, the middle segment cut short. The index
    numbered its rows over the readable segments while pixels came from the archive by the
    manifest's number: frames served under other frames' times. One numbering, the manifest's:
    every frame listed at its own time with its own pixels."""
    Recorder(SimSource(width=W, height=H, frames=30, paced=False, start_time_ns=1_800_000_000_000_000_000),
             tmp_path, session_id="s", analysis=False, policy=SegmentPolicy(max_duration_s=0.15)).run()
    session = tmp_path / "sessions" / "s"
    frames = list(iter_session_frames(session))
    want = [f.pixels.copy() for f in frames]
    times = [f.log_time for f in frames]
    archive_session(session, ["hdf5"])
    segments = sorted(session.glob("*.mcap"))
    assert len(segments) >= 3
    middle = segments[len(segments) // 2]
    with open(middle, "r+b") as f:
        f.truncate(middle.stat().st_size - 200)  # its summary and footer gone
    server = ApiServer(tmp_path)
    try:
        base = f"{server.url}/api/v1/sessions/s"
        with httpx.Client(timeout=60) as c:
            meta = c.get(base).json()
            assert meta["frames"] == len(want), meta
            listed = c.get(f"{base}/frames", params={"limit": 1000}).json()["items"]
            assert [i["timestamp_ns"] for i in listed] == times
            for n in range(len(want)):
                raw = c.get(f"{base}/frames/{n}", params={"format": "raw"})
                assert raw.status_code == 200, (n, raw.text[:300])
                assert np.array_equal(np.frombuffer(raw.content, "<u2").reshape(H, W), want[n]), n
                assert c.get(f"{base}/frames/{n}/metadata").json()["capture"]["frame_index"] == n
    finally:
        server.stop()
