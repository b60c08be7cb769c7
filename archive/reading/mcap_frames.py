"""Frames of sessions not archived yet, from their MCAP segments, with what serving them again
needs kept in memory: each closed segment's chunk index, and the last decompressed chunks.

A user looks through a session right after recording it, before it is archived: a scrubber or a
player asks for neighbouring frames, and a 640x512 frame's chunk holds about six of them. With
mcap's reader every request parsed the segment's whole summary and decompressed and parsed a
4 MB chunk (15-18 ms a frame). Here a request that finds its chunk kept costs a header walk;
one that does not reads and checks that one chunk. The chunks kept are bounded in bytes, the
indexes in number, and an index is dropped as soon as its file is not the one it describes.
"""

from __future__ import annotations

import inspect
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np
from mcap.reader import SeekingReader, make_reader

from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.icd.topics import TOPIC_IMAGE, TOPIC_METADATA, decode_image
from thermcap.recorder.storage.chunks import ChunkRecords, SegmentIndex, StaleIndexError, messages_at, read_chunk

__all__ = ["McapFrames"]

#: mcap 1.6 renamed iter_messages' bounds (``start_time``/``end_time`` warn and will go); older
#: releases, which pyproject still allows, know only the old names
_NEW_BOUNDS = "starting_at" in inspect.signature(SeekingReader.iter_messages).parameters


class McapFrames:
    """(pixels, sidecar bytes) of the frame logged at a time in a segment, shared by requests."""

    def __init__(self, max_chunk_bytes: int = 64 << 20, max_segments: int = 256) -> None:
        self.max_chunk_bytes = max_chunk_bytes
        self.max_segments = max_segments
        self._indexes: OrderedDict[Path, SegmentIndex] = OrderedDict()
        self._chunks: OrderedDict[tuple[Path, int, int, int], ChunkRecords] = OrderedDict()
        self._chunk_bytes = 0
        self._lock = threading.Lock()
        self.chunk_reads = 0  # chunks read from disk (the rest came from memory): for the tests

    def frame(self, segment: Path, log_time: int) -> tuple[np.ndarray | None, bytes | None]:
        """The frame's counts (a copy) and its sidecar as JSON bytes; either is None where the
        segment holds no such message. Raises ``McapFileError`` for a damaged chunk."""
        index = self._index(segment)
        if index is None:
            return _scan(segment, log_time)
        try:
            return self._frame(index, log_time)
        except StaleIndexError:  # replaced since it was indexed: index it again, once
            index = self._index(segment)
            return _scan(segment, log_time) if index is None else self._frame(index, log_time)

    def _frame(self, index: SegmentIndex, log_time: int) -> tuple[np.ndarray | None, bytes | None]:
        image, meta = index.topics.get(TOPIC_IMAGE), index.topics.get(TOPIC_METADATA)
        wanted = {c for c in (image, meta) if c is not None}
        pixels = sidecar = None
        for chunk in index.chunks_at(log_time):
            for channel, data in messages_at(self._chunk(index, chunk), log_time, wanted):
                if channel == image and pixels is None:
                    pixels = decode_image(data)[1].copy()
                elif channel == meta and sidecar is None:
                    sidecar = json_payload(index.channels[channel].message_encoding, bytes(data))
        if pixels is None and not index.is_current():  # "not there" only from the file as it is
            raise StaleIndexError(f"{index.path} changed since it was indexed")
        return pixels, sidecar

    def _index(self, segment: Path) -> SegmentIndex | None:
        """The segment's index, kept while its file stays the one indexed (None: it has no chunks)."""
        with self._lock:
            kept = self._indexes.get(segment)
        if kept is not None and kept.is_current():
            with self._lock:
                if segment in self._indexes:
                    self._indexes.move_to_end(segment)
            return kept
        index = SegmentIndex.load(segment)
        with self._lock:
            if index is None:
                self._indexes.pop(segment, None)
            else:
                self._indexes[segment] = index
                while len(self._indexes) > self.max_segments:
                    self._indexes.popitem(last=False)
        return index

    def is_kept(self, segment: Path, log_time: int) -> bool:
        """True where reading the frame takes no disk read and no decompression: its segment's
        index is kept and current and every chunk that spans ``log_time`` is kept. A caller on
        an event loop reads such a frame in place and hands any other to a thread."""
        with self._lock:
            index = self._indexes.get(segment)
        if index is None or not index.is_current():
            return False
        chunks = index.chunks_at(log_time)
        with self._lock:
            return bool(chunks) and all(_key(index, c) in self._chunks for c in chunks)

    def _chunk(self, index: SegmentIndex, chunk: int) -> ChunkRecords:
        key = _key(index, chunk)
        with self._lock:
            kept = self._chunks.get(key)
            if kept is not None:
                self._chunks.move_to_end(key)
                return kept
        records = read_chunk(index, chunk)  # outside the lock: other requests go on meanwhile
        with self._lock:
            self.chunk_reads += 1
            if key not in self._chunks and records.nbytes <= self.max_chunk_bytes:
                self._chunks[key] = records
                self._chunk_bytes += records.nbytes
                while self._chunk_bytes > self.max_chunk_bytes:
                    _, old = self._chunks.popitem(last=False)
                    self._chunk_bytes -= old.nbytes
        return records

    @property
    def kept_bytes(self) -> int:
        with self._lock:
            return self._chunk_bytes


def _key(index: SegmentIndex, chunk: int) -> tuple[Path, int, int, int]:
    """A kept chunk's key: its file as indexed (path, size, mtime) and its offset."""
    return index.path, index.size, index.mtime_ns, int(index.offsets[chunk])


def _scan(segment: Path, log_time: int) -> tuple[np.ndarray | None, bytes | None]:
    """A segment whose summary does not index its chunks (written without one): mcap's reader
    finds the messages by reading the file through, checking every chunk's CRC."""
    pixels = sidecar = None
    with open(segment, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        topics = [TOPIC_IMAGE, TOPIC_METADATA]
        messages = reader.iter_messages(topics=topics, starting_at=log_time, ending_before=log_time + 1) \
            if _NEW_BOUNDS else reader.iter_messages(topics=topics, start_time=log_time, end_time=log_time + 1)
        for _, ch, msg in messages:
            if ch.topic == TOPIC_IMAGE and pixels is None:
                pixels = decode_image(msg.data)[1].copy()
            elif ch.topic == TOPIC_METADATA and sidecar is None:
                sidecar = json_payload(ch.message_encoding, msg.data)
    return pixels, sidecar
