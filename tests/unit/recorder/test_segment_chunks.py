"""``recorder.storage.chunks``: a frame out of a closed segment by its chunk index. It must give
exactly the messages mcap's own reader gives at every time, whatever the chunk compression, and
know a replaced file from the one it indexed."""

from __future__ import annotations

import os
import shutil
from collections import defaultdict
from pathlib import Path

import pytest
from mcap.reader import make_reader

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.chunks import SegmentIndex, messages_at, read_chunk
from thermcap.recorder.storage.segments import SegmentPolicy
from thermcap.recorder.storage.writer import Compression


def small_chunk_session(tmp_path: Path, compression: Compression, seed: int = 3, frames: int = 40) -> Path:
    """A one-segment session of 64x48 frames in chunks of about eight frames' messages."""
    sim = SimSource(width=64, height=48, frames=frames, paced=False, seed=seed)
    res = Recorder(sim, tmp_path, session_id=f"c{seed}", analysis=False, recover_leftovers=False,
                   policy=SegmentPolicy(compression=compression, chunk_size=64 * 1024)).run()
    assert res.ok, res.problems
    (seg,) = sorted(tmp_path.glob(f"sessions/c{seed}/*.mcap"))
    return seg


def _by_time(seg: Path) -> dict[int, list[tuple[int, bytes]]]:
    out: dict[int, list[tuple[int, bytes]]] = defaultdict(list)
    with open(seg, "rb") as f:
        for _, channel, message in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False):
            out[message.log_time].append((channel.id, bytes(message.data)))
    return out


@pytest.mark.parametrize("compression", list(Compression))
def test_the_messages_at_every_time_are_the_ones_mcap_reads(tmp_path, compression):
    seg = small_chunk_session(tmp_path, compression)
    index = SegmentIndex.load(seg)
    assert index is not None and len(index.offsets) > 4, "the test wants many chunks"
    channels = set(index.channels)
    expected = _by_time(seg)
    assert len(expected) >= 40
    for t, messages in expected.items():
        got = [(ch, bytes(data)) for c in index.chunks_at(t)
               for ch, data in messages_at(read_chunk(index, c), t, channels)]
        assert sorted(got) == sorted(messages), t
    image = index.topics["/thermal/image"]
    t = min(expected)
    assert [ch for c in index.chunks_at(t) for ch, _ in messages_at(read_chunk(index, c), t, {image})] == [image]


def test_a_replaced_file_is_not_the_one_indexed(tmp_path):
    seg = small_chunk_session(tmp_path / "a", Compression.ZSTD)
    other = small_chunk_session(tmp_path / "b", Compression.ZSTD, seed=4, frames=30)
    index = SegmentIndex.load(seg)
    assert index.is_current()
    shutil.copyfile(other, seg)
    os.utime(seg, ns=(index.mtime_ns + 10**9, index.mtime_ns + 10**9))
    assert not index.is_current()
    seg.unlink()
    assert not index.is_current()


def test_a_chunk_read_through_a_stale_index_is_refused_as_stale_not_as_damage(tmp_path):
    from thermcap.recorder.storage.chunks import StaleIndexError

    seg = small_chunk_session(tmp_path / "a", Compression.ZSTD)
    other = small_chunk_session(tmp_path / "b", Compression.ZSTD, seed=4, frames=30)
    index = SegmentIndex.load(seg)
    assert read_chunk(index, 0).where == f"{seg}: chunk at byte {int(index.offsets[0])}"
    shutil.copyfile(other, seg)
    os.utime(seg, ns=(index.mtime_ns + 10**9, index.mtime_ns + 10**9))
    with pytest.raises(StaleIndexError, match=seg.name):
        read_chunk(index, 0)


def _mcap_order(seg: Path, topics: list[str] | None = None) -> list[tuple[int, int, int, int, bytes]]:
    with open(seg, "rb") as f:
        return [(m.channel_id, m.sequence, m.log_time, m.publish_time, bytes(m.data))
                for _, _, m in make_reader(f, validate_crcs=True).iter_messages(topics=topics)]


def _ours(messages) -> list[tuple[int, int, int, int, bytes]]:
    return [(m.channel_id, m.sequence, m.log_time, m.publish_time, bytes(m.data)) for m in messages]


@pytest.mark.parametrize("compression", list(Compression))
def test_iter_messages_is_mcaps_log_time_order_message_for_message(tmp_path, compression):
    from thermcap.recorder.storage.chunks import iter_messages

    seg = small_chunk_session(tmp_path, compression)
    index = SegmentIndex.load(seg)
    assert index is not None and len(index.offsets) > 4 and index.chunks_in_time_order
    assert _ours(iter_messages(index)) == _mcap_order(seg)
    wanted = {index.topics["/thermal/image"], index.topics["/thermal/metadata"]}
    assert _ours(iter_messages(index, wanted)) == _mcap_order(seg, ["/thermal/image", "/thermal/metadata"])


def _hand_written(path: Path, chunks: list[list[tuple[int, int]]]) -> Path:
    """An MCAP whose chunks hold the given (channel number, log time) messages in that order."""
    from mcap.writer import CompressionType, Writer

    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD, chunk_size=1 << 30)
        w.start()
        schema = w.register_schema("s", "jsonschema", b"{}")
        ids = [w.register_channel(f"/t{k}", "json", schema) for k in range(2)]
        seq = 0
        for chunk in chunks:
            for ch, t in chunk:
                w.add_message(ids[ch], t, f'{{"seq":{seq}}}'.encode(), t + 1, seq)
                seq += 1
            w.flush()  # closes the chunk here
        w.finish()
    return path


def test_messages_out_of_order_inside_chunks_come_out_as_mcap_orders_them(tmp_path):
    from thermcap.recorder.storage.chunks import iter_messages
    from thermcap.recorder.storage.reader import _segment_messages

    seg = _hand_written(tmp_path / "unsorted.mcap",
                        [[(0, 5), (1, 3), (0, 3), (1, 4), (0, 5)], [(0, 9), (1, 7), (1, 9)]])
    index = SegmentIndex.load(seg)
    assert index is not None and len(index.offsets) == 2 and index.chunks_in_time_order
    assert _ours(iter_messages(index)) == _mcap_order(seg)
    assert [(c.topic, *_ours([m])) for _, c, m in _segment_messages(seg, None)] == \
        [(index.channels[m[0]].topic, m) for m in _mcap_order(seg)]
    assert [m[2] for m in _mcap_order(seg)] == [3, 3, 4, 5, 5, 7, 9, 9]


def test_overlapping_chunks_are_read_through_mcaps_reader_in_its_order(tmp_path):
    from thermcap.recorder.storage.chunks import iter_messages
    from thermcap.recorder.storage.reader import _segment_messages

    seg = _hand_written(tmp_path / "overlap.mcap", [[(0, 1), (1, 8)], [(0, 4), (1, 6)], [(0, 2)]])
    index = SegmentIndex.load(seg)
    assert index is not None and not index.chunks_in_time_order
    with pytest.raises(ValueError, match="overlap"):
        next(iter_messages(index))
    assert [_ours([m])[0] for _, _, m in _segment_messages(seg, None)] == _mcap_order(seg)
    assert [m[2] for m in _mcap_order(seg)] == [1, 2, 4, 6, 8]


@pytest.mark.parametrize("tail, says", [
    (b"\x05" + (3).to_bytes(8, "little") + b"abc", "too short"),  # a message record shorter than its header
    (b"\x05\x00\x00", "bytes after its last record"),  # a cut record header
    (b"\x05" + (99).to_bytes(8, "little") + b"x" * 10, "runs past their end"),
])
def test_records_that_do_not_frame_are_refused_naming_the_chunk(tail, says):
    """A chunk's CRC-32 only proves its bytes are the ones written; records that do not add up
    (a writer's bug) are refused by both readers, naming where, never read as messages."""
    import struct

    from thermcap.recorder.storage.chunks import ChunkRecords

    good = b"\x05" + struct.pack("<Q", 22 + 4) + struct.pack("<HIQQ", 1, 0, 7, 7) + b"data"
    records = ChunkRecords(good + tail, "seg.mcap: chunk at byte 123")
    assert [bytes(d) for _, d in messages_at(ChunkRecords(good, "x"), 7, {1})] == [b"data"]
    with pytest.raises(McapFileError, match=f"seg.mcap: chunk at byte 123: .*{says}"):
        list(messages_at(records, 7, {1}))


def _two_channel_writer(path: Path):
    from thermcap.recorder.storage.writer import ChunkedWriter

    w = ChunkedWriter(path, compression=Compression.NONE, chunk_size=1 << 20, workers=0)
    w.start()
    sid = w.register_schema("s", "jsonschema", b"{}")
    return w, w.register_channel("/a", "json", sid), w.register_channel("/b", "json", sid)


def test_a_batch_of_messages_is_byte_for_byte_the_messages_one_by_one(tmp_path):
    """add_messages (a frame's messages at once) writes exactly what add_message does for each,
    out-of-order times included, and returns each payload's length."""
    one, a1, b1 = _two_channel_writer(tmp_path / "one.mcap")
    batch, a2, b2 = _two_channel_writer(tmp_path / "batch.mcap")
    for t in (30, 10, 20, 20):
        for cid, data, seq in [(a1, b"image", t), (b1, [b"pa", memoryview(b"rts")], 0), (a1, bytearray(b"x" * t), 7)]:
            one.add_message(cid, t, data, sequence=seq)
        msgs = [(a2, b"image", t), (b2, [b"pa", memoryview(b"rts")], 0), (a2, bytearray(b"x" * t), 7)]
        assert batch.add_messages(t, msgs) == [5, 5, t]
    one.finish()
    batch.finish()
    assert (tmp_path / "one.mcap").read_bytes() == (tmp_path / "batch.mcap").read_bytes()


def test_a_batch_with_an_unknown_channel_is_refused_whole(tmp_path):
    w, a, _b = _two_channel_writer(tmp_path / "w.mcap")
    w.add_message(a, 1, b"kept")
    with pytest.raises(ValueError, match="unknown channel id 99"):
        w.add_messages(2, [(a, b"not kept", 0), (99, b"?", 0)])
    w.finish()
    with open(tmp_path / "w.mcap", "rb") as f:
        reader = make_reader(f)
        assert [(m.log_time, m.data) for _, _, m in reader.iter_messages()] == [(1, b"kept")]
        assert reader.get_summary().statistics.message_count == 1


def test_a_frames_messages_share_one_chunk(tmp_path):
    """The chunk closes after a batch, never between a frame's image and its sidecar: one
    decompression serves both."""
    from thermcap.recorder.storage.writer import ChunkedWriter

    w = ChunkedWriter(tmp_path / "w.mcap", compression=Compression.NONE, chunk_size=64, workers=0)
    w.start()
    sid = w.register_schema("s", "jsonschema", b"{}")
    image, sidecar = w.register_channel("/image", "json", sid), w.register_channel("/meta", "json", sid)
    for t in range(5):
        w.add_messages(t, [(image, b"i" * 100, t), (sidecar, b"s" * 10, t)])
    w.finish()
    index = SegmentIndex.load(tmp_path / "w.mcap")
    assert index is not None and len(index.offsets) == 5
    with open(tmp_path / "w.mcap", "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert [sorted(c.message_index_offsets) for c in chunks] == [[image, sidecar]] * 5
