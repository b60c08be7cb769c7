"""A chunked, indexed MCAP writer that compresses chunks on worker threads.

The stock ``mcap.writer.Writer`` compresses each chunk inside ``add_message``, so one thread
does all the work and reaches about 2x real time at 640x512@60 with zstd. Here the writer thread
only appends messages to a chunk buffer; full chunks go to a small thread pool for CRC and
compression (zstandard, lz4 and libdeflate's CRC-32 release the GIL, so both cores work), and come back
to be written to the file in order. The file is a standard MCAP: the records are mcap's own,
every chunk is followed by its message indexes, and ``finish()`` writes the usual summary.

Crash safety: each chunk is handed to the OS (an unbuffered file) as soon as it is compressed,
and chunks are closed after ``max_chunk_age_s`` even when not full, so a ``kill -9`` loses at
most the chunk in progress plus the ones still compressing (a fraction of a second).
Schema and channel records are written outside chunks, right after the header, so even a file
cut in its first chunk still tells a recovery tool what its channels were.
"""

from __future__ import annotations

import os
import struct
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, BinaryIO

import imagecodecs
import lz4.frame
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from thermcap.recorder import __version__

__all__ = ["LEVELS", "LIBRARY", "MCAP_MAGIC", "ChunkedWriter", "Compression", "check_level"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
LIBRARY = f"thermcap/{__version__}"
_MSG_HEADER = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_MSG_FIXED = 2 + 4 + 8 + 8


class Compression(StrEnum):
    NONE = "none"
    LZ4 = "lz4"
    ZSTD = "zstd"

    @property
    def mcap_name(self) -> str:
        return "" if self is Compression.NONE else self.value


#: The levels each codec takes (zstd's negative "fast" levels are not offered).
LEVELS = {Compression.ZSTD: range(1, 23), Compression.LZ4: range(0, 17)}


def check_level(compression: Compression, level: int) -> int:
    """A compression level refused before the first frame (it had failed after 7)."""
    allowed = LEVELS.get(compression)
    if allowed is None:
        raise ValueError(f"--level {level}: no level applies to --compression {compression.value}")
    if level not in allowed:
        raise ValueError(f"--level {level}: {compression.value} takes levels {allowed.start}-{allowed.stop - 1}")
    return level


_tls = threading.local()


def _compress(kind: Compression, level: int, parts: list[Any]) -> tuple[bytes, int, int]:
    """Worker-thread job: join the chunk, compress it -> (compressed, mcap crc, size).

    Every chunk carries MCAP's CRC-32 of its uncompressed data, which every MCAP reader can
    check (ours all do), whatever the codec. It is libdeflate's CRC-32 (carry-less multiply,
    about 28 GB/s, 0.02 ms a 640x512 frame): zlib's runs at 5 GB/s, which is why chunks once
    carried the codec's own content checksum (xxhash, 0.04 ms a frame) and a CRC of 0 instead.
    The codecs' checksums are off: they would check the same bytes twice. One compressor per
    thread: sharing a ZstdCompressor across threads crashes the interpreter.
    """
    data = b"".join(parts)
    crc = imagecodecs.deflate_crc32(data)
    if kind is Compression.ZSTD:
        comp = getattr(_tls, "zstd", None)
        if comp is None or _tls.zstd_level != level:
            comp = _tls.zstd = zstandard.ZstdCompressor(level=level, write_checksum=False)
            _tls.zstd_level = level
        return comp.compress(data), crc, len(data)
    if kind is Compression.LZ4:
        return lz4.frame.compress(data, compression_level=max(0, level), content_checksum=False), crc, len(data)
    return data, crc, len(data)


@dataclass
class _OpenChunk:
    parts: list[Any] = field(default_factory=list)
    size: int = 0
    start_time: int = 0
    end_time: int = 0
    count: int = 0
    indexes: dict[int, list[tuple[int, int]]] = field(default_factory=dict)
    tokens: list[Any] = field(default_factory=list)
    opened_at: float = 0.0


@dataclass
class _PendingChunk:
    future: Future
    chunk: _OpenChunk


class ChunkedWriter:
    """Write an MCAP file; ``start()``, ``register_schema()``, ``register_channel()``,
    ``add_message()``, ``add_attachment()``, ``add_metadata()``, ``finish()`` as in mcap's Writer.

    :param output: a path (opened unbuffered, closed by ``finish``) or a binary stream.
    :param compression: chunk compression; zstd at a low level is the default.
    :param chunk_size: close a chunk once its uncompressed size passes this many bytes.
    :param max_chunk_age_s: close a chunk this long after its first message even if not full.
    :param workers: compression threads; 0 compresses inline on the calling thread.
    :param max_pending: chunks in flight at most (bounds memory); more makes ``add_message`` wait.
    :param on_chunk_written: called on the writer thread with the tokens given to ``add_message``
        once their chunk is in the OS's hands, e.g. to measure write latency.
    """

    def __init__(
        self,
        output: str | os.PathLike | BinaryIO,
        *,
        compression: Compression = Compression.ZSTD,
        compression_level: int = 1,
        chunk_size: int = 4 * 1024 * 1024,
        max_chunk_age_s: float = 0.25,
        workers: int = 2,
        max_pending: int = 6,
        executor: ThreadPoolExecutor | None = None,
        on_chunk_written: Callable[[list[Any]], None] | None = None,
    ) -> None:
        if isinstance(output, (str, os.PathLike)):
            self._stream: BinaryIO = open(output, "xb", buffering=0)  # noqa: SIM115 - owned, closed by close()
            self._owns_stream = True
        else:
            self._stream = output
            self._owns_stream = False
        self.compression = Compression(compression)
        self.compression_level = compression_level
        self.chunk_size = chunk_size
        self.max_chunk_age_s = max_chunk_age_s
        self.max_pending = max(1, max_pending)
        self._own_executor = executor is None and workers > 0
        self._executor = executor or (ThreadPoolExecutor(workers,
                                                         thread_name_prefix="mcap-compress") if workers > 0 else None)
        self._on_chunk_written = on_chunk_written
        self._pos = 0
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._channel_counts: dict[int, int] = {}
        self._message_count = 0
        self._start_time: int | None = None
        self._end_time = 0
        self._chunk = _OpenChunk()
        self._pending: deque[_PendingChunk] = deque()
        self._finished = False
        self.bytes_written = 0
        self.uncompressed_bytes = 0

    # -- low-level output -------------------------------------------------------------------
    def _write(self, *pieces: bytes | memoryview) -> None:
        for piece in pieces:
            view = memoryview(piece)
            while view.nbytes:
                n = self._stream.write(view)
                if n is None:  # a non-blocking stream that took nothing; unbuffered files return ints
                    n = 0
                view = view[n:]
                self._pos += n
        self.bytes_written = self._pos

    def _write_records(self, *records: Any) -> None:
        builder = RecordBuilder()
        for record in records:
            record.write(builder)
        self._write(builder.end())

    @property
    def position(self) -> int:
        return self._pos

    # -- the mcap Writer API ----------------------------------------------------------------
    def start(self, profile: str = "ros2", library: str = LIBRARY) -> None:
        self._write(MCAP_MAGIC)
        self._write_records(Header(profile=profile, library=library))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas[schema.id] = schema
        self._write_records(schema)
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata or {}))
        self._channels[channel.id] = channel
        self._channel_counts[channel.id] = 0
        self._write_records(channel)
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes | Iterable[Any],
                    publish_time: int | None = None, sequence: int = 0, token: Any = None) -> None:
        """Append a message; ``data`` may be bytes or a list of buffers (joined once, in the chunk)."""
        self.add_messages(log_time, [(channel_id, data, sequence)], publish_time=publish_time, token=token)

    def add_messages(self, log_time: int, messages: Sequence[tuple[int, Any, int]], *,
                     publish_time: int | None = None, token: Any = None) -> list[int]:
        """Append messages of one log time, each ``(channel id, data, sequence)``, in order;
        returns each one's payload length.

        Why a batch: a recorded frame is four messages or more (image, sidecar, marks, the
        source's own). They land in one chunk (the chunk closes after the batch, not between
        the image and its sidecar, so one decompression serves both), and the chunk's
        bookkeeping runs once a frame instead of once a message (a few microseconds)."""
        counts = self._channel_counts
        for channel_id, _, _ in messages:  # before anything changes: a refused batch leaves no trace
            if channel_id not in counts:
                raise ValueError(f"unknown channel id {channel_id}")
        chunk = self._chunk
        if chunk.count == 0:
            chunk.start_time = chunk.end_time = log_time
            chunk.opened_at = time.monotonic()
        elif log_time < chunk.start_time:
            chunk.start_time = log_time
        elif log_time > chunk.end_time:
            chunk.end_time = log_time
        publish = log_time if publish_time is None else publish_time
        parts, indexes = chunk.parts, chunk.indexes
        size = chunk.size
        lengths = []
        for channel_id, data, sequence in messages:
            if isinstance(data, (bytes, bytearray)):
                length = len(data)
                body: list[Any] = [data]
            else:
                body = [data] if isinstance(data, memoryview) else list(data)
                length = sum(memoryview(p).nbytes for p in body)
            index = indexes.get(channel_id)
            if index is None:
                index = indexes[channel_id] = []
            index.append((log_time, size))
            parts.append(_MSG_HEADER.pack(Opcode.MESSAGE, _MSG_FIXED + length, channel_id, sequence & 0xFFFFFFFF,
                                          log_time, publish))
            parts.extend(body)
            size += 9 + _MSG_FIXED + length
            counts[channel_id] += 1
            lengths.append(length)
        chunk.size = size
        chunk.count += len(lengths)
        if token is not None:
            chunk.tokens.append(token)
        self._message_count += len(lengths)
        if self._start_time is None or log_time < self._start_time:
            self._start_time = log_time
        if log_time > self._end_time:
            self._end_time = log_time
        if size >= self.chunk_size:
            self._close_chunk()
        if self._pending:
            self._drain(block=False)
        return lengths

    def poll(self) -> None:
        """Close an old chunk and write any compressed ones; call it when idle so data reaches disk."""
        if self._chunk.count and time.monotonic() - self._chunk.opened_at >= self.max_chunk_age_s:
            self._close_chunk()
        self._drain(block=False)

    def flush(self) -> None:
        """Close the open chunk and write everything compressed so far (no fsync)."""
        self._close_chunk()
        self._drain(block=True)

    def add_attachment(self, name: str, media_type: str, data: bytes, *, log_time: int = 0,
                       create_time: int = 0) -> None:
        self.flush()
        offset = self._pos
        attachment = Attachment(create_time=create_time, log_time=log_time, name=name, media_type=media_type, data=data)
        builder = RecordBuilder()
        attachment.write(builder)
        raw = builder.end()
        self._write(raw)
        self._attachment_indexes.append(AttachmentIndex(offset=offset, length=len(raw), create_time=create_time,
                                                        log_time=log_time, data_size=len(data), name=name,
                                                        media_type=media_type))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self.flush()
        offset = self._pos
        builder = RecordBuilder()
        Metadata(name=name, metadata=dict(data)).write(builder)
        raw = builder.end()
        self._write(raw)
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=len(raw), name=name))

    @property
    def pending_bytes(self) -> int:
        """Uncompressed bytes accepted but not yet written (the open chunk and those compressing)."""
        return self._chunk.size + sum(p.chunk.size for p in self._pending)

    @property
    def message_count(self) -> int:
        return self._message_count

    # -- chunks -----------------------------------------------------------------------------
    def _close_chunk(self) -> None:
        chunk = self._chunk
        if chunk.count == 0:
            return
        self._chunk = _OpenChunk()
        while len(self._pending) >= self.max_pending:
            self._write_chunk(self._pending.popleft())
        if self._executor is None:
            fut: Future = Future()
            fut.set_result(_compress(self.compression, self.compression_level, chunk.parts))
        else:
            fut = self._executor.submit(_compress, self.compression, self.compression_level, chunk.parts)
        chunk.parts = []  # the worker holds them now; drop ours so memory is freed when it is done
        self._pending.append(_PendingChunk(fut, chunk))

    def _drain(self, *, block: bool) -> None:
        while self._pending and (block or self._pending[0].future.done()):
            self._write_chunk(self._pending.popleft())

    def _write_chunk(self, pending: _PendingChunk) -> None:
        compressed, crc, size = pending.future.result()
        chunk = pending.chunk
        comp_name = self.compression.mcap_name.encode()
        body_len = 8 + 8 + 8 + 4 + 4 + len(comp_name) + 8 + len(compressed)
        start = self._pos
        head = struct.pack("<BQQQQI", Opcode.CHUNK, body_len, chunk.start_time, chunk.end_time, size, crc)
        head += struct.pack("<I", len(comp_name)) + comp_name + struct.pack("<Q", len(compressed))
        self._write(head, compressed)
        chunk_length = self._pos - start
        builder = RecordBuilder()
        offsets: dict[int, int] = {}
        for channel_id, records in chunk.indexes.items():
            offsets[channel_id] = self._pos + builder.count
            MessageIndex(channel_id=channel_id, records=records).write(builder)
        index_bytes = builder.end()
        self._write(index_bytes)
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=chunk.start_time, message_end_time=chunk.end_time, chunk_start_offset=start,
            chunk_length=chunk_length, message_index_offsets=offsets, message_index_length=len(index_bytes),
            compression=self.compression.mcap_name, compressed_size=len(compressed), uncompressed_size=size))
        self.uncompressed_bytes += size
        if self._on_chunk_written is not None and chunk.tokens:
            self._on_chunk_written(chunk.tokens)

    def add_raw_chunk(self, record: bytes, index: ChunkIndex, message_counts: dict[int, int]) -> None:
        """Copy a chunk record and the message indexes that follow it from another MCAP file,
        unchanged (no decompression): ``record`` starts at the chunk's opcode and includes its
        message index records; ``index`` is the source's ChunkIndex. Channel ids must mean the
        same in both files (the caller checks). This is what makes exports run at disk speed."""
        self.flush()
        start = self._pos
        self._write(record)
        offsets = {cid: start + (off - index.chunk_start_offset) for cid, off in index.message_index_offsets.items()}
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=index.message_start_time, message_end_time=index.message_end_time,
            chunk_start_offset=start, chunk_length=index.chunk_length, message_index_offsets=offsets,
            message_index_length=index.message_index_length, compression=index.compression,
            compressed_size=index.compressed_size, uncompressed_size=index.uncompressed_size))
        for cid, n in message_counts.items():
            self._channel_counts[cid] = self._channel_counts.get(cid, 0) + n
            self._message_count += n
        if message_counts:
            t0, t1 = index.message_start_time, index.message_end_time
            self._start_time = t0 if self._start_time is None else min(self._start_time, t0)
            self._end_time = max(self._end_time, t1)
        self.uncompressed_bytes += index.uncompressed_size

    # -- summary ----------------------------------------------------------------------------
    def finish(self, *, fsync: bool = False) -> None:
        """Write the remaining chunks, the indexes and the summary, then the closing magic;
        with ``fsync`` the file is on disk before this returns (and before any rename)."""
        if self._finished:
            return
        self.flush()
        self._write_records(DataEnd(data_section_crc=0))
        summary_start = self._pos
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: Iterable[Any]) -> None:
            begin = builder.count
            for record in records:
                record.write(builder)
            if builder.count > begin:
                offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + begin,
                                             group_length=builder.count - begin))

        stats = Statistics(
            message_count=self._message_count, schema_count=len(self._schemas), channel_count=len(self._channels),
            attachment_count=len(self._attachment_indexes), metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes), message_start_time=self._start_time or 0,
            message_end_time=self._end_time, channel_message_counts=dict(self._channel_counts))
        group(Opcode.SCHEMA, self._schemas.values())
        group(Opcode.CHANNEL, self._channels.values())
        group(Opcode.STATISTICS, [stats])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, self._attachment_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, summary_offset_start), crc)
        self._write(summary)
        self._write_records(Footer(summary_start=summary_start, summary_offset_start=summary_offset_start,
                                   summary_crc=crc))
        self._write(MCAP_MAGIC)
        self._finished = True
        if fsync:
            if hasattr(self._stream, "flush"):
                self._stream.flush()
            os.fsync(self._stream.fileno())
        self.close()

    def close(self) -> None:
        """Release threads and (if we opened it) the file, without writing a summary."""
        if self._own_executor and self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None
        if self._owns_stream and not self._stream.closed:
            self._stream.close()

    def fileno(self) -> int:
        return self._stream.fileno()
