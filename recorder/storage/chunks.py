"""One frame out of a closed segment without reading the rest: its chunk index, one chunk.

mcap's seeking reader parses a segment's whole summary on every open (about 6 ms for a 20 s
segment, three times that for a minute) and then every record of the chunk it wants in Python.
Serving one frame of a session that is not archived yet cost 15-18 ms that way. Here the summary
is read once into a ``SegmentIndex`` (a caller keeps it: a closed segment never changes), a frame
is one read of the chunk that holds its time, the chunk's CRC-32 is checked with libdeflate (ten
times zlib's speed) and only the record headers are walked to find the messages logged at that
time. A caller may keep decompressed chunks too (``read_chunk``'s result): frames next to each
other share one.

A chunk whose CRC-32 or framing does not hold raises ``McapFileError`` naming the file and the
chunk's offset: nothing from it is returned. A file that is no longer the one indexed (replaced
on disk between the index and the read) raises ``StaleIndexError`` instead, which is no damage:
the caller indexes the file again.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Container, Iterator
from dataclasses import dataclass
from functools import cached_property
from operator import itemgetter
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

import imagecodecs
import numpy as np
from mcap.reader import make_reader

from thermcap.recorder.exceptions import McapFileError

__all__ = [
    "ChunkRecords",
    "RawMessage",
    "SegmentIndex",
    "StaleIndexError",
    "checked_chunk",
    "frame_log_times",
    "iter_messages",
    "log_times_in",
    "message_records",
    "messages_at",
    "read_chunk",
    "read_through",
]

_CHUNK = 0x06
_MESSAGE = 0x05
_RECORD_HEAD = struct.Struct("<BQ")
_CHUNK_FIXED = struct.Struct("<QQQI")  # message start, message end, uncompressed size, uncompressed CRC
_MESSAGE_FIXED = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time


class StaleIndexError(McapFileError):
    """The file at the index's path is not the one it indexed."""


@dataclass(frozen=True)
class SegmentIndex:
    """What a closed segment's summary says about where its messages are."""

    path: Path
    size: int
    mtime_ns: int
    starts: np.ndarray  # int64 [chunks]: each chunk's first log time, in file order
    ends: np.ndarray  # int64 [chunks]: each chunk's last log time
    offsets: np.ndarray  # int64 [chunks]: where each chunk record starts
    lengths: np.ndarray  # int64 [chunks]: each chunk record's length
    channels: dict[int, Any]  # channel id -> the summary's mcap Channel record
    schemas: dict[int, Any]  # schema id -> the summary's mcap Schema record

    @classmethod
    def load(cls, path: str | Path) -> SegmentIndex | None:
        """The index of a segment whose summary lists its chunks; None where it lists none (an
        MCAP written without chunks or without a summary), which a caller reads through instead.
        A file whose summary cannot be read (cut short) raises ``McapFileError``."""
        path = Path(path)
        with open(path, "rb") as f:
            st = os.fstat(f.fileno())
            try:
                summary = make_reader(f).get_summary()
            except Exception as exc:  # mcap raises its own errors for a cut or foreign file
                raise McapFileError(f"{path}: no readable summary ({type(exc).__name__}: {exc})") from exc
        if summary is None or not summary.chunk_indexes:
            return None
        chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        return cls(path, st.st_size, st.st_mtime_ns,
                   np.array([c.message_start_time for c in chunks], np.int64),
                   np.array([c.message_end_time for c in chunks], np.int64),
                   np.array([c.chunk_start_offset for c in chunks], np.int64),
                   np.array([c.chunk_length for c in chunks], np.int64),
                   dict(summary.channels), dict(summary.schemas))

    @cached_property
    def topics(self) -> dict[str, int]:
        """topic -> channel id."""
        return {ch.topic: ch.id for ch in self.channels.values()}

    def is_current(self) -> bool:
        """False once the file on disk is not the one indexed (replaced, rewritten or gone)."""
        try:
            return self.describes(os.stat(self.path))
        except OSError:
            return False

    def describes(self, st: os.stat_result) -> bool:
        return (st.st_size, st.st_mtime_ns) == (self.size, self.mtime_ns)

    @property
    def chunks_in_time_order(self) -> bool:
        """True where no chunk's time span starts before the previous chunk's ends (in file
        order), as a recorder's segment is written: then reading the chunks one after another,
        each in time order, is reading the whole file in time order."""
        return bool(np.all(self.starts[1:] >= self.ends[:-1]))

    def chunks_at(self, log_time: int) -> list[int]:
        """The chunks whose time span holds ``log_time`` (more than one where spans overlap)."""
        hits = np.flatnonzero((self.starts <= log_time) & (self.ends >= log_time))
        return [int(i) for i in hits]


@dataclass(frozen=True)
class ChunkRecords:
    """One chunk's records, decompressed and CRC-checked: what a cache keeps."""

    data: bytes
    where: str  # "<file>: chunk at byte <offset>", for errors

    @property
    def nbytes(self) -> int:
        return len(self.data)


def read_chunk(index: SegmentIndex, chunk: int) -> ChunkRecords:
    """Chunk number ``chunk`` of the segment, its records decompressed and checked against the
    chunk's CRC-32 (where the writer set one, as every thermcap writer does)."""
    offset, length = int(index.offsets[chunk]), int(index.lengths[chunk])
    where = f"{index.path}: chunk at byte {offset}"
    with open(index.path, "rb") as f:
        if not index.describes(os.fstat(f.fileno())):
            raise StaleIndexError(f"{index.path} changed since it was indexed")
        raw = os.pread(f.fileno(), length, offset)
    if len(raw) != length:
        raise McapFileError(f"{where}: {len(raw)} of its {length} bytes are on disk")
    return checked_chunk(raw, where)


def checked_chunk(raw: bytes | memoryview, where: str) -> ChunkRecords:
    """A chunk record's bytes (opcode and length first), its records decompressed and checked
    against the chunk's CRC-32: the one check every path that hands a chunk on makes, whether
    it reads frames out of it or copies it whole (``thermcap cut``, ``export.mcap``). Raises
    ``McapFileError`` naming ``where`` for a chunk that does not hold."""
    length = len(raw)
    try:
        opcode, body_len = _RECORD_HEAD.unpack_from(raw, 0)
        _, _, size, crc = _CHUNK_FIXED.unpack_from(raw, 9)
        (name_len,) = struct.unpack_from("<I", raw, 37)
        compression = bytes(raw[41:41 + name_len]).decode()
        (records_len,) = struct.unpack_from("<Q", raw, 41 + name_len)
    except (struct.error, UnicodeDecodeError) as exc:
        raise McapFileError(f"{where}: not a chunk record ({exc})") from exc
    start = 49 + name_len
    if opcode != _CHUNK or 9 + body_len != length or start + records_len > length:
        raise McapFileError(f"{where}: not a chunk record the summary's index describes")
    payload = memoryview(raw)[start:start + records_len]
    try:
        if compression == "zstd":
            import zstandard

            data = zstandard.ZstdDecompressor().decompress(payload, max_output_size=size)
        elif compression == "lz4":
            import lz4.frame

            data = lz4.frame.decompress(payload)
        elif compression == "":
            data = bytes(payload)
        else:
            raise McapFileError(f"{where}: unknown compression {compression!r}")
    except McapFileError:
        raise
    except Exception as exc:  # each codec raises its own error type on damaged input
        raise McapFileError(f"{where}: does not decompress ({type(exc).__name__}: {exc})") from exc
    if len(data) != size:
        raise McapFileError(f"{where}: decompressed to {len(data)} bytes, the chunk says {size}")
    if crc and imagecodecs.deflate_crc32(data) != crc:
        raise McapFileError(f"{where}: CRC-32 of its records differs from the one recorded")
    return ChunkRecords(data, where)


def _message_records(records: ChunkRecords) -> Iterator[tuple[int, int, int, int, int, int]]:
    """(log time, channel, sequence, publish time, data start, data end) of every message record
    of the chunk, in its order, reading only record headers. A record that runs past the end, a
    message record too short for its header or bytes after the last record raise
    ``McapFileError`` naming the chunk."""
    data = records.data
    pos, end = 0, len(data)
    while pos + 9 <= end:
        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
        body = pos + 9
        if body + length > end:
            raise McapFileError(f"{records.where}: a record at byte {pos} of its records runs past their end")
        if opcode == _MESSAGE:
            if length < _MESSAGE_FIXED.size:
                raise McapFileError(f"{records.where}: a message record at byte {pos} is too short")
            channel, sequence, t, published = _MESSAGE_FIXED.unpack_from(data, body)
            yield t, channel, sequence, published, body + _MESSAGE_FIXED.size, body + length
        pos = body + length
    if pos != end:
        raise McapFileError(f"{records.where}: {end - pos} bytes after its last record")


def message_records(records: ChunkRecords) -> Iterator[tuple[int, int, int, int, int, int]]:
    """(log time, channel, sequence, publish time, data start, data stop) of each message record
    of a chunk, in the chunk's order: for readers that take one topic out of a chunk."""
    return _message_records(records)


def messages_at(records: ChunkRecords, log_time: int, channels: set[int]) -> Iterator[tuple[int, memoryview]]:
    """(channel id, message data) of every message of ``channels`` logged at ``log_time``, in the
    chunk's order."""
    view = memoryview(records.data)
    for t, channel, _, _, start, stop in _message_records(records):
        if t == log_time and channel in channels:
            yield channel, view[start:stop]


class RawMessage(NamedTuple):
    """A message as ``iter_messages`` gives it: the fields of mcap's ``Message``, its data a
    view into the chunk's decompressed records (no copy; it keeps that chunk alive)."""

    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: memoryview


def iter_messages(index: SegmentIndex, channels: Container[int] | None = None) -> Iterator[RawMessage]:
    """Every message of the segment (of ``channels``; all where None) in the order mcap's reader
    gives them in log-time order: by log time, then chunk, then place in the chunk. One chunk
    is decompressed at a time (each CRC-checked by ``read_chunk``) and only record headers are
    read. For the chunks of a segment as the recorder writes them (``chunks_in_time_order``);
    any other file raises ``ValueError`` and is read through mcap's reader instead.

    Why: archiving reads every message of the session once, and mcap's reader spent about
    0.45 ms of Python a 640x512 frame on it (a record object and a heap entry per message),
    holding the GIL the formats' threads wait for."""
    if not index.chunks_in_time_order:
        raise ValueError(f"{index.path}: chunks overlap in time; read it with mcap's reader")
    for chunk in range(len(index.offsets)):
        records = read_chunk(index, chunk)
        view = memoryview(records.data)
        found = [m for m in _message_records(records) if channels is None or m[1] in channels]
        if any(found[k][0] > found[k + 1][0] for k in range(len(found) - 1)):
            found.sort(key=itemgetter(0))  # stable: equal times keep their place in the chunk
        for t, channel, sequence, published, start, stop in found:
            yield RawMessage(channel, sequence, t, published, view[start:stop])


def read_through(path: str | Path, topics: list[str] | None = None) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) of a whole file through mcap's own reader, CRCs checked, for a
    segment with no usable chunk index (no summary, overlapping chunks, no chunk at all).

    Damaged bytes make mcap raise nearly anything (``EndOfFile``, ``InvalidMagic``,
    ``RecordLengthLimitExceeded``, ``UnicodeDecodeError``, ``MemoryError``); here each becomes
    ``McapFileError`` naming the file, which every caller treats as one damaged part, so one file
    can never hide the rest of its session. Messages before the damage are given first."""
    with open(path, "rb") as f:
        try:
            yield from make_reader(f, validate_crcs=True).iter_messages(topics=topics)
        except Exception as exc:
            raise McapFileError(f"{path}: cannot be read ({type(exc).__name__}: {exc})") from exc


_MESSAGE_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel id, records' byte length


def frame_log_times(path: str | Path, topics: Container[str]) -> list[int] | None:
    """The log time of every message on ``topics`` in a closed segment, from the message index
    records after each chunk (no chunk is decompressed), sorted; None where the segment has no
    chunk index or message indexes to read them from (a caller then does without)."""
    path = Path(path)
    with open(path, "rb") as f:
        try:
            summary = make_reader(f).get_summary()
        except Exception as exc:
            raise McapFileError(f"{path}: no readable summary ({type(exc).__name__}: {exc})") from exc
        return log_times_in(f, summary, topics)


def log_times_in(f: BinaryIO, summary: Any, topics: Container[str]) -> list[int] | None:
    """``frame_log_times`` for a segment already open, whose summary its caller has read."""
    if summary is None or not summary.chunk_indexes:
        return None
    wanted = {cid for cid, ch in summary.channels.items() if ch.topic in topics}
    times: list[int] = []
    for chunk in summary.chunk_indexes:
        for cid, offset in chunk.message_index_offsets.items():
            if cid not in wanted:
                continue
            f.seek(offset)
            head = f.read(_MESSAGE_INDEX_HEAD.size)
            if len(head) < _MESSAGE_INDEX_HEAD.size:
                return None
            opcode, _, channel, n = _MESSAGE_INDEX_HEAD.unpack(head)
            if opcode != 0x07 or channel != cid or n % 16:
                return None  # not the message index the chunk index points at
            pairs = np.frombuffer(f.read(n), "<u8")
            if pairs.size * 8 != n:
                return None
            times.extend(int(t) for t in pairs[0::2])
    return sorted(times)
