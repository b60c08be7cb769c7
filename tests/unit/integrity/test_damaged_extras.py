"""Issue 65, defect 13: one damaged chunk of ``extras.mcap`` hid a whole hdf5/tiff-lzw session
whose source was deleted (404, /healthz "ok"). The extras hold the low-rate topics and the
sidecars' second copy; the frames and their sidecars are in the archive formats themselves."""

from __future__ import annotations

import numpy as np
from fastapi.testclient import TestClient
from mcap.reader import make_reader

import thermcap
from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.segments import SegmentPolicy


def test_a_damaged_extras_chunk_hides_nothing(tmp_path):
    root = tmp_path / "root"
    Recorder(SimSource(width=64, height=48, frames=40, paced=False, seed=2, start_time_ns=1_700_000_000_000_000_000),
             root, session_id="s", analysis=False, policy=SegmentPolicy(max_duration_s=0.25)).run()
    session = root / "sessions" / "s"
    truth = [f.pixels.copy() for f in iter_session_frames(session)]
    archive_session(session, ["hdf5", "tiff-lzw"], delete_source=True)
    extras = session / "archive" / "extras.mcap"
    with open(extras, "rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[0]
    raw = bytearray(extras.read_bytes())
    raw[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0x40
    extras.write_bytes(bytes(raw))

    opened = thermcap.open(session)
    assert len(opened) == len(truth) and np.array_equal(opened.counts(7), truth[7])
    assert opened.sidecar(7)  # the sidecar from the archive format's own copy
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        r = c.get("/api/v1/sessions/s")
        assert r.status_code == 200 and r.json()["frames"] == len(truth), r.text
        frame = c.get("/api/v1/sessions/s/frames/7", params={"format": "raw"})
        assert frame.status_code == 200 and frame.content == truth[7].astype("<u2").tobytes()
        assert c.get("/api/v1/sessions/s/frames/7/metadata").status_code == 200
