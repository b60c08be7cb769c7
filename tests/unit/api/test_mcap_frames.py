"""Frames of a session not archived yet come from its segment's chunks, kept in memory between
requests within a byte budget: neighbouring frames read their chunk once, memory stays bounded,
a replaced segment is read anew, and a damaged chunk is refused."""

from __future__ import annotations

import os
import shutil

import pytest

from tests.unit.recorder.test_segment_chunks import small_chunk_session
from thermcap.archive.reading.mcap_frames import McapFrames
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.chunks import SegmentIndex
from thermcap.recorder.storage.reader import iter_segment_frames
from thermcap.recorder.storage.writer import Compression


@pytest.fixture
def segment(tmp_path):
    return small_chunk_session(tmp_path, Compression.ZSTD)


def test_every_frame_is_the_recorded_one_and_each_chunk_is_read_once(segment):
    frames = list(iter_segment_frames(segment))
    index = SegmentIndex.load(segment)
    chunks = {c for f in frames for c in index.chunks_at(f.log_time)}
    assert len(chunks) > 4
    source = McapFrames()
    for _ in range(2):  # the second pass is served from memory
        for f in frames:
            pixels, sidecar = source.frame(segment, f.log_time)
            assert pixels.tobytes() == f.pixels.tobytes() and pixels.flags.writeable
            assert sidecar == f.sidecar
    assert source.chunk_reads == len(chunks)


def test_the_chunks_kept_stay_within_their_budget(segment):
    frames = list(iter_segment_frames(segment))
    index = SegmentIndex.load(segment)
    budget = int(2.5 * max(index.lengths))  # the records of about two chunks
    source = McapFrames(max_chunk_bytes=budget)
    for f in frames + frames[::-1]:
        assert source.frame(segment, f.log_time)[0].tobytes() == f.pixels.tobytes()
        assert source.kept_bytes <= budget
    assert source.chunk_reads > len({c for f in frames for c in index.chunks_at(f.log_time)})


def test_a_replaced_segment_is_read_anew(tmp_path, segment):
    source = McapFrames()
    first = next(iter_segment_frames(segment))
    assert source.frame(segment, first.log_time)[0].tobytes() == first.pixels.tobytes()
    other = small_chunk_session(tmp_path / "other", Compression.ZSTD, seed=9, frames=20)
    shutil.copyfile(other, segment)
    st = os.stat(segment)
    os.utime(segment, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    now = next(iter_segment_frames(segment))
    assert source.frame(segment, now.log_time)[0].tobytes() == now.pixels.tobytes()
    assert source.frame(segment, first.log_time) == (None, None)  # that time is not in the new file


def test_a_damaged_chunk_is_refused_naming_the_segment(segment):
    first = next(iter_segment_frames(segment))
    index = SegmentIndex.load(segment)
    (chunk,) = index.chunks_at(first.log_time)
    raw = bytearray(segment.read_bytes())
    raw[int(index.offsets[chunk] + index.lengths[chunk]) - 100] ^= 0xFF  # inside its compressed records
    segment.write_bytes(bytes(raw))
    with pytest.raises(McapFileError, match=segment.name):
        McapFrames().frame(segment, first.log_time)


def test_a_segment_without_chunks_is_read_through(tmp_path, segment):
    """An MCAP written without chunks (so its summary indexes none) is scanned instead."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    flat = tmp_path / "flat.mcap"
    with open(segment, "rb") as src, open(flat, "wb") as out:
        writer = Writer(out, use_chunking=False)
        writer.start()
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(src).iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas.get(channel.schema_id, 0))
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time)
        writer.finish()
    assert SegmentIndex.load(flat) is None
    frames = list(iter_segment_frames(segment))
    source = McapFrames()
    for f in frames[::7]:
        pixels, sidecar = source.frame(flat, f.log_time)
        assert pixels.tobytes() == f.pixels.tobytes() and sidecar == f.sidecar
    assert source.chunk_reads == 0


def test_a_segment_replaced_between_the_check_and_the_read_is_indexed_again(tmp_path, segment, monkeypatch):
    """The race: the kept index still looked current when the request checked it, and the file
    was replaced before its chunk was read. The frame comes from the new file; no damage."""
    source = McapFrames()
    first = next(iter_segment_frames(segment))
    source.frame(segment, first.log_time)
    other = small_chunk_session(tmp_path / "other", Compression.ZSTD, seed=9, frames=20)
    shutil.copyfile(other, segment)
    st = os.stat(segment)
    os.utime(segment, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    checks = iter([True])  # the first check, made before the file changed, passes
    real = SegmentIndex.is_current
    monkeypatch.setattr(SegmentIndex, "is_current", lambda self: next(checks, None) or real(self))
    now = next(iter_segment_frames(segment))
    pixels, sidecar = source.frame(segment, now.log_time)
    assert pixels.tobytes() == now.pixels.tobytes() and sidecar == now.sidecar
