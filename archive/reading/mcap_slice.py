"""A valid, indexed MCAP of one time range and some topics, streamed in constant memory.

From the MCAP source, chunks that lie wholly inside the range (and topic set) are copied byte
for byte with their message indexes, each checked against its CRC-32 first (decompressed, not
decoded); only the chunks at the range's edges are re-read message by message. A damaged
chunk stops the export with ``McapFileError`` naming it: never a copy of bytes that no longer
hold. When the source was deleted after archiving, the frames and
sidecars come from the archive instead.
"""

from __future__ import annotations

import contextlib
import hashlib
import heapq
import io
import json
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, cast

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Chunk, Message, MessageIndex
from mcap.stream_reader import breakup_chunk

from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.icd.rosmsg import SIDECAR
from thermcap.recorder.icd.topics import (
    IMAGE_SCHEMA_NAME,
    IMAGE_SCHEMA_TEXT,
    TOPIC_IMAGE,
    TOPIC_METADATA,
    image_message_parts,
)
from thermcap.recorder.storage.chunks import checked_chunk
from thermcap.recorder.storage.reader import session_segments
from thermcap.recorder.storage.writer import ChunkedWriter, Compression

__all__ = ["export_mcap", "unreadable_segments"]

_FLUSH_AT = 4 << 20


class _Sink(io.RawIOBase):
    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        data = b if isinstance(b, bytes) else bytes(b)  # a whole chunk copied from the source: no second copy
        self.parts.append(data)
        self.size += len(data)
        return len(data)

    def take(self) -> bytes:
        out = self.parts[0] if len(self.parts) == 1 else b"".join(self.parts)
        self.parts.clear()
        self.size = 0
        return out


def unreadable_segments(session_dir: Path) -> list[str]:
    """Each segment whose summary does not read (cut short, emptied), with why: checked before a
    byte of an export goes out, so a response is refused with its reason instead of stopping
    half way after a 200."""
    problems = []
    for seg in session_segments(session_dir) if session_dir.is_dir() else []:
        try:
            with open(seg, "rb") as f:
                summary = make_reader(f).get_summary()
            if summary is None:
                problems.append(f"{seg.name}: no summary")
        except (McapError, ValueError, struct.error, UnicodeDecodeError, MemoryError, OSError) as exc:
            problems.append(f"{seg.name}: its summary does not read ({type(exc).__name__}: {exc})")
    return problems


def export_mcap(session_dir: Path, start_ns: int | None, end_ns: int | None, topics: list[str] | None,
                frames_from_archive=None, extras_file: Callable[[], Any] | None = None) -> Iterator[bytes]:
    sink = _Sink()
    writer = ChunkedWriter(cast(BinaryIO, sink), compression=Compression.ZSTD, compression_level=1, workers=0)
    writer.start(profile="ros2", library="thermcap export")
    segs = session_segments(session_dir) if session_dir.is_dir() else []
    if segs:
        yield from _from_mcap(writer, sink, segs, start_ns, end_ns, topics)
    elif frames_from_archive is not None:
        yield from _from_archive(writer, sink, frames_from_archive, topics, start_ns, end_ns, extras_file)
    writer.finish()
    yield sink.take()


def _from_mcap(writer: ChunkedWriter, sink: _Sink, segs: list[Path], t0: int | None, t1: int | None,
               topics: list[str] | None) -> Iterator[bytes]:
    """Each source chunk is visited once: copied whole when it lies inside the range (and every
    channel is wanted under the same id), else decoded on its own and filtered message by
    message. Reading an edge chunk's *time window* through the reader instead would also return
    the neighbouring chunks' messages at the same times, and repeat them."""
    out_channels: dict[str, int] = {}
    out_schemas: dict[str, int] = {}
    kept = _Kept(writer)
    for seg in segs:
        with open(seg, "rb") as f:
            try:
                reader = make_reader(f, validate_crcs=True)
                summary = reader.get_summary()
            except (McapError, ValueError, struct.error, UnicodeDecodeError, MemoryError) as exc:
                raise McapFileError(f"{seg}: its summary does not read ({type(exc).__name__}: {exc})") from exc
            if summary is None:
                continue
            # Register this segment's schemas and channels in the output (same order, same ids).
            same_ids = True
            for cid in sorted(summary.channels):
                ch = summary.channels[cid]
                if topics and ch.topic not in topics:
                    same_ids = False
                    continue
                if ch.topic not in out_channels:
                    sc = summary.schemas.get(ch.schema_id)
                    key = sc.name if sc else ""
                    if sc and key not in out_schemas:
                        out_schemas[key] = writer.register_schema(sc.name, sc.encoding, sc.data)
                    out_channels[ch.topic] = writer.register_channel(ch.topic, ch.message_encoding,
                                                                     out_schemas.get(key, 0), ch.metadata)
                same_ids &= out_channels[ch.topic] == cid
            for rec in reader.iter_metadata():
                kept.metadata(rec.name, rec.metadata)
            for att in reader.iter_attachments():
                kept.attachment(att)
            wanted = {cid: out_channels[ch.topic] for cid, ch in summary.channels.items() if ch.topic in out_channels}
            for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
                if (t1 is not None and ci.message_start_time >= t1) or (t0 is not None and ci.message_end_time < t0):
                    continue
                inside = (t0 is None or ci.message_start_time >= t0) and (t1 is None or ci.message_end_time < t1)
                f.seek(ci.chunk_start_offset)
                where = f"{seg}: chunk at byte {ci.chunk_start_offset}"
                if inside and same_ids:
                    record = f.read(ci.chunk_length + ci.message_index_length)
                    # copied without decoding its messages, but never unchecked: a chunk whose
                    # records no longer match its CRC-32 stops the export, named
                    checked_chunk(memoryview(record)[:ci.chunk_length], where)
                    counts = {}
                    for cid, off in ci.message_index_offsets.items():
                        rel = off - ci.chunk_start_offset
                        stream = ReadDataStream(io.BytesIO(record[rel + 9:]))
                        counts[cid] = len(MessageIndex.read(stream).records)
                    writer.add_raw_chunk(record, ci, counts)
                else:
                    for msg in _chunk_messages(f.read(ci.chunk_length), where):
                        if msg.channel_id in wanted and (t0 is None or msg.log_time >= t0) \
                                and (t1 is None or msg.log_time < t1):
                            writer.add_message(wanted[msg.channel_id], msg.log_time, msg.data, msg.publish_time,
                                               msg.sequence)
                if sink.size >= _FLUSH_AT:
                    yield sink.take()
    writer.flush()


def _chunk_messages(record: bytes, where: str) -> list[Message]:
    """The messages of one chunk record (opcode and length included), in the order written."""
    try:
        chunk = Chunk.read(ReadDataStream(io.BytesIO(record[9:])))
        return [r for r in breakup_chunk(chunk, validate_crc=True) if isinstance(r, Message)]
    except Exception as exc:  # mcap and each codec raise their own types on damaged bytes
        raise McapFileError(f"{where}: does not read ({type(exc).__name__}: {exc})") from exc


class _Kept:
    """Metadata records and attachments, each written once however many segments repeat it
    (every segment carries the session record and the bad-pixel map so it stands alone)."""

    def __init__(self, writer: ChunkedWriter) -> None:
        self.writer = writer
        self.seen: set[tuple] = set()

    def metadata(self, name: str, metadata: dict[str, str]) -> None:
        key = ("m", name, tuple(sorted(metadata.items())))
        if key not in self.seen:
            self.seen.add(key)
            self.writer.add_metadata(name, dict(metadata))

    def attachment(self, att) -> None:
        key = ("a", att.name, hashlib.sha256(att.data).digest())
        if key not in self.seen:
            self.seen.add(key)
            self.writer.add_attachment(att.name, att.media_type, att.data, log_time=att.log_time,
                                       create_time=att.create_time)


def _from_archive(writer: ChunkedWriter, sink: _Sink, frames, topics: list[str] | None, t0: int | None,
                  t1: int | None, extras_file: Callable[[], Any] | None) -> Iterator[bytes]:
    """Images from the archive, everything else (sidecars as recorded, stats, cues, ground truth,
    importer metadata, attachments, metadata records) from extras.mcap, merged in time order:
    the same messages an export of the MCAP source gave, nothing dropped."""
    want_img = not topics or TOPIC_IMAGE in topics
    img = None
    if want_img:
        img = writer.register_channel(TOPIC_IMAGE, "cdr", writer.register_schema(IMAGE_SCHEMA_NAME, "ros2msg",
                                                                                  IMAGE_SCHEMA_TEXT.encode()))
    f = extras_file() if extras_file is not None else None
    stream: Iterator[tuple[int, int, Any]]
    with f if f is not None else contextlib.nullcontext():
        if f is not None:
            reader = make_reader(f, validate_crcs=True)
            kept = _Kept(writer)
            for rec in reader.iter_metadata():
                kept.metadata(rec.name, rec.metadata)
            for att in reader.iter_attachments():
                kept.attachment(att)
            images = ((t, 0, (idx, t, pixels)) for idx, t, pixels, _ in frames) if img is not None else iter(())
            stream = heapq.merge(images, _extras_messages(writer, reader, topics, t0, t1), key=lambda x: (x[0], x[1]))
        else:  # an archive from before extras.mcap: the sidecars come from the frames
            stream = _frame_messages(writer, frames, img, not topics or TOPIC_METADATA in topics)
        for t, kind, item in stream:
            if kind == 0:
                assert img is not None  # images are only yielded when the image topic is wanted
                idx, t, pixels = item
                writer.add_message(img, t, image_message_parts(pixels(), t), sequence=idx)
            else:
                channel, msg = item
                writer.add_message(channel, msg.log_time, msg.data, msg.publish_time, msg.sequence)
            if sink.size >= _FLUSH_AT:
                yield sink.take()
    writer.flush()


def _extras_messages(writer: ChunkedWriter, reader: Any, topics: list[str] | None, t0: int | None,
                     t1: int | None) -> Iterator[tuple[int, int, Any]]:
    channels: dict[int, int] = {}
    schemas: dict[int, int] = {}
    for schema, ch, msg in reader.iter_messages(log_time_order=True):
        if (topics and ch.topic not in topics) or ch.topic == TOPIC_IMAGE:
            continue
        if (t0 is not None and msg.log_time < t0) or (t1 is not None and msg.log_time >= t1):
            continue
        if ch.id not in channels:
            sid = 0
            if schema is not None:
                if schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                sid = schemas[schema.id]
            channels[ch.id] = writer.register_channel(ch.topic, ch.message_encoding, sid, dict(ch.metadata))
        yield msg.log_time, 1, (channels[ch.id], msg)


def _frame_messages(writer: ChunkedWriter, frames, img: int | None, want_meta: bool) -> Iterator[tuple[int, int, Any]]:
    """Old archives without extras.mcap: images and sidecars both from the frames."""
    meta = writer.register_channel(TOPIC_METADATA, "cdr", writer.register_schema(
        SIDECAR.name, "ros2msg", SIDECAR.text.encode())) if want_meta else None
    for idx, t, pixels, sidecar in frames:
        if img is not None:
            yield t, 0, (idx, t, pixels)
        if meta is not None:
            doc = sidecar()
            yield t, 1, (meta, _Msg(t, SIDECAR.encode(doc, json.dumps(doc, separators=(",", ":")).encode()), idx))


@dataclass
class _Msg:
    log_time: int
    data: bytes
    sequence: int = 0
    publish_time: int = 0

    def __post_init__(self) -> None:
        self.publish_time = self.publish_time or self.log_time
