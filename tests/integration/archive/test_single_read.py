"""Archiving reads its MCAP source once. Every chunk of the source is decompressed exactly once
while the default formats are written, hashed, checked and verified and the extras are kept:
it was four times (a hash scan, the formats' shared read, and two reads for the extras). The
count takes both ways a chunk is read: thermcap's chunk reader (``chunks.read_chunk``, what a
recorder's segment is read with) and mcap's (any other file)."""

from __future__ import annotations

from collections import Counter

import mcap.stream_reader

import thermcap.recorder.storage.chunks as recorder_chunks
from thermcap.archive.archiver import DEFAULT_FORMATS, archive_session
from thermcap.archive.extras import summarize_mcap
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import session_segments


def test_every_source_chunk_is_decompressed_once(tmp_path, monkeypatch):
    rec = Recorder(SimSource(width=640, height=512, frames=60, paced=False, seed=5), tmp_path, session_id="s",
                   analysis=True, recover_leftovers=False)
    assert rec.run().ok
    seen: Counter = Counter()
    real = mcap.stream_reader.get_chunk_data_stream
    ours = recorder_chunks.read_chunk

    def counting(chunk, validate_crc=False):
        seen[(chunk.message_start_time, chunk.message_end_time)] += 1
        return real(chunk, validate_crc)

    def counting_ours(index, chunk):
        seen[(int(index.starts[chunk]), int(index.ends[chunk]))] += 1
        return ours(index, chunk)

    monkeypatch.setattr(mcap.stream_reader, "get_chunk_data_stream", counting)
    monkeypatch.setattr(recorder_chunks, "read_chunk", counting_ours)
    before = summarize_mcap(session_segments(rec.session_dir))  # reads every source chunk once
    source_chunks = set(seen)
    assert len(source_chunks) > 3
    seen.clear()
    manifest = archive_session(rec.session_dir, DEFAULT_FORMATS)
    assert all(manifest["formats"][f]["verified"] for f in DEFAULT_FORMATS) and manifest["extras"]["verified"]
    assert {k: seen[k] for k in source_chunks} == dict.fromkeys(source_chunks, 1)
    assert manifest["extras"]["topics"] == before["topics"]
