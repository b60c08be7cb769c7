"""Issue 65, defect 11: one bit flipped in a closed segment's chunk opcode or length was a dead
end. The official reader read every frame (their CRCs hold, it finds chunks by the summary's
index); ``archive`` refused the chunk, ``recover SESSION`` said "nothing to recover" and
``recover SEG`` "file was complete", while the index served fewer frames and told the user to run
exactly that. Now a chunk whose record head disagrees with the summary's index is a damaged file,
and recover rewrites it from the index, every frame kept."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

import thermcap
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.recover import recover_path
from thermcap.recorder.storage.segments import SegmentPolicy


@pytest.fixture
def session(tmp_path):
    Recorder(SimSource(width=64, height=48, frames=60, paced=False, start_time_ns=1_700_000_000_000_000_000),
             tmp_path / "root", session_id="s", analysis=False,
             policy=SegmentPolicy(max_duration_s=0.5, chunk_size=16 << 10)).run()
    return tmp_path / "root" / "sessions" / "s"


@pytest.mark.parametrize("field", ["opcode", "length"])
def test_a_flipped_chunk_head_is_recovered_with_every_frame(session, field):
    truth = [(f.log_time, f.pixels.copy()) for f in iter_session_frames(session)]
    seg = sorted(session.glob("[0-9]*.mcap"))[1]
    with open(seg, "rb") as f:
        chunk = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)[1]
    raw = bytearray(seg.read_bytes())
    at = chunk.chunk_start_offset + (0 if field == "opcode" else 1)
    raw[at] ^= 0x10 if field == "opcode" else 0x01
    seg.write_bytes(bytes(raw))
    assert len(thermcap.open(session)) < len(truth)  # the chunk's frames are hidden until it is repaired

    results = recover_path(session)
    assert any(r.source.endswith(seg.name) and r.stopped_because != "file was complete" for r in results), \
        [(r.source, r.stopped_because) for r in results]
    got = [(f.log_time, f.pixels) for f in iter_session_frames(session)]
    assert len(got) == len(truth)
    assert all(t == u and np.array_equal(a, b) for (t, a), (u, b) in zip(got, truth, strict=True))
    opened = thermcap.open(session)
    assert len(opened) == len(truth) and np.array_equal(opened.counts(len(truth) // 2), truth[len(truth) // 2][1])
    archive_session(session, ["png16"])  # the archiver takes it now
