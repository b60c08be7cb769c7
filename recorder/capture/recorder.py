"""The real-time recorder: a capture thread, a bounded queue, a writer thread.

A live camera never waits on compression or disk: each frame goes to a bounded queue with
``put_nowait``; when the queue is full the frame is dropped *and counted* per topic (stats
channel, session summary, exit report). A source that can wait (a file, a pipe, an importer)
blocks on the queue instead and loses nothing. The writer thread builds and validates the ICD sidecar,
encodes the image, and feeds the segment writer, whose chunks compress on a thread pool. Memory
is bounded by the queue length plus the chunks in flight, however long the session runs.

Several cameras share one session and one clock: each has its own capture thread, detector,
sidecar encoder and drop accounting (``CameraFeed``), and writes ``/thermal/<name>/...``; a
camera that fails or ends is reported and the others go on. Each camera's detector runs in a
child process (``analysis.process_runner``), so it never competes with the writer for the
interpreter. The live view (``recorder.live``)
is offered each written frame without waiting; it drops its own frames, never ours.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import queue
import secrets
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from thermcap.recorder import __version__
from thermcap.recorder.analysis.detector import EventBuilder, HotSpotDetector
from thermcap.recorder.analysis.runner import DetectorRunner, Unanalysable, start_runner
from thermcap.recorder.capture.counters import LatencyHistogram, RecorderCounters
from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource
from thermcap.recorder.capture.sources.health import source_losses
from thermcap.recorder.capture.triggers import TriggerPolicy, TriggerWatch
from thermcap.recorder.exceptions import RecordingError, ThermcapError
from thermcap.recorder.icd.names import FORMAT_VERSION, iso_utc
from thermcap.recorder.icd.sidecar import SidecarEncoder
from thermcap.recorder.icd.topics import (
    TOPIC_EVENTS,
    TOPIC_STATS,
    CameraTopics,
    camera_topics,
    image_message_parts,
    sum_image_topics,
)
from thermcap.recorder.radiometry import LinearModel, describe_model
from thermcap.recorder.storage.atomic import write_json_atomic
from thermcap.recorder.storage.foxglove_layout import CountsRange, write_layout
from thermcap.recorder.storage.layout import DataRoot, SessionLayout
from thermcap.recorder.storage.lock import lock_session
from thermcap.recorder.storage.ring import Evictor, ProtectionBook, RingPolicy, Window
from thermcap.recorder.storage.segments import DiskStalled, SegmentPolicy, SessionWriter

if TYPE_CHECKING:
    from thermcap.recorder.live.branch import LiveBranch

__all__ = ["CameraFeed", "Recorder", "RecordingResult", "new_session_id", "sessions_dir"]

_STOP = object()
#: A source that waits for the detector gets at least this many analysis slots (see
#: ``Recorder._analysis_slots``), within this many bytes of frames.
FILE_ANALYSIS_SLOTS = 32
FILE_ANALYSIS_SLOT_BYTES = 64 << 20
#: A closed segment waiting longer than this for fsync makes the recorder unhealthy: frames still
#: go on into the next segments, but the disk is not keeping its promises.
SETTLE_STALL_S = 30.0
#: After an event window expires (the ring needed its share), health says so for this long.
EXPIRY_ALERT_S = 60.0


def sessions_dir(root: str | os.PathLike) -> Path:
    return DataRoot.of(root).sessions


def new_session_id(sensor_id: str, when_ns: int | None = None) -> str:
    when_ns = time.time_ns() if when_ns is None else when_ns
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(when_ns // 1_000_000_000))
    clean = "".join(c for c in sensor_id if c.isalnum() or c == "-") or "SENSOR"
    return f"{stamp}_{clean}_{secrets.token_hex(2)}"


@dataclass
class RecordingResult:
    session_id: str
    session_dir: Path
    frames_captured: int
    frames_written: int
    dropped: dict[str, int]
    segments: list[dict[str, Any]]
    wall_s: float
    write_latency_ms: dict[str, Any]
    error: str | None = None
    recovered: list[str] = field(default_factory=list)
    analysis_skipped: int = 0
    # frames the detector cannot analyse because they have no temperature (not a fault: said why)
    analysis_unavailable: int = 0
    analysis_unavailable_why: str | None = None
    events: int = 0
    timing: dict[str, Any] = field(default_factory=dict)
    frames_paused: int = 0  # not recorded on purpose (`thermcap ctl pause`); not drops
    evicted_segments: int = 0
    evicted_bytes: int = 0
    cameras: dict[str, dict[str, Any]] = field(default_factory=dict)  # a session of several cameras
    live: dict[str, Any] | None = None
    # complete in .active files but never confirmed by the disk (fsync stalled): not counted as
    # written, since a power cut may still take them; `thermcap recover` keeps them once it answers
    frames_unconfirmed: int = 0
    # where the detector ran ("process", or "thread" and why), its CPU and any failure
    analysis_runner: dict[str, Any] | None = None
    # what the (first) source went through: a supervised command's restarts and gaps (the
    # session's "source" is what it is, from describe())
    source_health: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True only when nothing went wrong and nothing was dropped, skipped or missed."""
        return self.error is None and not any(self.dropped.values()) and not self.analysis_skipped \
            and not any(c.get("error") for c in self.cameras.values()) and not source_losses(self.source_health)

    @property
    def problems(self) -> list[str]:
        out = [self.error] if self.error else []
        if any(self.dropped.values()):
            out.append(f"dropped messages per topic: {self.dropped}")
        if self.analysis_skipped:
            failure = (self.analysis_runner or {}).get("failure")
            out.append(f"{self.analysis_skipped} frames not analysed ("
                       f"{failure or 'the detector fell behind or failed'})")
        out.extend(source_losses(self.source_health))
        late = self.timing.get("frames_late") or 0
        if late:
            out.append(f"{late} frames late: the source achieved {self.timing.get('achieved_fps')} fps "
                       f"of the declared {self.timing.get('declared_fps')}")
        for name, cam in self.cameras.items():
            if cam.get("error") and cam["error"] != self.error:
                out.append(f"camera {name}: {cam['error']}")
        return out

    @property
    def frames_dropped(self) -> int:
        return sum_image_topics(self.dropped)

    def to_dict(self) -> dict[str, Any]:
        return {"session_id": self.session_id, "session_dir": str(self.session_dir),
                "frames_captured": self.frames_captured, "frames_written": self.frames_written,
                "frames_unconfirmed": self.frames_unconfirmed, "frames_dropped": self.frames_dropped,
                "dropped": self.dropped, "segments": self.segments,
                "wall_s": round(self.wall_s, 3), "write_latency_ms": self.write_latency_ms,
                "error": self.error, "recovered": self.recovered, "ok": self.ok, "problems": self.problems,
                "analysis_skipped": self.analysis_skipped, "analysis_unavailable": self.analysis_unavailable,
                "analysis_unavailable_why": self.analysis_unavailable_why, "events": self.events,
                "timing": self.timing, "analysis_runner": self.analysis_runner,
                "frames_paused": self.frames_paused, "evicted_segments": self.evicted_segments,
                "evicted_bytes": self.evicted_bytes, "source_health": self.source_health,
                **({"cameras": self.cameras} if self.cameras else {}),
                **({"live": self.live} if self.live is not None else {})}


@dataclass
class CameraFeed:
    """One camera of a session: its source, topics, sidecar encoder, detector, triggers and
    counts. Its capture thread is the only writer of ``captured``/``paused``/the capture clock;
    the writer thread the only writer of ``written``."""

    topics: CameraTopics
    source: FrameSource
    sidecars: SidecarEncoder
    can_wait: bool
    detector: HotSpotDetector | None = None
    runner: DetectorRunner | None = None  # started with the recording, closed after its last frame
    runner_fallback: str | None = None  # why the detector runs in a thread, not a child process
    analysis_period_ns: int = 0
    next_analysis_ns: int = 0
    events: EventBuilder = field(default_factory=EventBuilder)
    triggers: TriggerWatch | None = None
    captured: int = 0
    written: int = 0
    paused: int = 0
    analysis_skipped: int = 0
    # how long the writer waited for the detector's answers (a source that waits: every frame is
    # analysed, so a costly scene holds the recording), and how often each of its caps bit
    analysis_wait_ns: int = 0
    analysis_capped: dict[str, int] = field(default_factory=dict)
    pauses: list[list[int | None]] = field(default_factory=list)  # [first paused frame, first after]
    first_mono: int | None = None
    last_mono: int | None = None
    last_wall: float = field(default_factory=time.monotonic)
    error: str | None = None
    ended: bool = False  # its capture thread finished: the input ended, a stop, or a failure
    waiting: bool = False  # blocked on a full queue (a source that can wait), not stalled
    counts_range: CountsRange = field(default_factory=CountsRange)  # for the session's Foxglove layout
    thread_ids: dict[str, int] = field(default_factory=dict)  # "capture"/"analysis" -> native id (CPU accounting)

    @property
    def name(self) -> str | None:
        return self.topics.name

    @property
    def label(self) -> str:
        return self.name or self.source.sensor.sensor_id

    def message_topics(self, frame: CapturedFrame) -> list[str]:
        return [self.topics.image, self.topics.metadata] + [self.topics.extra(t) for t, _ in frame.messages]

    def timing(self) -> dict[str, Any]:
        """How the frames were timed and whether the source kept its rate: never hidden."""
        declared = float(self.source.sensor.frame_rate_hz or 0.0)
        n, span = self.captured, None
        if self.first_mono is not None and self.last_mono is not None and n > 1:
            span = (self.last_mono - self.first_mono) / 1e9
        achieved = round((n - 1) / span, 3) if span else None
        return {"time_basis": getattr(self.source, "time_basis", "capture"), "declared_fps": declared,
                "achieved_fps": achieved, "frames_late": int(getattr(self.source, "frames_late", 0))}

    def summary(self, dropped: dict[str, int]) -> dict[str, Any]:
        return {"sensor_id": self.source.sensor.sensor_id, "frames_captured": self.captured,
                "frames_written": self.written, "frames_dropped": dropped.get(self.topics.image, 0),
                "frames_paused": self.paused, "analysis_skipped": self.analysis_skipped,
                "timing": self.timing(), "error": self.error, "ended": self.ended,
                "seconds_since_last_frame": round(time.monotonic() - self.last_wall, 3)}


class Recorder:
    """Record one session from ``source`` into ``<root>/sessions/<id>/``.

    :param source: one source (the ``/thermal/image`` layout), or ``{name: source}`` for a session
        of several cameras on one clock (``/thermal/<name>/image``, ...).
    :param queue_frames: capacity of the capture -> writer queue (about 2 s at 60 fps by default;
        640x512 frames make that 79 MB at most), shared by the cameras.
    :param writer_delay_s: an artificial pause per frame on the writer thread, for testing the
        drop accounting; never set it in production.
    :param wait_when_full: capture waits for the writer instead of dropping. Always on for a
        source that can wait (a file, a pipe, an importer: ``source.can_wait``), since nothing is
        lost by waiting; only a live camera, which cannot be paused, ever drops (counted).
    :param live: the live view to offer each written frame to (it never makes us wait).
    """

    def __init__(self, source: FrameSource | Mapping[str, FrameSource], root: str | os.PathLike, *,
                 session_id: str | None = None,
                 policy: SegmentPolicy | None = None, queue_frames: int = 120, stats_interval_s: float = 1.0,
                 writer_delay_s: float = 0.0, recover_leftovers: bool = True, analysis: bool = True,
                 analysis_queue: int = 8, analysis_wait_s: float = 0.25, analysis_max_fps: float | None = None,
                 analysis_runner: str = "process", wait_when_full: bool = False, ring: RingPolicy | None = None,
                 triggers: TriggerPolicy | None = None, stall_s: float = 5.0,
                 live: LiveBranch | None = None, stop_grace_s: float = 5.0) -> None:
        sources: dict[str | None, FrameSource] = {None: source} if not isinstance(source, Mapping) else \
            {str(k): v for k, v in source.items()}
        if not sources:
            raise RecordingError("no source to record")
        self.multi = isinstance(source, Mapping)
        self.source = next(iter(sources.values()))  # the first camera (the only one, usually)
        self.root = Path(root)
        label = "-".join(str(n) for n in sources)[:40] if self.multi else self.source.sensor.sensor_id
        self.session_id = session_id or new_session_id(label)
        self.session_dir = sessions_dir(self.root) / self.session_id
        self.policy = policy or SegmentPolicy()
        self.queue: queue.Queue = queue.Queue(maxsize=max(1, queue_frames))
        self.stats_interval_s = stats_interval_s
        self.writer_delay_s = writer_delay_s
        self.recover_leftovers = recover_leftovers
        self.counters = RecorderCounters()
        self.latency = LatencyHistogram()
        self._interval_latency = LatencyHistogram()
        self._stop = threading.Event()
        self._writer_error: str | None = None
        self._disk_stalled = False  # fsync stopped answering: the last writes cannot wait for it
        self._unavailable_why: str | None = None
        self._stop_seen = False  # the writer took every capture thread's stop token
        self._signals = 0
        self._session: SessionWriter | None = None
        self._last_frame_ns: int | None = None
        # Analysis beside recording: a child process (or a thread) and bounded slots per camera;
        # when it falls behind, a live camera's frames go unanalysed (sidecar source "skipped",
        # counted), capture never waits for it. It runs at most at the source's frame rate so an
        # as-fast-as-possible import does not starve writing.
        self.feeds: list[CameraFeed] = []
        for name, src in sources.items():
            can_wait = wait_when_full or bool(getattr(src, "can_wait", False))
            feed = CameraFeed(topics=camera_topics(name), source=src, can_wait=can_wait,
                              sidecars=SidecarEncoder(src.sensor.to_sidecar(), _radiometric_block(src.model)),
                              triggers=TriggerWatch(triggers) if triggers is not None else None)
            if analysis:
                feed.detector = HotSpotDetector(src.model, bad_pixel_map=src.bad_pixel_map)
                feed.analysis_period_ns = int(1e9 / (analysis_max_fps or src.sensor.frame_rate_hz or 60.0))
            self.feeds.append(feed)
            src.report = lambda ev, feed=feed: self._requests.put(("source_event", (feed, ev)))
        self.analysis_wait_s = analysis_wait_s
        if analysis_runner not in ("process", "thread"):
            raise RecordingError(f"analysis_runner must be 'process' or 'thread', not {analysis_runner!r}")
        self.analysis_runner = analysis_runner
        self.analysis_slots = max(1, analysis_queue)
        # Control while recording (thermcap ctl): requests are queued to the writer thread, which
        # acts on them between two frames, so a split or a mark never loses or repeats a frame.
        self.ring = ring
        self.stall_s = stall_s
        self.stop_grace_s = stop_grace_s
        self._requests: queue.SimpleQueue = queue.SimpleQueue()
        self._paused = threading.Event()
        self._recorder_events: list[dict[str, Any]] = []
        self._book: ProtectionBook | None = None
        self._evictor: Evictor | None = None
        self.writer_thread_id: int | None = None
        self._waiting_for_disk = False
        self.live = live
        if live is not None:
            for feed in self.feeds:
                live.add_camera(feed.name, feed.source.model)
        self.started = threading.Event()

    # -- public -----------------------------------------------------------------------------
    def request_split(self) -> None:
        """Close the open segment after the frame being written; the next frame opens a new one."""
        self._requests.put(("split", ""))

    def pause(self) -> bool:
        """Stop recording frames (capture goes on reading the source, so a camera never backs up);
        the gap is recorded as a pause. False if already paused."""
        if self._paused.is_set():
            return False
        self._paused.set()
        self._requests.put(("pause", ""))
        return True

    def resume(self) -> bool:
        if not self._paused.is_set():
            return False
        self._paused.clear()
        self._requests.put(("resume", ""))
        return True

    def mark(self, note: str = "", reason: str = "manual") -> dict[str, Any] | None:
        """An event at the current frame, on the events topic and in events.json; with --ring its
        window (pre/post) is protected from eviction. Returns what the ring will keep of it
        (``mark_outlook``), so the one who marks hears it now, not when the window expires."""
        self._requests.put(("mark", f"{reason}\0{note}"))
        return self.mark_outlook()

    def mark_outlook(self) -> dict[str, Any] | None:
        """What a window made now would hold, against the share of the ring's budget event
        windows may hold (``--max-protected``, half of ``--max-disk`` by default), at the rate
        this session has been written: ``kept`` is "whole", "whole, older windows expire" or
        "not whole" with the seconds that fit. None without a ring."""
        ring = self.ring
        if ring is None:
            return None
        out: dict[str, Any] = {"pre_s": ring.pre_s, "post_s": ring.post_s}
        budget = None if ring.keep_events else ring.protected_budget
        rate = self._session.bytes_per_s() if self._session is not None else None
        if budget is None or rate is None:
            out["kept"] = "whole" if budget is None else "whole, if it fits (no rate measured yet)"
            return out
        # a window keeps the whole segments it touches: up to one more than it spans end to end
        seg_s = min(filter(None, (self.policy.max_duration_s,
                                  self.policy.max_bytes / rate if self.policy.max_bytes else None)), default=None)
        span_s = ring.pre_s + ring.post_s
        if seg_s:
            span_s = (math.ceil(span_s / seg_s) + 1) * seg_s
        want = int(span_s * rate)
        in_use = self._evictor.protected_bytes() if self._evictor is not None else 0
        fits_s = round(budget / rate, 1)
        out.update(bytes_per_s=int(rate), window_bytes=want, protected_budget=budget, protected_in_use=in_use)
        if want <= budget - in_use:
            out["kept"] = "whole"
        elif want <= budget:
            out["kept"] = "whole, older windows expire to make room"
        else:
            out.update(kept="not whole", seconds_that_fit=fits_s,
                       why=f"a {ring.pre_s + ring.post_s:g} s window is about {want / 1e6:,.0f} MB at "
                           f"{rate / 1e6:,.1f} MB/s in the whole segments it touches, over the "
                           f"{budget / 1e6:,.0f} MB event windows may hold; "
                           f"about {fits_s:g} s fit: shorten --pre/--post or raise --max-protected/--max-disk")
        return out

    @property
    def paused(self) -> bool:
        return self._paused.is_set()

    @property
    def frames_paused(self) -> int:
        return sum(f.paused for f in self.feeds)

    @property
    def _pauses(self) -> list[list[int | None]]:
        """The session's pauses, on the frames' clock: the first camera's (all pause together)."""
        return self.feeds[0].pauses

    def status(self) -> dict[str, Any]:
        c = self.counters
        seg = self._session.segments[-1].name if self._session and self._session.segments else None
        out: dict[str, Any] = {
            "session_id": self.session_id, "session_dir": str(self.session_dir), "paused": self.paused,
            "frames_captured": c.frames_captured, "frames_written": c.frames_written,
            "frames_paused": self.frames_paused, "dropped": dict(c.dropped),
            "queue_depth": self.queue.qsize(), "queue_capacity": self.queue.maxsize, "segment": seg,
            "segments": len(self._session.segments) if self._session else 0,
            "write_latency_ms": self.latency.summary_ms(), "events": len(self._recorder_events),
            "source_health": self.source.health(),
            "last_event": self._recorder_events[-1] if self._recorder_events else None,
            "seconds_since_last_frame": round(time.monotonic() - max(f.last_wall for f in self.feeds), 3),
            "cameras": {f.label: f.summary(c.dropped) for f in self.feeds},
            "segments_settling": (settling := self._settling()),
        }
        if self._evictor is not None:
            st = self._evictor.state
            out["ring"] = {"evicted_segments": st.evicted_segments, "evicted_bytes": st.evicted_bytes,
                           "blocked": st.blocked, "blocked_reason": st.blocked_reason,
                           "windows_expired": st.windows_expired, "last_expired": st.last_expired,
                           "protected_windows": len(self._book.windows) if self._book else 0,
                           # what a mark made now would keep: a dashboard sees it before anyone marks
                           "mark_would_keep": self.mark_outlook()}
        if self.live is not None:
            out["live"] = {"url": self.live.url, **self.live.snapshot()}
        healthy, reasons = self.health(settling=settling)  # the same snapshot the status shows
        out["healthy"], out["problems"] = healthy, reasons
        return out

    def health(self, max_dropped: int = 0, *, settling: list[dict[str, Any]] | None = None) -> tuple[bool, list[str]]:
        """Unhealthy when a camera stops giving frames (and we are not paused), when drops exceed
        ``max_dropped``, when a camera or the writer failed, when a closed segment has waited
        more than ``SETTLE_STALL_S`` for fsync, or when the ring cannot free space."""
        reasons = []
        for f in self.feeds:
            who = f"camera {f.name}: " if self.multi else ""
            quiet = time.monotonic() - f.last_wall
            if f.error:
                reasons.append(f"{who}{f.error}")
            elif not self.paused and self.started.is_set() and quiet > self.stall_s:
                reasons.append(f"{who}no frame from the source for {quiet:.1f} s")
        dropped = self.counters.frames_dropped
        if dropped > max_dropped:
            reasons.append(f"{dropped} frames dropped")
        if self._writer_error:
            reasons.append(self._writer_error)
        settling = self._settling() if settling is None else settling
        if settling and settling[0]["waiting_s"] > SETTLE_STALL_S:
            reasons.append(f"disk: segment {settling[0]['name']} has waited {settling[0]['waiting_s']:.0f} s for "
                           f"fsync ({len(settling)} closed segments waiting; frames are still written)")
        expired_at = self._evictor.state.last_expired_mono if self._evictor is not None else None
        if expired_at is not None and time.monotonic() - expired_at < EXPIRY_ALERT_S:
            assert self._evictor is not None
            reasons.append(f"ring: an event window expired to keep recording ({self._evictor.state.last_expired})")
        if self._evictor is not None and self._evictor.state.blocked:
            reasons.append(f"ring cannot free space: {self._evictor.state.blocked_reason}"
                           + ("; waiting for disk (the source is not read meanwhile, nothing is lost)"
                              if self._waiting_for_disk else ""))
        return not reasons, reasons

    def _settling(self) -> list[dict[str, Any]]:
        """Closed segments still waiting for fsync and their final name, oldest first."""
        session = self._session
        return [{"name": n, "waiting_s": round(s, 3)} for n, s in session.settling()] if session else []

    def stop(self) -> None:
        """Ask for a clean stop (Ctrl-C): capture ends, queued frames are written, segments close."""
        self._stop.set()
        for f in self.feeds:
            f.source.stop()

    def run(self, duration_s: float | None = None,
            progress: Callable[[Recorder], None] | None = None) -> RecordingResult:
        recovered: list[str] = []
        if self.recover_leftovers:
            from thermcap.recorder.storage.recover import recover_leftovers
            recovered = [str(p) for p in recover_leftovers(self.root)]
        try:
            self.session_dir.mkdir(parents=True, exist_ok=False)
        except OSError as exc:
            raise RecordingError(f"cannot create session folder {self.session_dir}: {exc.strerror or exc}") from exc
        lock = lock_session(self.session_dir, "recorder")
        if lock is None:
            raise RecordingError(f"{self.session_dir}: cannot take the session lock (another process holds it)")
        started_ns = time.time_ns()
        meta = self._session_meta(started_ns)
        try:
            write_json_atomic(SessionLayout.of(self.session_dir).session_json, {**meta, "status": "recording"})
            _take_reserve(SessionLayout.of(self.session_dir).reserve)
        except OSError as exc:
            lock.release()
            raise RecordingError(f"cannot start recording in {self.session_dir}: {exc.strerror or exc} (a recording "
                                 f"needs {RESERVE_BYTES >> 20} MiB kept for its summary, and room for its "
                                 f"segments)") from exc
        extra_topics = {f.topics.extra(t): schema for f in self.feeds for t, schema in f.source.extra_topics.items()}
        bad_pixels: Any = self.source.bad_pixel_map
        if self.multi:
            bad_pixels = {f.name: f.source.bad_pixel_map for f in self.feeds if f.source.bad_pixel_map is not None}
        self._session = SessionWriter(self.session_dir, session_meta=meta, extra_topics=extra_topics,
                                      bad_pixel_map=bad_pixels, policy=self.policy,
                                      on_chunk_written=self._chunk_written, on_segment_closed=self._segment_closed,
                                      cameras=[str(f.name) for f in self.feeds] if self.multi else None,
                                      segment_attachments=self._segment_attachments)
        if self.ring is not None:
            self._book = ProtectionBook(self.session_dir)
            self._evictor = Evictor(self.root, self.ring, {self.session_dir: self._book},
                                    log=lambda m: print(f"thermcap: {m}", file=sys.stderr, flush=True))
            self._evictor.start()
        t0 = time.monotonic()
        deadline = None if duration_s is None else t0 + duration_s
        self._start_runners()
        writer = threading.Thread(target=self._writer_loop, name="thermcap-writer", daemon=True)
        captures = [threading.Thread(target=self._capture_loop, args=(f, deadline), name=f"thermcap-capture-{f.label}",
                                     daemon=True) for f in self.feeds]
        previous = self._catch_signals()
        writer.start()
        now = time.monotonic()
        for f, c in zip(self.feeds, captures, strict=True):
            f.last_wall = now
            c.start()
        self.started.set()
        stop_asked: float | None = None
        try:
            while writer.is_alive():
                writer.join(0.25)
                if progress is not None:
                    progress(self)
                past_deadline = deadline is not None and time.monotonic() > deadline
                if stop_asked is None and (self._stop.is_set() or past_deadline):
                    stop_asked = time.monotonic()
                    for f in self.feeds:  # a source waiting for its input (a command giving nothing) hears it too
                        f.source.stop()
                if stop_asked is not None and time.monotonic() - stop_asked > self.stop_grace_s:
                    self._abandon_stalled(captures)
        finally:
            self._close_runners()
            self._restore_signals(previous)
            if self._evictor is not None:
                self._evictor.stop()
        wall = time.monotonic() - t0
        failed = [f for f in self.feeds if f.error]
        source_error = None
        if failed and len(failed) == len(self.feeds):  # with several cameras, one failing is not the session's end
            source_error = failed[0].error if not self.multi else \
                "every camera failed: " + "; ".join(f"{f.name}: {f.error}" for f in failed)
        error = self._writer_error or source_error
        events = [e for f in self.feeds for e in self._camera_events(f)] + self._recorder_events
        SessionLayout.of(self.session_dir).reserve.unlink(missing_ok=True)  # room for what follows
        written = self.counters.frames_written
        lost_on_disk = unconfirmed = 0
        if self._writer_error:  # count what is durably there, not what was handed to the writer
            written, unconfirmed = self._durable_frames()
            lost_on_disk = max(0, self.counters.frames_written - written - unconfirmed)
        with contextlib.suppress(OSError):  # a full disk: the events can be rebuilt with `thermcap analyze`
            write_json_atomic(SessionLayout.of(self.session_dir).events_json,
                              {"session_id": self.session_id, "events": events}, fsync=not self._disk_stalled)
        with contextlib.suppress(OSError):  # a full disk: `thermcap layout` writes it again
            write_layout(self.session_dir, {f.name: f.counts_range.bounds() for f in self.feeds})
        result = RecordingResult(
            session_id=self.session_id, session_dir=self.session_dir,
            frames_captured=self.counters.frames_captured, frames_written=written,
            dropped=dict(self.counters.dropped), segments=[s.to_dict() for s in self._session.segments],
            wall_s=wall, write_latency_ms=self.latency.summary_ms(), error=error, recovered=recovered,
            analysis_skipped=self.counters.analysis_skipped, analysis_unavailable=self.counters.analysis_unavailable,
            analysis_unavailable_why=self._unavailable_why, events=len(events), timing=self.timing(),
            frames_paused=self.frames_paused,
            evicted_segments=self._evictor.state.evicted_segments if self._evictor else 0,
            evicted_bytes=self._evictor.state.evicted_bytes if self._evictor else 0,
            cameras={str(f.name): f.summary(self.counters.dropped) for f in self.feeds} if self.multi else {},
            analysis_runner=self._runner_summary(),
            live=self.live.snapshot() if self.live is not None else None, frames_unconfirmed=unconfirmed,
            source_health=self.source.health())
        if lost_on_disk:
            result.error = (f"{result.error}; {lost_on_disk} frames handed to the writer never reached a closed "
                            f"chunk and are lost ({written} are on disk)")
        summary = {**meta, "status": "complete" if error is None else "failed", "ended_ns": time.time_ns(),
                   "pauses": self._pauses,
                   **{k: v for k, v in result.to_dict().items() if k not in ("session_dir", "recovered", "ok", "live")}}
        if self.multi:  # the per-camera figures beside the per-camera sensor and model
            summary["cameras"] = {str(f.name): {**meta["cameras"][str(f.name)], **result.cameras[str(f.name)],
                                                "pauses": f.pauses} for f in self.feeds}
        try:
            write_json_atomic(SessionLayout.of(self.session_dir).session_json, summary, fsync=not self._disk_stalled)
        except OSError as exc:
            result.error = result.error or f"cannot write session summary: {exc.strerror or exc}"
        lock.release()
        return result

    def _durable_frames(self) -> tuple[int, int]:
        """Frames on disk after a write error: closed segments' counts, and the whole chunks of
        the segment the error cut (what ``recover`` keeps); and, apart, the frames of segments the
        disk never confirmed (a stalled fsync), which a user must not be told are safe."""
        from thermcap.recorder.exceptions import McapFileError
        from thermcap.recorder.storage.reader import count_frames
        from thermcap.recorder.storage.recover import durable_frames

        layout = SessionLayout.of(self.session_dir)
        n = unconfirmed = 0
        with contextlib.suppress(McapFileError, OSError):
            n += sum(count_frames(self.session_dir).values())
        for active in layout.active_segments():
            if self._disk_stalled:
                unconfirmed += durable_frames(active)
            else:
                n += durable_frames(active)
        return n, unconfirmed

    def _camera_events(self, feed: CameraFeed) -> list[dict[str, Any]]:
        events = feed.events.finish()
        return [{**e, "camera": feed.name} for e in events] if self.multi else events

    def _abandon_stalled(self, captures: list[threading.Thread]) -> None:
        """A camera that does not stop (a device stuck in a read) must not hold the session open:
        once it has given nothing for the grace period after the stop, its stop token is given for
        it and it is reported as stalled. A camera waiting for queue space is not stalled."""
        for f, c in zip(self.feeds, captures, strict=True):
            quiet = time.monotonic() - f.last_wall
            if c.is_alive() and not f.ended and not f.waiting and quiet > self.stop_grace_s:
                try:
                    self.queue.put_nowait((f, _STOP))
                except queue.Full:
                    continue  # the next pass tries again
                f.error = f.error or f"stalled: no frame and no stop for {quiet:.0f} s"
                f.ended = True

    def timing(self) -> dict[str, Any]:
        """How the frames were timed and whether the source kept its rate (the first camera's; each
        camera's own is in ``cameras``)."""
        return self.feeds[0].timing()

    # -- signals ---------------------------------------------------------------------------------
    def _catch_signals(self) -> Any:
        """Ctrl-C asks for a clean stop; a second one only hurries it (no more waiting for the
        detector), so the open segment is always finished, never cut by an exception."""
        if threading.current_thread() is not threading.main_thread():
            return None

        def on_signal(signum: int, _frame: Any) -> None:
            self._signals += 1
            if self._signals > 1:
                self.analysis_wait_s = 0.0
                print("thermcap: still finishing the open segment (nothing is lost by waiting); "
                      "kill -9 leaves it for `thermcap recover`", file=sys.stderr, flush=True)
            self.stop()

        return signal.signal(signal.SIGINT, on_signal)

    @staticmethod
    def _restore_signals(previous: Any) -> None:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)

    @property
    def queue_depth(self) -> int:
        return self.queue.qsize()

    # -- threads ------------------------------------------------------------------------------
    def _capture_loop(self, feed: CameraFeed, deadline: float | None) -> None:
        counters = self.counters
        feed.thread_ids["capture"] = threading.get_native_id()
        try:
            for frame in feed.source.frames():
                if feed.ended:  # abandoned as stalled: whatever comes now is after the session's end
                    return
                counters.captured()
                feed.captured += 1
                mono = frame.capture_mono_ns or time.monotonic_ns()
                if feed.first_mono is None:
                    feed.first_mono = mono
                feed.last_mono = mono
                feed.last_wall = time.monotonic()
                if self._paused.is_set():  # read and let go: a paused camera must not back up
                    feed.paused += 1
                    if not feed.pauses or feed.pauses[-1][1] is not None:
                        feed.pauses.append([frame.timestamp_ns, None])  # the gap, on the frames' clock
                    if self._stop.is_set() or (deadline is not None and time.monotonic() >= deadline):
                        break
                    continue
                if feed.pauses and feed.pauses[-1][1] is None:
                    feed.pauses[-1][1] = frame.timestamp_ns
                if feed.runner is not None:
                    self._offer_analysis(feed, frame)
                try:
                    if feed.can_wait:
                        feed.waiting = True
                        self.queue.put((feed, frame))
                        feed.waiting = False
                    else:
                        self.queue.put_nowait((feed, frame))
                except queue.Full:
                    counters.drop(feed.message_topics(frame))
                if self._stop.is_set() or (deadline is not None and time.monotonic() >= deadline):
                    break
        except ThermcapError as exc:
            feed.error = str(exc)
        except Exception as exc:  # a source bug must still end the session cleanly
            feed.error = f"source failed: {type(exc).__name__}: {exc}"
        finally:
            with contextlib.suppress(Exception):
                feed.source.close()
            if not feed.ended:
                feed.ended = True
                self.queue.put((feed, _STOP))  # blocks only until the writer frees a slot

    def _analysis_slots(self, feed: CameraFeed, frame_bytes: int) -> int:
        """How many frames the detector may hold. A live camera: ``analysis_queue``, since a
        frame it cannot analyse soon is skipped anyway. A source that waits for the detector:
        at least ``FILE_ANALYSIS_SLOTS`` within ``FILE_ANALYSIS_SLOT_BYTES``, so a burst of costly
        frames or a late wake-up of either process does not stall the other: 8 slots had kept
        a file of noise (sigma 45 counts) to 0.35x (320x256) and 0.43x (640x512) its rate without analysis,
        32 to 0.48x and 0.53x (alternated, median of 3)."""
        if not feed.can_wait:
            return self.analysis_slots
        fit = FILE_ANALYSIS_SLOT_BYTES // max(1, frame_bytes)
        return max(self.analysis_slots, min(FILE_ANALYSIS_SLOTS, max(1, fit)))

    def _start_runners(self) -> None:
        """Each camera's detector in a child process (a thread where none starts), sized for the
        camera's frames; started with the recording so nothing is left running if it never is."""
        for feed in self.feeds:
            if feed.detector is None:
                continue
            sensor = feed.source.sensor
            frame_bytes = int(sensor.width or 0) * int(sensor.height or 0) * 2
            feed.runner, feed.runner_fallback = start_runner(
                feed.detector, self._analysis_slots(feed, frame_bytes), frame_bytes,
                name=f"thermcap-analysis-{feed.label}", prefer=self.analysis_runner)
            if feed.runner_fallback:
                print(f"thermcap: the detector runs in a thread ({feed.runner_fallback})", file=sys.stderr, flush=True)

    def _close_runners(self) -> None:
        for feed in self.feeds:
            if feed.runner is not None:
                feed.runner.close(self.stop_grace_s)

    def _runner_summary(self) -> dict[str, Any] | None:
        runners = [f for f in self.feeds if f.runner is not None]
        if not runners:
            return None
        failures = [getattr(f.runner, "failure", None) for f in runners]
        failures = [x for x in failures if x and x != "closed"]
        return {"runner": runners[0].runner.kind if runners[0].runner else None,
                "fallback": next((f.runner_fallback for f in runners if f.runner_fallback), None),
                "cpu_s": round(sum(f.runner.cpu_s for f in runners if f.runner), 3),
                "slots": [f.runner.slots for f in runners if f.runner],
                # frames too flat for any target, answered without the child (ProcessRunner)
                "answered_in_recorder": sum(getattr(f.runner, "answered_here", 0) for f in runners),
                # what tells a user why analysis slowed a file's recording: the writer's wait for
                # the detector, and the frames where a cap bit (noise or texture), by rule
                "waited_for_detector_s": round(sum(f.analysis_wait_ns for f in runners) / 1e9, 3),
                "capped": {rule: sum(f.analysis_capped.get(rule, 0) for f in runners)
                           for rule in sorted({r for f in runners for r in f.analysis_capped})},
                "failure": failures[0] if failures else None,
                # "compiled", or "warming" when numba compiled them beside this recording (a first
                # run on the machine) and the frames before them were answered on numpy
                "kernels": runners[0].runner.kernels.get("kernels") if runners[0].runner else None,
                "frames_before_kernels": sum(int(f.runner.kernels.get("frames_before_kernels", 0))  # type: ignore[call-overload]
                                             for f in runners if f.runner)}

    def _offer_analysis(self, feed: CameraFeed, frame: CapturedFrame) -> None:
        fut: Future = Future()
        frame.analysis = fut
        assert feed.runner is not None
        if feed.can_wait:  # not real time: every frame is analysed (the source waits for a slot)
            if not feed.runner.submit(frame.pixels, fut, wait=True):
                fut.set_result(None)
            return
        now = time.monotonic_ns()
        if now < feed.next_analysis_ns:
            fut.set_result(None)
            return
        if feed.runner.submit(frame.pixels, fut, wait=False):
            feed.next_analysis_ns = max(feed.next_analysis_ns + feed.analysis_period_ns,
                                        now - feed.analysis_period_ns)
        else:
            fut.set_result(None)

    def _writer_loop(self) -> None:
        session = self._session
        assert session is not None
        self.writer_thread_id = threading.get_native_id()
        next_stats = time.monotonic() + self.stats_interval_s
        running = len(self.feeds)
        try:
            while True:
                try:
                    item = self.queue.get(timeout=0.05)
                except queue.Empty:
                    session.poll()
                    item = None
                if item is not None and item[1] is _STOP:
                    running -= 1
                    if running == 0:
                        self._stop_seen = True
                        self._handle_requests()
                        break
                    item = None
                self._handle_requests()
                if item is not None:
                    feed, frame = item
                    if self.writer_delay_s:
                        time.sleep(self.writer_delay_s)
                    if self._evictor is not None and self._evictor.state.blocked and feed.can_wait:
                        self._wait_for_disk(session)  # a file or a pipe is never dropped from: it waits
                    if self._evictor is not None and self._evictor.state.blocked:
                        # nothing left to evict: drop and count rather than fill the disk
                        self.counters.drop(feed.message_topics(frame))
                        self.counters.disk_dropped += 1
                    else:
                        self._write_frame(feed, frame)
                if time.monotonic() >= next_stats:
                    self._write_stats()
                    next_stats += self.stats_interval_s
            self._write_stats()
            session.close()
        except RecordingError as exc:
            self._writer_error = str(exc)
            self._disk_stalled = isinstance(exc, DiskStalled)
            self._abort(session, running)
        except Exception as exc:
            self._writer_error = f"writer failed: {type(exc).__name__}: {exc}"
            self._abort(session, running)

    def _wait_for_disk(self, session: SessionWriter) -> None:
        """Hold a source that can wait until the ring frees space (a protected window expires
        from the budget's view, an operator frees disk) or a stop is asked; capture stops reading
        it meanwhile, so the pipe backs up instead of losing frames. Said on status and in logs."""
        assert self._evictor is not None
        self._waiting_for_disk = True
        print(f"thermcap: waiting for disk, not reading the source: {self._evictor.state.blocked_reason}",
              file=sys.stderr, flush=True)
        next_try = time.monotonic() + 0.5
        try:
            while self._evictor.state.blocked and not self._stop.is_set():
                self._handle_requests()
                session.poll()
                time.sleep(0.05)
                if time.monotonic() >= next_try:
                    next_try = time.monotonic() + 0.5
                    with contextlib.suppress(Exception):
                        self._evictor.evict_once()
        finally:
            self._waiting_for_disk = False

    def _abort(self, session: SessionWriter, running: int) -> None:
        self.stop()
        session.abandon()
        # Let the capture threads finish their last puts; what they captured is counted as dropped.
        while running > 0:
            try:
                feed, frame = self.queue.get(timeout=1.0)
            except queue.Empty:
                if all(f.ended for f in self.feeds) and self.queue.empty():
                    return
                continue
            if frame is _STOP:
                running -= 1
                continue
            self.counters.drop(feed.message_topics(frame))

    def _handle_requests(self) -> None:
        """On the writer thread, between frames: splits, pauses, marks."""
        while True:
            try:
                kind, arg = self._requests.get_nowait()
            except queue.Empty:
                return
            at = self._last_frame_ns if self._last_frame_ns is not None else time.time_ns()
            if kind == "split":
                assert self._session is not None
                if self._session.current is not None:
                    self._session.close_segment()
                self._record_event({"kind": "split", "at_ns": at})
            elif kind == "pause":
                self._record_event({"kind": "pause", "at_ns": at})
            elif kind == "resume":
                self._record_event({"kind": "resume", "at_ns": at, "frames_paused": self.frames_paused})
            elif kind == "mark":
                reason, _, note = arg.partition("\0")
                self._protect(at, "mark", reason, note)
            elif kind == "source_event":  # a gap the source reported: when it began, with its end
                feed, ev = arg
                self._record_event({**ev, **({"camera": feed.name} if self.multi else {})})

    def _protect(self, at: int, kind: str, reason: str, note: str = "", camera: str | None = None) -> None:
        ev: dict[str, Any] = {"kind": kind, "at_ns": at, "reason": reason, "note": note,
                              "protect_start_ns": None, "protect_end_ns": None}
        if camera is not None:
            ev["camera"] = camera
        if self._book is not None and self.ring is not None:
            w = Window(at - int(self.ring.pre_s * 1e9), at + int(self.ring.post_s * 1e9), reason, note)
            self._book.add(w)
            ev["protect_start_ns"], ev["protect_end_ns"] = w.start_ns, w.end_ns
        self._record_event(ev)

    def _record_event(self, ev: dict[str, Any]) -> None:
        self._recorder_events.append({**ev, "start_ns": ev.get("start_ns") or ev["at_ns"],
                                      "end_ns": ev.get("protect_end_ns") or ev.get("end_ns") or ev["at_ns"]})
        if self._session is not None:
            self._session.write_message(TOPIC_EVENTS, ev["at_ns"], json.dumps(ev, separators=(",", ":")).encode())
        if self.live is not None:
            self.live.offer_event(ev["at_ns"], ev)

    def _segment_closed(self) -> None:
        if self._evictor is not None:  # on the writer thread, between two segments
            try:
                self._evictor.evict_once()
            except Exception as exc:  # eviction must never end a recording: it says so and goes on
                self._evictor.state.blocked = True
                self._evictor.state.blocked_reason = f"eviction failed: {type(exc).__name__}: {exc}"

    def _segment_attachments(self) -> list[tuple[str, str, bytes]]:
        return [(f"{feed.name}/{name}" if self.multi else name, media, data)
                for feed in self.feeds for name, media, data in feed.source.segment_attachments()]

    def _write_frame(self, feed: CameraFeed, frame: CapturedFrame) -> None:
        ts = frame.timestamp_ns
        blocks = self._sidecar_blocks(feed, frame)
        payload = feed.sidecars.encode(blocks)
        feed.events.add(ts, blocks)
        if feed.triggers is not None:
            for reason in feed.triggers.check(blocks):
                self._protect(ts, "trigger", reason, camera=feed.name)
        extra = [(feed.topics.extra(topic), _compact_json(msg).encode(), msg)
                 for topic, msg in frame.messages]
        attachments = frame.attachments if not self.multi else \
            [(f"{feed.name}/{name}", media, data) for name, media, data in frame.attachments]
        assert self._session is not None
        self._session.write_frame(ts, image_message_parts(frame.pixels, ts), payload, extra,
                                  token=frame.capture_mono_ns or None, sequence=frame.index,
                                  attachments=attachments, camera=feed.name, sidecar_doc=blocks)
        self.counters.frames_written += 1
        if feed.written % max(1, int(feed.source.sensor.frame_rate_hz or 1)) == 0:  # about one frame a second
            feed.counts_range.add(frame.pixels)
        feed.written += 1
        self._last_frame_ns = ts if self._last_frame_ns is None else max(ts, self._last_frame_ns)
        if self.live is not None:
            self.live.offer(feed.name, ts, frame.pixels, frame.index, payload)

    def _chunk_written(self, tokens: list[Any]) -> None:
        now = time.monotonic_ns()
        for t in tokens:
            s = (now - t) / 1e9
            self.latency.add(s)
            self._interval_latency.add(s)

    def _write_stats(self) -> None:
        c = self.counters
        dropped = {t: 0 for f in self.feeds for t in (f.topics.image, f.topics.metadata)}
        stats = {
            "frames_captured": c.frames_captured, "frames_written": c.frames_written,
            "dropped": {**dropped, **c.dropped},
            "queue_depth": self.queue.qsize(), "queue_capacity": self.queue.maxsize,
            "write_latency_ms": {"interval": self._interval_latency.summary_ms(), "session": self.latency.summary_ms()},
            "analysis_skipped": c.analysis_skipped,
            "timing": self.timing(),
            "segment": self._session.segments[-1].index if self._session and self._session.segments else 0,
            "frames_paused": self.frames_paused,
        }
        if self.multi:
            stats["cameras"] = {str(f.name): f.summary(c.dropped) for f in self.feeds}
        if self._evictor is not None:
            st = self._evictor.state
            stats["ring"] = {"evicted_segments": st.evicted_segments, "evicted_bytes": st.evicted_bytes,
                             "blocked": st.blocked, "blocked_reason": st.blocked_reason,
                             "windows_expired": st.windows_expired, "frames_dropped_for_disk": c.disk_dropped}
        if self.live is not None:
            stats["live"] = self.live.snapshot()
        self._interval_latency = LatencyHistogram()
        assert self._session is not None
        # On the frames' clock (a replayed or simulated session may not be "now"), never before them.
        log_time = self._last_frame_ns if self._last_frame_ns is not None else time.time_ns()
        self._session.write_message(TOPIC_STATS, log_time, json.dumps(stats, separators=(",", ":")).encode())

    # -- sidecar ------------------------------------------------------------------------------
    def _sidecar_blocks(self, feed: CameraFeed, frame: CapturedFrame) -> dict[str, Any]:
        """The per-frame sidecar blocks; the encoder adds the session's sensor and radiometric ones."""
        extra = frame.sidecar
        capture = {"timestamp": iso_utc(frame.timestamp_ns), "frame_index": frame.index}
        capture.update(extra.get("capture", {}))
        analysis, targets = extra.get("thermal_analysis") or _NO_ANALYSIS, extra.get("targets", [])
        if frame.analysis is not None:
            try:
                if feed.can_wait and not frame.analysis.done():
                    waited = time.perf_counter_ns()
                    result = frame.analysis.result()
                    feed.analysis_wait_ns += time.perf_counter_ns() - waited
                else:
                    result = frame.analysis.result(timeout=None if feed.can_wait else self.analysis_wait_s)
            except FutureTimeout:
                result = None
            if result is None:
                self.counters.analysis_skipped += 1
                feed.analysis_skipped += 1
                analysis, targets = _SKIPPED, []
            elif isinstance(result, Unanalysable):
                self.counters.analysis_unavailable += 1
                self._unavailable_why = result.why
                analysis, targets = _NO_ANALYSIS, []
            else:
                analysis, targets = result[1], [d.to_sidecar() for d in result[0]]
                capped = analysis.get("detection_capped")
                if capped:
                    feed.analysis_capped[capped["rule"]] = feed.analysis_capped.get(capped["rule"], 0) + 1
        return {
            "capture": capture,
            "environment": extra.get("environment", {}),
            "thermal_analysis": analysis,
            "slew_to_cue": extra.get("slew_to_cue") or _NO_CUE,
            "targets": targets,
        }

    def _session_meta(self, started_ns: int) -> dict[str, Any]:
        def camera(src: FrameSource) -> dict[str, Any]:
            return {"sensor": {**src.sensor.to_sidecar(), "sensor_id": src.sensor.sensor_id},
                    "radiometric_model": src.model.to_dict(), "source": src.describe()}

        meta: dict[str, Any] = {"session_id": self.session_id, "started_ns": started_ns,
                                "started": iso_utc(started_ns)}
        if self.multi:
            meta["cameras"] = {str(f.name): {**camera(f.source), "image_topic": f.topics.image,
                                             "metadata_topic": f.topics.metadata} for f in self.feeds}
        else:
            meta.update(camera(self.source))
        meta.update(software_version=__version__, format_version=FORMAT_VERSION)
        if self.ring is not None:
            meta["ring"] = {"max_disk": self.ring.max_disk, "min_free": self.ring.min_free,
                            "min_free_percent": self.ring.min_free_percent, "pre_s": self.ring.pre_s,
                            "post_s": self.ring.post_s, "max_protected": self.ring.protected_budget,
                            "keep_events": self.ring.keep_events}
        return meta


#: a source's own messages of a frame as compact JSON, with an encoder made once (``json.dumps``
#: with options makes one a call); a circular message fails on recursion instead of a marker check
_strict_json = json.JSONEncoder(separators=(",", ":"), check_circular=False, allow_nan=False).encode


#: Bytes kept free for a recording's last words: session.json, events.json and the layout.
RESERVE_BYTES = 1 << 20


def _take_reserve(path: Path) -> None:
    """Allocate the reserve (blocks, not a sparse file), so a disk that fills mid-recording still
    has room for the summary; freed just before it is written."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        try:
            os.posix_fallocate(fd, 0, RESERVE_BYTES)
        except OSError as exc:
            if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
                raise
            with os.fdopen(os.dup(fd), "wb") as f:  # a filesystem without fallocate: write it
                f.write(bytes(RESERVE_BYTES))
        os.fsync(fd)
    except OSError:
        path.unlink(missing_ok=True)
        raise
    finally:
        os.close(fd)


def _compact_json(msg: Any) -> str:
    """Standard JSON, always: a non-finite number (a NaN in a radar cue) is written as null, and
    what it was is kept beside it in ``_non_finite`` (path -> "NaN", "Infinity", "-Infinity"),
    so strict readers take the message and nothing about the value is lost."""
    try:
        return _strict_json(msg)
    except ValueError:
        found: dict[str, str] = {}
        clean = _finite(msg, "", found)
        return _strict_json({**clean, "_non_finite": found} if isinstance(clean, dict)
                            else {"value": clean, "_non_finite": found})


def _finite(value: Any, path: str, found: dict[str, str]) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        found[path or "."] = "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
        return None
    if isinstance(value, dict):
        return {k: _finite(v, f"{path}.{k}" if path else str(k), found) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v, f"{path}[{i}]", found) for i, v in enumerate(value)]
    return value

_NO_ANALYSIS = {"thermal_contrast_grade": 0.0, "max_target_temp_c": None, "min_background_temp_c": None,
                "delta_t_deg_c": None, "snr_db": None, "detection_confidence": None, "source": "none"}
_SKIPPED = {**_NO_ANALYSIS, "source": "skipped"}
_NO_CUE = {"slew_to_cue_active": False, "radar_cue_received": False, "radar_azimuth_deg": None,
           "radar_elevation_deg": None, "radar_range_m": None, "turret_pan_deg": None, "turret_tilt_deg": None,
           "search_pattern_active": False, "state": "idle"}


def _radiometric_block(model: Any) -> dict[str, Any]:
    """The ICD ``radiometric`` block: scale/offset for linear models, null for curves, plus the model."""
    if isinstance(model, LinearModel):
        return {"bit_depth": model.bit_depth, "scale_factor_deg_c_per_count": model.scale_c_per_count,
                "offset_deg_c": model.offset_c, "scene_temp_min_deg_c": round(model.temp_min_c, 4),
                "scene_temp_max_deg_c": round(model.temp_max_c, 4), "calibration_date": None,
                "calibration_method": "factory_blackbody", "model": model.to_dict()}
    return {"bit_depth": getattr(model, "bit_depth", 16), "scale_factor_deg_c_per_count": None, "offset_deg_c": None,
            "scene_temp_min_deg_c": None, "scene_temp_max_deg_c": None, "calibration_date": None,
            "calibration_method": model.kind,
            "model": describe_model(model)}
