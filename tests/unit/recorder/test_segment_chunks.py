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

from recorder.capture.recorder import Recorder
from recorder.capture.sources.sim import SimSource
from recorder.storage.chunks import SegmentIndex, messages_at, read_chunk
from recorder.storage.segments import SegmentPolicy
from recorder.storage.writer import Compression


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
    channels = set(index.encodings)
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
    from recorder.storage.chunks import StaleIndexError

    seg = small_chunk_session(tmp_path / "a", Compression.ZSTD)
    other = small_chunk_session(tmp_path / "b", Compression.ZSTD, seed=4, frames=30)
    index = SegmentIndex.load(seg)
    assert read_chunk(index, 0).where == f"{seg}: chunk at byte {int(index.offsets[0])}"
    shutil.copyfile(other, seg)
    os.utime(seg, ns=(index.mtime_ns + 10**9, index.mtime_ns + 10**9))
    with pytest.raises(StaleIndexError, match=seg.name):
        read_chunk(index, 0)
