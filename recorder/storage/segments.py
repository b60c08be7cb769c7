"""A session is a folder of MCAP segments; this module writes them, rotates them and names them.

Naming: ``NNNN.mcap.active`` while a segment is open, renamed to ``NNNN.mcap`` only after
``finish()`` and fsync, so a file called ``*.mcap`` is always complete and indexed, and an
``.active`` file is always something ``thermcap recover`` should look at. The folder itself is
fsynced after each rename, so the new name survives a power cut too.

A closed segment's fsync, rename and folder fsync happen on a thread of their own, one segment
after another, while the writer thread goes on into the next segment: on a busy disk an fsync
can take seconds, and frames queued behind it would be in memory only, which ``kill -9`` takes.
A file that has been written survives ``kill -9`` in the page cache, fsynced or not. So a crash
may leave several ``.active`` files (finished ones not yet renamed, and the open one);
``recover`` names the finished ones and rewrites the open one.

Every segment stands alone: it carries the schemas, the session metadata record (sensor,
radiometric model, software version, host) and the bad-pixel map attachment, so one segment
copied off a vehicle opens in Foxglove with everything needed to read its temperatures.
"""

from __future__ import annotations

import json
import os
import queue
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from thermcap.recorder import __version__
from thermcap.recorder.exceptions import RecordingError
from thermcap.recorder.icd.rosmsg import ANNOTATIONS, SIDECAR, annotations_message, message_for_topic
from thermcap.recorder.icd.topics import (
    IMAGE_SCHEMA_NAME,
    IMAGE_SCHEMA_TEXT,
    TOPIC_EVENTS,
    TOPIC_STATS,
    CameraTopics,
    camera_topics,
)
from thermcap.recorder.storage.atomic import fsync_dir
from thermcap.recorder.storage.layout import ACTIVE_SUFFIX
from thermcap.recorder.storage.rosbag2 import write_bag_metadata
from thermcap.recorder.storage.writer import ChunkedWriter, Compression

__all__ = ["ACTIVE_SUFFIX", "DiskStalled", "SegmentPolicy", "SessionWriter", "auto_compression", "segment_name"]

SEGMENT_STATS_METADATA = "thermcap.segment"
SESSION_METADATA = "thermcap.session"
# Closed segments waiting for their fsync and rename, at most; one more makes the writer wait.
# Each holds only a file descriptor, so this bounds descriptors (and the .active files a crash
# leaves), not memory: 32 rides out a 30 s stall (when /healthz says so) with 1 s segments.
MAX_SETTLING = 32


def segment_name(index: int) -> str:
    return f"{index:04d}.mcap"


def auto_compression(width: int, height: int, fps: float) -> tuple[Compression, int]:
    """zstd-1 (ratio ~2.3 on thermal frames) while 2 cores keep it several times real time; lz4
    (ratio ~1.6, ~1.6x less CPU) above 25 Mpixel/s, e.g. 1280x1024@60, where zstd-1 leaves too
    little headroom. Both are standard MCAP chunk compressions. Measured by ``thermcap bench record``."""
    if width * height * fps > 25e6:
        return Compression.LZ4, 0
    return Compression.ZSTD, 1


@dataclass
class SegmentPolicy:
    """When to start a new segment, and how each one is written."""

    max_duration_s: float | None = 60.0
    max_bytes: int | None = 4 * 1024**3
    compression: Compression = Compression.ZSTD
    compression_level: int = 1
    chunk_size: int = 4 * 1024 * 1024
    max_chunk_age_s: float = 0.25
    workers: int = 2
    fsync_interval_s: float = 1.0
    # How long a clean close waits for the disk to confirm its closed segments: a disk whose
    # fsync never returns (a lost NFS mount, a dying card) must not hold the recorder's exit.
    settle_timeout_s: float = 60.0


@dataclass
class SegmentInfo:
    index: int
    name: str
    frames: int = 0
    messages: int = 0
    start_ns: int | None = None
    end_ns: int | None = None
    bytes: int = 0
    topic_bytes: dict[str, int] = field(default_factory=dict)
    topic_messages: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"index": self.index, "name": self.name, "frames": self.frames, "messages": self.messages,
                "start_ns": self.start_ns, "end_ns": self.end_ns, "bytes": self.bytes,
                "topic_bytes": self.topic_bytes, "topic_messages": self.topic_messages}


class _Syncer(threading.Thread):
    """fsyncs the open segment every interval, off the writer thread (fsync can take 100 ms)."""

    def __init__(self, interval_s: float):
        super().__init__(name="segment-fsync", daemon=True)
        self.interval_s = interval_s
        self.lock = threading.Lock()
        self.fd: int | None = None
        self._halt = threading.Event()
        self.error: OSError | None = None

    def run(self) -> None:
        while not self._halt.wait(self.interval_s):
            # The lock only hands over the descriptor (a duplicate, so the segment may close
            # meanwhile): held through an fsync that takes seconds, it would stop the writer
            # thread at its next segment, with frames queued in memory only.
            with self.lock:
                try:
                    fd = os.dup(self.fd) if self.fd is not None else None
                except OSError as exc:
                    self.error, fd = exc, None
            if fd is None:
                continue
            try:
                os.fsync(fd)
            except OSError as exc:  # reported by the writer, which owns the stop decision
                self.error = exc
            finally:
                os.close(fd)

    def stop(self, timeout_s: float | None = None) -> None:
        """Stop; a thread stuck in an fsync that never returns is left behind (a daemon)."""
        self._halt.set()
        self.join(timeout_s)


class _SettlingThread:
    """One daemon thread running settles in order. Not a ThreadPoolExecutor: its workers are
    joined at interpreter exit, so one fsync that never returns would keep the process alive
    for ever after the recorder has said what it could not confirm."""

    def __init__(self) -> None:
        self._jobs: queue.SimpleQueue[tuple[Callable[..., None], tuple[Any, ...], Future[None]] | None] = \
            queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="segment-settle", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (job := self._jobs.get()) is not None:
            fn, args, future = job
            if not future.set_running_or_notify_cancel():
                continue
            try:
                fn(*args)
            except BaseException as exc:
                future.set_exception(exc)
            else:
                future.set_result(None)

    def submit(self, fn: Callable[..., None], *args: Any) -> Future[None]:
        future: Future[None] = Future()
        self._jobs.put((fn, args, future))
        return future

    def shutdown(self, timeout_s: float | None) -> bool:
        """Let the queued settles finish within ``timeout_s``; True if they did."""
        self._jobs.put(None)
        self._thread.join(timeout_s)
        return not self._thread.is_alive()


class DiskStalled(RecordingError):
    """Closed segments the disk has not confirmed (fsync has not returned) within the deadline."""


class _Settling(NamedTuple):
    name: str
    since: float  # time.monotonic() when the segment was closed
    future: Future[None]


def _as_message(topic: str, payload: bytes, doc: dict[str, Any] | None = None) -> bytes:
    """``payload`` (JSON) as its topic's ROS 2 message; ``doc`` is the same document when the
    caller has it, so it is not parsed back."""
    return message_for_topic(topic).encode(json.loads(payload) if doc is None else doc, payload)


class SessionWriter:
    """Writes frames, sidecars and other messages of one session into rotating segments."""

    def __init__(self, session_dir: Path, *, session_meta: dict[str, Any], extra_topics: dict[str, dict[str, Any]],
                 bad_pixel_map: np.ndarray | dict[str, np.ndarray] | None = None,
                 policy: SegmentPolicy | None = None,
                 on_chunk_written: Callable[[list[Any]], None] | None = None,
                 on_segment_closed: Callable[[], None] | None = None,
                 cameras: Sequence[str] | None = None,
                 segment_attachments: Callable[[], Sequence[tuple[str, str, bytes]]] | None = None) -> None:
        """``cameras``: the names of a session of several cameras (``/thermal/<name>/...``);
        None keeps the single-camera layout. ``bad_pixel_map`` is then one map per name.
        ``segment_attachments`` gives what every segment carries from the start, as the bad-pixel
        map (a camera's GenICam XML): a segment alone, once the ring evicted the others, still
        says what recorded it."""
        self.dir = Path(session_dir)
        self.cameras: dict[str | None, CameraTopics] = {None: camera_topics(None)} if not cameras else \
            {n: camera_topics(n) for n in cameras}
        self.on_segment_closed = on_segment_closed
        self.policy = policy or SegmentPolicy()
        self.session_meta = session_meta
        self.extra_topics = extra_topics
        self.bad_pixel_map = bad_pixel_map
        self.segment_attachments = segment_attachments
        self.on_chunk_written = on_chunk_written
        self.segments: list[SegmentInfo] = []
        self._writer: ChunkedWriter | None = None
        self._channels: dict[str, int] = {}
        self._schema: Callable[[str, str], int] = lambda name, text: 0
        self._executor = ThreadPoolExecutor(self.policy.workers, thread_name_prefix="mcap-compress") \
            if self.policy.workers > 0 else None
        self._syncer = _Syncer(self.policy.fsync_interval_s) if self.policy.fsync_interval_s > 0 else None
        if self._syncer:
            self._syncer.start()
        self._settler: _SettlingThread | None = _SettlingThread()
        self._settling: deque[_Settling] = deque()
        self._stalled = False  # a settle outlived its deadline: nothing more is waited for
        self._next_index = self._first_free_index()

    def _first_free_index(self) -> int:
        used = [int(p.name[:4]) for p in self.dir.glob("[0-9][0-9][0-9][0-9].mcap*") if p.name[:4].isdigit()]
        return max(used, default=-1) + 1

    @property
    def current(self) -> SegmentInfo | None:
        return self.segments[-1] if self._writer is not None else None

    def _path(self, info: SegmentInfo, active: bool) -> Path:
        return self.dir / (info.name + (ACTIVE_SUFFIX if active else ""))

    # -- segment lifecycle -------------------------------------------------------------------
    def _open_segment(self) -> None:
        info = SegmentInfo(index=self._next_index, name=segment_name(self._next_index))
        self._next_index += 1
        path = self._path(info, active=True)
        try:
            writer = ChunkedWriter(path, compression=self.policy.compression,
                                   compression_level=self.policy.compression_level, chunk_size=self.policy.chunk_size,
                                   max_chunk_age_s=self.policy.max_chunk_age_s, workers=0,
                                   executor=self._executor, on_chunk_written=self.on_chunk_written)
            writer.start(profile="ros2")
            channels: dict[str, int] = {}
            # Every topic is a ROS 2 message (ros2msg schema, CDR), so rosbags and ros2 bag read the
            # segments as they are; see recorder.icd.rosmsg.
            schemas: dict[str, int] = {}

            def schema(msg_name: str, text: str) -> int:
                if msg_name not in schemas:
                    schemas[msg_name] = writer.register_schema(msg_name, "ros2msg", text.encode())
                return schemas[msg_name]

            for topics in self.cameras.values():
                channels[topics.image] = writer.register_channel(topics.image, "cdr",
                                                                 schema(IMAGE_SCHEMA_NAME, IMAGE_SCHEMA_TEXT))
                channels[topics.metadata] = writer.register_channel(topics.metadata, "cdr",
                                                                    schema(SIDECAR.name, SIDECAR.text))
                channels[topics.annotations] = writer.register_channel(topics.annotations, "cdr",
                                                                       schema(ANNOTATIONS.name, ANNOTATIONS.text))
            for topic in [*self.extra_topics, TOPIC_STATS, TOPIC_EVENTS]:
                m = message_for_topic(topic)
                channels[topic] = writer.register_channel(topic, "cdr", schema(m.name, m.text))
            self._schema = schema
            meta = {k: v if isinstance(v, str) else json.dumps(v) for k, v in self.session_meta.items()}
            meta.update(segment_index=str(info.index), software_version=__version__, host=socket.gethostname())
            writer.add_metadata(SESSION_METADATA, meta)
            maps = self.bad_pixel_map if isinstance(self.bad_pixel_map, dict) else {"": self.bad_pixel_map}
            for camera, bad in maps.items():
                if bad is None:
                    continue
                ys, xs = np.nonzero(bad)
                bpm = {"width": int(bad.shape[1]), "height": int(bad.shape[0]),
                       "convention": "[x, y] of each defective pixel; correct by median of good neighbours (ICD 5.3)",
                       "pixels": [[int(x), int(y)] for y, x in zip(ys, xs, strict=True)]}
                writer.add_attachment(f"{camera}/bad_pixel_map.json" if camera else "bad_pixel_map.json",
                                      "application/json", json.dumps(bpm).encode(),
                                      log_time=time.time_ns(), create_time=time.time_ns())
            for name, media_type, data in self.segment_attachments() if self.segment_attachments else ():
                writer.add_attachment(name, media_type, data, log_time=time.time_ns(), create_time=time.time_ns())
        except OSError as exc:
            raise RecordingError(f"cannot start segment {path}: {exc.strerror or exc}") from exc
        self._writer = writer
        self._channels = channels
        self.segments.append(info)
        if self._syncer:
            with self._syncer.lock:
                self._syncer.fd = writer.fileno()

    def bytes_per_s(self) -> float | None:
        """What the session has cost on disk a second of frames so far: its closed segments', or
        the open one's while none is closed (its bytes written and those still in the chunk being
        built, uncompressed: a little high while compressing, never low, so an early mark is
        not promised a window that will not fit); None before half a second of frames."""
        closed = [(i.bytes, i.end_ns - i.start_ns) for i in self.segments
                  if i.bytes and i.start_ns is not None and i.end_ns is not None and i.end_ns > i.start_ns]
        if not closed and self._writer is not None and self.segments:
            info = self.segments[-1]
            if info.start_ns is not None and info.end_ns is not None and info.end_ns > info.start_ns:
                closed = [(self._writer.position + self._writer.pending_bytes, info.end_ns - info.start_ns)]
        span = sum(ns for _, ns in closed)
        return sum(b for b, _ in closed) / (span / 1e9) if span >= 5e8 else None

    def close_segment(self) -> None:
        """End the open segment: its last chunks, summary and closing magic are written here,
        then its fsync, the rename .active -> .mcap and the folder's fsync are left to the
        settling thread, in order. A settling error is raised by a later call (write, poll,
        close), naming the segment."""
        writer, info = self._writer, self.segments[-1] if self.segments else None
        if writer is None or info is None:
            return
        path = self._path(info, True)
        fd: int | None = None
        try:
            writer.add_metadata(SEGMENT_STATS_METADATA, {k: json.dumps(v) for k, v in info.to_dict().items()})
            if self._syncer:
                with self._syncer.lock:
                    self._syncer.fd = None
            fd = os.dup(writer.fileno())
            writer.finish()
            info.bytes = writer.position
        except OSError as exc:
            if fd is not None:
                os.close(fd)
            raise RecordingError(f"cannot close segment {path}: {exc.strerror or exc}") from exc
        finally:
            self._writer = None
        assert self._settler is not None, "close_segment after shutdown"
        self._settling.append(_Settling(info.name, time.monotonic(),
                                        self._settler.submit(self._settle, fd, path, self._path(info, False))))
        if self.on_segment_closed is not None:
            # Here, on the writer thread, before the next segment opens: a ring's eviction
            # keeps the disk within its budget plus the one open segment only if the writer
            # does not run ahead of it. (The segment just closed is not a candidate until it
            # settles; it is the newest anyway.)
            self.on_segment_closed()
        self._reap(keep=MAX_SETTLING)

    def _settle(self, fd: int, active: Path, final: Path) -> None:
        """On the settling thread: the finished file to disk, then its final name."""
        try:
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(active, final)
            fsync_dir(self.dir)
        except OSError as exc:
            raise RecordingError(f"cannot close segment {active}: {exc.strerror or exc}") from exc
        with suppress(OSError):  # the folder stays a rosbag2 bag of its finished segments (derived data)
            write_bag_metadata(self.dir)

    def _reap(self, keep: int) -> None:
        """Raise the first settling error; wait while more than ``keep`` segments settle."""
        while self._settling and (len(self._settling) > keep or self._settling[0].future.done()):
            self._settling.popleft().future.result()

    def settling(self) -> list[tuple[str, float]]:
        """Closed segments still waiting for their fsync and rename, oldest first, each with the
        seconds it has waited: a disk that stalls shows here before anything is lost."""
        now = time.monotonic()
        return [(s.name, now - s.since) for s in list(self._settling) if not s.future.done()]

    def settle(self, timeout_s: float | None = None) -> None:
        """Wait until every closed segment has its final name (raises its error if one failed);
        past ``timeout_s``, raise DiskStalled naming the segments still waiting."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while self._settling:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                self._settling[0].future.result(timeout=left)
            except FutureTimeout:
                self._stalled = True
                waiting = [name for name, _ in self.settling()]
                raise DiskStalled(
                    f"the disk has not confirmed {', '.join(waiting)} in {self.dir} after {timeout_s:g} s (fsync "
                    f"has not returned): their frames are written, complete in the .active files, but may not "
                    f"survive a power cut; once the disk answers, run `thermcap recover {self.dir}`") from None
            self._settling.popleft()

    def _maybe_rotate(self, log_time: int, incoming: int) -> None:
        info = self.current
        if info is None:
            self._open_segment()
            return
        p = self.policy
        too_long = p.max_duration_s is not None and info.start_ns is not None and \
            (log_time - info.start_ns) >= p.max_duration_s * 1e9
        too_big = p.max_bytes is not None and self._writer is not None and \
            self._writer.position + self._writer.pending_bytes + incoming > p.max_bytes and info.messages > 0
        if too_long or too_big:
            self.close_segment()
            self._open_segment()

    # -- writing -------------------------------------------------------------------------------
    def write_frame(self, log_time: int, image_parts: list[Any], sidecar_json: bytes,
                    extra: Sequence[tuple[str, bytes, dict[str, Any]]] = (), token: Any = None, sequence: int = 0,
                    attachments: Sequence[tuple[str, str, bytes]] = (), camera: str | None = None,
                    sidecar_doc: dict[str, Any] | None = None) -> None:
        """One frame: its image, its sidecar (``sidecar_json`` kept byte for byte inside the ROS 2
        message; ``sidecar_doc`` is the same document as a dict, when the caller has it), the
        boxes of its targets for Foxglove, and the JSON messages that belong with it."""
        size = sum(memoryview(p).nbytes for p in image_parts) + len(sidecar_json)
        self._maybe_rotate(log_time, size)
        writer = self._writer
        assert writer is not None  # _maybe_rotate opened a segment
        for name, media_type, data in attachments:
            with self._writing():
                writer.add_attachment(name, media_type, data, log_time=log_time, create_time=log_time)
        topics = self.cameras[camera]
        doc = sidecar_doc if sidecar_doc is not None else (json.loads(sidecar_json) if sidecar_json else {})
        batch = [(topics.image, image_parts, sequence),
                 (topics.metadata, SIDECAR.encode(doc, sidecar_json), sequence),
                 (topics.annotations, annotations_message(log_time, doc.get("targets") or []), sequence)]
        batch += [(topic, _as_message(topic, payload, extra_doc), 0) for topic, payload, extra_doc in extra]
        self._add(log_time, batch, token)
        self.segments[-1].frames += 1

    def write_message(self, topic: str, log_time: int, payload: bytes) -> None:
        """A JSON document on ``topic``, as its ROS 2 message (the JSON kept inside it)."""
        if self._writer is None:
            self._maybe_rotate(log_time, len(payload))
        self._add(log_time, [(topic, _as_message(topic, payload), 0)])

    def _add(self, log_time: int, batch: list[tuple[str, Any, int]], token: Any = None) -> None:
        """Messages of one log time, each ``(topic, data, sequence)``, into the open segment."""
        writer = self._writer
        assert writer is not None
        info = self.segments[-1]
        channels = self._channels
        with self._writing():
            for topic, _, _ in batch:
                if topic not in channels:  # a source's message on a topic it did not declare: kept, as JSON
                    m = message_for_topic(topic)
                    channels[topic] = writer.register_channel(topic, "cdr", self._schema(m.name, m.text))
            lengths = writer.add_messages(log_time, [(channels[t], data, seq) for t, data, seq in batch], token=token)
        topic_bytes, topic_messages = info.topic_bytes, info.topic_messages
        for (topic, _, _), n in zip(batch, lengths, strict=True):
            topic_bytes[topic] = topic_bytes.get(topic, 0) + n
            topic_messages[topic] = topic_messages.get(topic, 0) + 1
        info.messages += len(lengths)
        if info.start_ns is None or log_time < info.start_ns:
            info.start_ns = log_time
        if info.end_ns is None or log_time > info.end_ns:
            info.end_ns = log_time

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """Turn an OSError (disk full, I/O error) on the open segment into a RecordingError naming it."""
        try:
            yield
        except OSError as exc:
            raise RecordingError(f"writing {self._path(self.segments[-1], True)} failed: "
                                 f"{exc.strerror or exc}") from exc

    def poll(self) -> None:
        self._reap(keep=MAX_SETTLING)
        if self._writer is not None:
            with self._writing():
                self._writer.poll()
        if self._syncer and self._syncer.error is not None:
            err, self._syncer.error = self._syncer.error, None
            raise RecordingError(f"fsync of {self.dir} failed: {err.strerror or err}")

    def close(self) -> None:
        """Close the open segment cleanly, wait until every segment has its final name (at most
        the policy's settle timeout), and stop the helper threads."""
        try:
            self.close_segment()
            self.settle(self.policy.settle_timeout_s)
        finally:
            self.shutdown()

    def abandon(self) -> None:
        """After a write error: keep the open segment as .active for ``recover``; touch nothing
        else. Segments already finished still settle (or stay .active if they cannot)."""
        if self._writer is not None:
            with suppress(OSError):
                self._writer.close()
            self._writer = None
        self.shutdown()

    def shutdown(self) -> None:
        """Stop the helper threads; settles still queued get the policy's settle timeout, and a
        thread stuck in fsync past it is left behind rather than waited for."""
        timeout = 0.0 if self._stalled else self.policy.settle_timeout_s
        if self._settler:
            self._settler.shutdown(timeout)
            self._settler = None
            self._settling.clear()
        if self._syncer:
            self._syncer.stop(timeout)
            self._syncer = None
        if self._executor:
            self._executor.shutdown(wait=True)
            self._executor = None
