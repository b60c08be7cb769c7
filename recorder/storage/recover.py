"""Turn an interrupted segment (``NNNN.mcap.active``) into a valid, indexed ``NNNN.mcap``.

A segment cut by ``kill -9`` or a power loss is a valid MCAP prefix: magic, header, schemas and
channels (written outside chunks for exactly this), then whole chunks, then perhaps a partial
record. We walk the records, keep every complete record whose chunk decompresses and checks out,
and stop at the first one that does not; everything before it is rewritten into a new file
with a fresh summary. The new file is fsynced and checked with the official mcap reader before
it takes the final name, and only then is the ``.active`` file removed.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.icd.topics import is_image_topic
from thermcap.recorder.storage.atomic import fsync_dir, write_json_atomic
from thermcap.recorder.storage.layout import SESSION_JSON, DataRoot, SessionLayout
from thermcap.recorder.storage.ledger import deletions
from thermcap.recorder.storage.lock import holder, lock_session
from thermcap.recorder.storage.reader import count_frames
from thermcap.recorder.storage.rosbag2 import write_bag_metadata
from thermcap.recorder.storage.segments import ACTIVE_SUFFIX
from thermcap.recorder.storage.writer import MCAP_MAGIC, ChunkedWriter, Compression

ORIGINAL_SUFFIX = ".orig"  # a repaired file's original, kept until the result reads back
UNREADABLE_SUFFIX = ".unreadable"  # an empty segment moved aside: it held no frame

__all__ = ["ORIGINAL_SUFFIX", "UNREADABLE_SUFFIX", "RecoveryResult", "durable_frames", "recover_leftovers",
           "recover_path", "recover_segment", "scan_records"]

_READERS = {
    Opcode.HEADER: Header, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
    Opcode.ATTACHMENT: Attachment, Opcode.METADATA: Metadata, Opcode.CHUNK: Chunk,
}


@dataclass
class RecoveryResult:
    source: str
    output: str
    messages: int = 0
    frames: int = 0
    chunks: int = 0
    bytes_kept: int = 0
    bytes_discarded: int = 0
    damaged_chunks: int = 0
    stopped_because: str = ""
    topics: dict[str, int] = field(default_factory=dict)
    skipped: bool = False  # a live process holds the session: nothing was touched

    def to_dict(self) -> dict:
        return self.__dict__.copy()


def scan_records(stream: BinaryIO, size: int, path: str,
                 chunks: dict[int, int] | None = None) -> Iterator[tuple[int, int, bytes]]:
    """Yield (offset, opcode, body) for every complete record; stop silently at a cut record.

    ``chunks`` (offset -> record length, from the summary's chunk index when it reads): a record
    starting where the index says a chunk starts is taken as that chunk, whatever its head says.
    A flipped bit in a chunk's opcode or length would otherwise end the walk there, losing every
    record after it; the chunk's own CRC still decides whether its content holds.

    Raises McapFileError only when the file is not an MCAP at all.
    """
    if stream.read(8) != MCAP_MAGIC:
        raise McapFileError(f"{path}: not an MCAP file (bad magic)")
    pos = 8
    chunks = chunks or {}
    while True:
        head = stream.read(9)
        if len(head) < 9:
            return
        opcode, length = struct.unpack("<BQ", head)
        if pos in chunks and chunks[pos] - 9 <= size - pos - 9:
            opcode, length = Opcode.CHUNK, chunks[pos] - 9
        if length > size - pos - 9:
            return
        body = stream.read(length)
        if len(body) < length:
            return
        yield pos, opcode, body
        pos += 9 + length


def _parse(opcode: int, body: bytes) -> Any:
    reader: Any = _READERS[Opcode(opcode)]
    return reader.read(ReadDataStream(io.BytesIO(body)))


def _is_complete(path: Path) -> bool:
    """Finished and intact: closing magic, a summary, every message readable (checksums
    included), and every chunk record's head what the summary's index says (mcap's reader finds
    chunks by the index alone; thermcap's own readers check the head, and refuse a chunk whose
    head disagrees). A finished file with a damaged chunk is not renamed as it is: it is rewritten."""
    try:
        with open(path, "rb") as f:
            f.seek(-8, os.SEEK_END)
            if f.read(8) != MCAP_MAGIC:
                return False
            f.seek(0)
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            n = sum(1 for _ in reader.iter_messages(log_time_order=False))
            if summary is None or summary.statistics is None or n != summary.statistics.message_count:
                return False
            for c in summary.chunk_indexes:
                f.seek(c.chunk_start_offset)
                opcode, length = struct.unpack("<BQ", f.read(9))
                if opcode != Opcode.CHUNK or 9 + length != c.chunk_length:
                    return False
        return True
    except Exception:
        return False


def _indexed_chunks(path: Path) -> dict[int, int]:
    """Where the summary's chunk index says each chunk record starts, and its length; empty where
    the file has no summary that reads (cut short: the walk then trusts each record's head)."""
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:
        return {}
    return {c.chunk_start_offset: c.chunk_length for c in summary.chunk_indexes} if summary else {}


def recover_segment(path: str | os.PathLike, *, output: str | os.PathLike | None = None,
                    keep_original: bool = False) -> RecoveryResult:
    """Recover one ``.active`` (or otherwise truncated) MCAP file; returns what was kept.

    An ``.active`` file becomes the finished segment of its name. A closed file (a segment cut
    short, or any MCAP) is repaired in place: the result replaces it atomically, under the same
    name, so every command goes on counting it as the segment it was; the original is kept
    beside it (``.orig``) until the result has read back. An empty file holds nothing to keep:
    it is moved aside (``.unreadable``), never deleted, so it no longer blocks the session."""
    src = Path(path)
    if not src.is_file():
        raise McapFileError(f"{src}: no such file")
    active = src.name.endswith(ACTIVE_SUFFIX)
    in_place = output is None and not active
    dst = Path(output) if output is not None else src.with_name(src.name[: -len(ACTIVE_SUFFIX)]) if active else src
    if not in_place and dst.exists():
        raise McapFileError(f"{dst} already exists; refusing to overwrite a finished segment")
    before = src.stat()
    size = before.st_size
    result = RecoveryResult(source=str(src), output=str(dst))
    if size == 0:
        aside = (dst if active else src).with_name((dst if active else src).name + UNREADABLE_SUFFIX)
        _rename_no_clobber(src, aside)
        fsync_dir(src.parent)
        result.output = str(aside)
        result.stopped_because = f"held no bytes (no frame to keep); moved aside as {aside.name}"
        return result
    orig = src.with_name(src.name + ORIGINAL_SUFFIX)
    if _is_complete(src):
        # finish() completed but the rename did not, or the file was whole all along: name it
        if in_place:
            if orig.exists() and not keep_original:
                orig.unlink()  # a repair that ended before it removed the original: the result read back
        elif keep_original:
            _copy(src, dst)
        else:
            _rename_no_clobber(src, dst)
        fsync_dir(dst.parent)
        result.messages, result.frames, result.topics = _summary_counts(dst)
        result.bytes_kept = size
        result.stopped_because = "file was complete"
        return result

    tmp = dst.with_name(dst.name + ".recovering")
    if tmp.exists():
        tmp.unlink()  # a previous recovery died half way; it was never the real file
    writer = ChunkedWriter(tmp, compression=Compression.ZSTD, compression_level=3, workers=2)
    channel_map: dict[int, int] = {}
    schema_map: dict[int, int] = {0: 0}
    channel_topics: dict[int, str] = {}
    pending_channels: dict[int, Channel] = {}
    last_good = 8
    started = False

    def ensure_channel(cid: int) -> int | None:
        if cid in channel_map:
            return channel_map[cid]
        ch = pending_channels.get(cid)
        if ch is None or ch.schema_id not in schema_map:
            return None
        channel_map[cid] = writer.register_channel(ch.topic, ch.message_encoding, schema_map[ch.schema_id], ch.metadata)
        channel_topics[cid] = ch.topic
        return channel_map[cid]

    def add(msg: Message) -> bool:
        new_id = ensure_channel(msg.channel_id)
        if new_id is None:
            return False
        writer.add_message(new_id, msg.log_time, msg.data, msg.publish_time, msg.sequence)
        topic = channel_topics[msg.channel_id]
        result.topics[topic] = result.topics.get(topic, 0) + 1
        result.messages += 1
        return True

    chunks = _indexed_chunks(src)
    try:
        with open(src, "rb") as f:
            for offset, opcode, body in scan_records(f, size, str(src), chunks):
                if opcode in (Opcode.DATA_END, Opcode.FOOTER):
                    result.stopped_because = "reached the end of the data section"
                    break
                if opcode not in _READERS and opcode != Opcode.MESSAGE:
                    last_good = offset + 9 + len(body)
                    continue
                try:
                    if opcode == Opcode.MESSAGE:
                        record = Message.read(ReadDataStream(io.BytesIO(body)), len(body))
                    else:
                        record = _parse(opcode, body)
                    if opcode == Opcode.HEADER:
                        writer.start(profile=record.profile, library=record.library)
                        started = True
                    elif not started:
                        raise McapFileError(f"{src}: first record is not a header")
                    elif opcode == Opcode.SCHEMA:
                        schema_map[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                    elif opcode == Opcode.CHANNEL:
                        pending_channels[record.id] = record
                    elif opcode == Opcode.ATTACHMENT:
                        writer.add_attachment(record.name, record.media_type, record.data,
                                              log_time=record.log_time, create_time=record.create_time)
                    elif opcode == Opcode.METADATA:
                        writer.add_metadata(record.name, record.metadata)
                    elif opcode == Opcode.MESSAGE:
                        add(record)
                    elif opcode == Opcode.CHUNK:
                        inner = breakup_chunk(record, validate_crc=True)
                        for r in inner:
                            if isinstance(r, Schema) and r.id not in schema_map:
                                schema_map[r.id] = writer.register_schema(r.name, r.encoding, r.data)
                            elif isinstance(r, Channel):
                                pending_channels.setdefault(r.id, r)
                        for r in inner:
                            if isinstance(r, Message):
                                add(r)
                        result.chunks += 1
                except (McapFileError, OSError):
                    raise  # our own output could not be written (a full disk): not damage in the source
                except Exception as exc:
                    if opcode == Opcode.CHUNK:
                        # The record's framing held, only its content is damaged (checksum, codec):
                        # lose this chunk, keep reading the ones after it.
                        result.damaged_chunks += 1
                        result.stopped_because = f"skipped a damaged chunk at byte {offset}: {exc}"
                        last_good = offset + 9 + len(body)
                        continue
                    result.stopped_because = f"damaged {Opcode(opcode).name.lower()} record at byte {offset}: {exc}"
                    break
                last_good = offset + 9 + len(body)
            else:
                result.stopped_because = "end of file"
        if not started:
            raise McapFileError(f"{src}: no MCAP header survived; nothing to recover")
        writer.finish(fsync=True)
    except BaseException as exc:
        writer.close()
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise McapFileError(f"{src}: the recovered copy could not be written ({exc.filename or tmp}: "
                                f"{exc.strerror or exc}); {src.name} is left as it was") from None
        raise
    result.bytes_kept = last_good
    result.bytes_discarded = size - last_good
    result.frames = sum(n for t, n in result.topics.items() if is_image_topic(t))
    # Check the result with the official reader (every chunk's CRC) before it takes the final name.
    if not _is_complete(tmp) or _summary_counts(tmp)[0] != result.messages:
        tmp.unlink()
        raise McapFileError(f"{src}: the recovered copy did not read back with {result.messages} messages; "
                            f"{src.name} is left as it was")
    if _changed(src, before):
        tmp.unlink()
        raise McapFileError(f"{src}: changed while it was being recovered (is a recorder writing it?); left as it was")
    if in_place:
        _replace_keeping_original(tmp, src, orig, result.messages, keep_original)
        return result
    try:
        _rename_no_clobber(tmp, dst)
    except McapFileError:
        tmp.unlink()
        raise
    fsync_dir(dst.parent)
    if not keep_original:
        src.unlink()
        fsync_dir(src.parent)
    return result


def _replace_keeping_original(new: Path, path: Path, orig: Path, messages: int, keep_original: bool) -> None:
    """``new`` takes ``path``'s name in one rename; the original stays as ``orig`` (a second
    link, no copy) until the result under the final name reads back with its messages."""
    if orig.exists():
        orig.unlink()  # only ever a second link to ``path`` or an older original already replaced
    os.link(path, orig)
    fsync_dir(path.parent)
    os.replace(new, path)
    fsync_dir(path.parent)
    if _summary_counts(path)[0] != messages:
        os.replace(orig, path)  # put the original back: the result is not what was checked
        fsync_dir(path.parent)
        raise McapFileError(f"{path}: the repaired file did not read back; the original was put back")
    if not keep_original:
        orig.unlink()
        fsync_dir(path.parent)


def _summary_counts(path: Path) -> tuple[int, int, dict[str, int]]:
    """(messages, frames, messages per topic) from a finished file's summary."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        return 0, 0, {}
    per = summary.statistics.channel_message_counts
    topics: dict[str, int] = {}
    for cid, ch in summary.channels.items():
        topics[ch.topic] = topics.get(ch.topic, 0) + per.get(cid, 0)
    frames = sum(n for t, n in topics.items() if is_image_topic(t))
    return summary.statistics.message_count, frames, topics


def durable_frames(path: Path) -> int:
    """Frames a cut segment holds in whole, CRC-checked chunks: what ``recover`` would keep, and
    so what a recording that stopped on a write error may count as written."""
    images: set[int] = set()
    n = 0
    try:
        with open(path, "rb") as f:
            for _offset, opcode, body in scan_records(f, os.fstat(f.fileno()).st_size, str(path)):
                if opcode == Opcode.CHANNEL:
                    ch = _parse(opcode, body)
                    if is_image_topic(ch.topic):
                        images.add(ch.id)
                elif opcode == Opcode.CHUNK:
                    try:
                        inner = breakup_chunk(_parse(opcode, body), validate_crc=True)
                    except Exception:
                        continue  # a damaged chunk keeps nothing
                    for r in inner:
                        if isinstance(r, Channel) and is_image_topic(r.topic):
                            images.add(r.id)
                    n += sum(1 for r in inner if isinstance(r, Message) and r.channel_id in images)
                elif opcode == Opcode.MESSAGE:
                    n += Message.read(ReadDataStream(io.BytesIO(body)), len(body)).channel_id in images
    except (OSError, McapFileError):
        return n
    return n


def _changed(path: Path, before: os.stat_result) -> bool:
    try:
        now = path.stat()
    except FileNotFoundError:
        return True
    return (now.st_ino, now.st_size, now.st_mtime_ns) != (before.st_ino, before.st_size, before.st_mtime_ns)


def _rename_no_clobber(src: Path, dst: Path) -> None:
    """Give ``src`` the name ``dst`` only if nothing has it: link (fails if it exists), then unlink.
    A plain rename would silently replace a segment that appeared in the meantime."""
    try:
        os.link(src, dst)
    except FileExistsError:
        raise McapFileError(f"{dst} already exists; refusing to overwrite a finished segment") from None
    src.unlink()


def _copy(src: Path, dst: Path) -> None:
    with open(src, "rb") as a, open(dst, "xb") as b:
        while chunk := a.read(1 << 20):
            b.write(chunk)
        b.flush()
        os.fsync(b.fileno())


def recover_path(path: str | os.PathLike, *, keep_original: bool = False) -> list[RecoveryResult]:
    """A file, a session folder, or a data root: recover every ``.active`` segment found, and
    mark every session whose recorder died (``session.json`` still says it is recording), also
    one killed between two segments, which leaves no ``.active`` file behind.

    Each session is recovered under its lock; a session some live process holds (a recorder
    still writing it) is skipped and reported, never touched."""
    p = Path(path)
    if p.is_file():
        by_session = {p.parent: [p]}
    elif p.is_dir():
        by_session = {}
        for active in sorted(p.rglob(f"*.mcap{ACTIVE_SUFFIX}")):
            by_session.setdefault(active.parent, []).append(active)
        for seg in sorted(p.rglob("[0-9][0-9][0-9][0-9].mcap")):
            if _looks_cut(seg):  # a closed segment the archiver refuses: repaired in place
                by_session.setdefault(seg.parent, []).append(seg)
        for meta in sorted(p.rglob(SESSION_JSON)):
            if _left_recording(meta.parent):
                by_session.setdefault(meta.parent, [])
    else:
        raise McapFileError(f"{p}: no such file or folder")
    results = []
    for session, actives in by_session.items():
        lock = lock_session(session, "recover")
        if lock is None:
            who = holder(session) or "another process"
            results += [RecoveryResult(source=str(a), output="", skipped=True,
                                       stopped_because=f"skipped: {who} holds the session") for a in actives]
            continue
        try:
            SessionLayout.of(session).reserve.unlink(missing_ok=True)  # a killed recorder's reserve
            done = []
            for active in actives:
                done.append(recover_segment(active, keep_original=keep_original))
            results += done
            _mark_session(session, done)
            with contextlib.suppress(OSError):  # derived data: a failure must not undo the work above
                write_bag_metadata(session)
        finally:
            lock.release()
    return results


_UNFINISHED = ("recording", "interrupted")  # what session.json says of a recorder that never wrote its end


def _left_recording(session_dir: Path) -> bool:
    """Whether the session's own record still says a recorder is writing it (true or not)."""
    try:
        return json.loads(SessionLayout.of(session_dir).session_json.read_text()).get("status") in _UNFINISHED
    except (OSError, ValueError, AttributeError):
        return False


def _looks_cut(seg: Path) -> bool:
    """A closed segment with no closing magic, no readable summary (cut short, or empty), or a
    chunk whose record head the summary's index contradicts. Cheap: the tail, the summary and
    nine bytes a chunk, not every chunk's content."""
    try:
        if seg.stat().st_size < 16:
            return True
        with open(seg, "rb") as f:
            f.seek(-8, os.SEEK_END)
            if f.read(8) != MCAP_MAGIC:
                return True
            f.seek(0)
            summary = make_reader(f).get_summary()
            if summary is None or summary.statistics is None:
                return True
            for c in summary.chunk_indexes:  # a chunk head the index contradicts: the readers refuse it
                f.seek(c.chunk_start_offset)
                opcode, length = struct.unpack("<BQ", f.read(9))
                if opcode != Opcode.CHUNK or 9 + length != c.chunk_length:
                    return True
        return False
    except OSError:
        return False  # unreadable here: named by the command that reads it, never moved
    except Exception:
        return True


def _mark_session(session_dir: Path, results: list[RecoveryResult] | None = None) -> None:
    meta_path = SessionLayout.of(session_dir).session_json
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError):
        return
    repaired = [r for r in results or [] if r.stopped_because != "file was complete" and not r.skipped]
    if meta.get("status") in _UNFINISHED or repaired:
        # The recorder died before its summary, or a segment lost its cut tail: the counts come
        # from what the segments now hold, so session.json, `info` and the catalog agree.
        if meta.get("status") not in _UNFINISHED and "frames_written_before_recovery" not in meta:
            meta["frames_written_before_recovery"] = meta.get("frames_written")
        meta["status"] = "recovered"
        # a finished segment with no readable summary: `info` names it; no count is made up
        with contextlib.suppress(McapFileError):
            on_disk = count_frames(session_dir)
            # and the segments that left before (the ring, sync): written all the same
            gone = {e["segment"]: int(e.get("frames") or 0) for e in deletions(session_dir)
                    if e["segment"] not in on_disk}
            meta["frames_written"] = sum(on_disk.values()) + sum(gone.values())
        meta["recovered_ns"] = time.time_ns()
        notes = meta.setdefault("recovered_segments", {})
        for r in repaired:
            notes[Path(r.source).name.removesuffix(ACTIVE_SUFFIX)] = {
                "frames": r.frames, "messages": r.messages, "bytes_discarded": r.bytes_discarded,
                "damaged_chunks": r.damaged_chunks, "output": Path(r.output).name, "why": r.stopped_because}
        write_json_atomic(meta_path, meta)


def recover_leftovers(root: str | os.PathLike) -> list[Path]:
    """At recorder start: recover ``.active`` segments of sessions no live recorder holds."""
    done: list[Path] = []
    for session in DataRoot.of(root).session_dirs():
        actives = sorted(session.glob(f"*.mcap{ACTIVE_SUFFIX}"))
        if not actives and not _left_recording(session):
            continue
        lock = lock_session(session, "recover")
        if lock is None:
            continue  # a recorder is still writing it
        try:
            SessionLayout.of(session).reserve.unlink(missing_ok=True)
            for active in actives:
                try:
                    recover_segment(active)
                    done.append(active)
                except McapFileError:
                    continue  # left for the user, with `thermcap recover` to say why
            _mark_session(session)
        finally:
            lock.release()
    return done
