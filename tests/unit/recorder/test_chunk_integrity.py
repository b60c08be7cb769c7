"""Every compressed chunk carries MCAP's CRC-32 of its uncompressed data, and every reader that
takes messages out of a chunk checks it: a changed byte that the codec still decodes (zstd
stores incompressible data as raw blocks) must never reach an archive as altered counts."""

from __future__ import annotations

import dataclasses
import zlib
from pathlib import Path

import numpy as np
import pytest
import zstandard
from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from thermcap.benches.record import MemorySource
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.reader import iter_segment_frames
from thermcap.recorder.storage.segments import SegmentPolicy
from thermcap.recorder.storage.writer import Compression


def _noise_session(tmp_path: Path, compression: Compression) -> Path:
    """A session of uniformly random 16-bit frames: zstd keeps them as raw blocks."""
    sim = SimSource(width=64, height=48, frames=4, paced=False, seed=3)
    rng = np.random.default_rng(7)
    frames = [dataclasses.replace(f, pixels=rng.integers(0, 65536, (48, 64), dtype=np.uint16))
              for f in sim.frames()]
    Recorder(MemorySource(sim, frames, len(frames)), tmp_path, session_id="n",
             policy=SegmentPolicy(compression=compression)).run()
    (seg,) = sorted(tmp_path.glob("**/*.mcap"))
    return seg


def _chunks(path: Path) -> list[Chunk]:
    with open(path, "rb") as f:
        return [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]


@pytest.mark.parametrize("compression", list(Compression))
def test_every_chunk_has_the_crc_of_its_uncompressed_data(tmp_path, compression):
    chunks = _chunks(_noise_session(tmp_path, compression))
    assert chunks
    for chunk in chunks:
        data = chunk.data
        if chunk.compression == "zstd":
            data = zstandard.ZstdDecompressor().decompress(data, max_output_size=chunk.uncompressed_size)
        elif chunk.compression == "lz4":
            import lz4.frame

            data = lz4.frame.decompress(data)
        assert chunk.uncompressed_crc != 0
        assert chunk.uncompressed_crc == zlib.crc32(data)


@pytest.mark.parametrize("compression", list(Compression))
def test_a_byte_changed_inside_a_chunk_is_refused_by_the_frame_reader(tmp_path, compression):
    seg = _noise_session(tmp_path, compression)
    before = [f.pixels.copy() for f in iter_segment_frames(seg)]
    raw = bytearray(seg.read_bytes())
    # the middle of the first image's pixels: inside the chunk's (raw-block) data
    at = raw.find(before[0][24].tobytes()[:32])
    assert at > 0, "the noise frame is stored verbatim inside the chunk"
    raw[at + 5] ^= 0x10
    seg.write_bytes(bytes(raw))
    with pytest.raises(McapFileError, match=seg.name):
        list(iter_segment_frames(seg))


@pytest.mark.parametrize("compression", list(Compression))
def test_a_byte_changed_inside_a_chunk_is_refused_by_the_chunk_reader(tmp_path, compression):
    from thermcap.recorder.storage.chunks import SegmentIndex, messages_at, read_chunk

    seg = _noise_session(tmp_path, compression)
    first = next(iter_segment_frames(seg))
    raw = bytearray(seg.read_bytes())
    at = raw.find(first.pixels[24].tobytes()[:32])
    assert at > 0
    raw[at + 5] ^= 0x10
    seg.write_bytes(bytes(raw))
    index = SegmentIndex.load(seg)  # the summary is intact: only the chunk's data changed
    assert index is not None
    chunk = next(c for c in range(len(index.offsets)) if index.offsets[c] < at < index.offsets[c] + index.lengths[c])
    with pytest.raises(McapFileError, match=f"{seg.name}: chunk at byte {index.offsets[chunk]}"):
        list(messages_at(read_chunk(index, chunk), first.log_time, set(index.channels)))
