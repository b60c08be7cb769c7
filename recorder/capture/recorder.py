"""The real-time recorder: a capture thread, a bounded queue, a writer thread.

A live camera never waits on compression or disk: each frame goes to a bounded queue with
``put_nowait``; when the queue is full the frame is dropped *and counted* per topic (stats
channel, session summary, exit report). A source that can wait (a file, a pipe, an importer)
blocks on the queue instead and loses nothing. The writer thread builds and validates the ICD sidecar,
encodes the image, and feeds the segment writer, whose chunks compress on a thread pool. Memory
is bounded by the queue length plus the chunks in flight, however long the session runs.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import secrets
import signal
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recorder import __version__
from recorder.analysis.detector import EventBuilder, HotSpotDetector
from recorder.capture.counters import LatencyHistogram, RecorderCounters
from recorder.capture.sources.base import CapturedFrame, FrameSource
from recorder.capture.triggers import TriggerPolicy, TriggerWatch
from recorder.exceptions import RecordingError, ThermcapError
from recorder.icd.names import FORMAT_VERSION, iso_utc
from recorder.icd.sidecar import SidecarEncoder
from recorder.icd.topics import TOPIC_EVENTS, TOPIC_IMAGE, TOPIC_METADATA, TOPIC_STATS, image_message_parts
from recorder.radiometry import LinearModel, describe_model
from recorder.storage.layout import SessionLayout
from recorder.storage.lock import lock_session
from recorder.storage.ring import Evictor, ProtectionBook, RingPolicy, Window
from recorder.storage.segments import SegmentPolicy, SessionWriter, write_json_atomic

__all__ = ["Recorder", "RecordingResult", "new_session_id", "sessions_dir"]

_STOP = object()


def sessions_dir(root: str | os.PathLike) -> Path:
    return Path(root) / "sessions"


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
    events: int = 0
    timing: dict[str, Any] = field(default_factory=dict)
    frames_paused: int = 0  # not recorded on purpose (`thermcap ctl pause`); not drops
    evicted_segments: int = 0
    evicted_bytes: int = 0

    @property
    def ok(self) -> bool:
        """True only when nothing went wrong and nothing was dropped or skipped."""
        return self.error is None and not any(self.dropped.values()) and not self.analysis_skipped

    @property
    def problems(self) -> list[str]:
        out = [self.error] if self.error else []
        if any(self.dropped.values()):
            out.append(f"dropped messages per topic: {self.dropped}")
        if self.analysis_skipped:
            out.append(f"{self.analysis_skipped} frames not analysed (the detector fell behind)")
        late = self.timing.get("frames_late") or 0
        if late:
            out.append(f"{late} frames late: the source achieved {self.timing.get('achieved_fps')} fps "
                       f"of the declared {self.timing.get('declared_fps')}")
        return out

    @property
    def frames_dropped(self) -> int:
        return self.dropped.get(TOPIC_IMAGE, 0)

    def to_dict(self) -> dict[str, Any]:
        return {"session_id": self.session_id, "session_dir": str(self.session_dir),
                "frames_captured": self.frames_captured, "frames_written": self.frames_written,
                "frames_dropped": self.frames_dropped, "dropped": self.dropped, "segments": self.segments,
                "wall_s": round(self.wall_s, 3), "write_latency_ms": self.write_latency_ms,
                "error": self.error, "recovered": self.recovered, "ok": self.ok, "problems": self.problems,
                "analysis_skipped": self.analysis_skipped, "events": self.events, "timing": self.timing,
                "frames_paused": self.frames_paused, "evicted_segments": self.evicted_segments,
                "evicted_bytes": self.evicted_bytes}


class Recorder:
    """Record one session from ``source`` into ``<root>/sessions/<id>/``.

    :param queue_frames: capacity of the capture -> writer queue (about 2 s at 60 fps by default;
        640x512 frames make that 79 MB at most).
    :param writer_delay_s: an artificial pause per frame on the writer thread, for testing the
        drop accounting; never set it in production.
    :param wait_when_full: capture waits for the writer instead of dropping. Always on for a
        source that can wait (a file, a pipe, an importer: ``source.can_wait``), since nothing is
        lost by waiting; only a live camera, which cannot be paused, ever drops (counted).
    """

    def __init__(self, source: FrameSource, root: str | os.PathLike, *, session_id: str | None = None,
                 policy: SegmentPolicy | None = None, queue_frames: int = 120, stats_interval_s: float = 1.0,
                 writer_delay_s: float = 0.0, recover_leftovers: bool = True, analysis: bool = True,
                 analysis_queue: int = 8, analysis_wait_s: float = 0.25, analysis_max_fps: float | None = None,
                 wait_when_full: bool = False, ring: RingPolicy | None = None,
                 triggers: TriggerPolicy | None = None, stall_s: float = 5.0) -> None:
        self.source = source
        self.root = Path(root)
        self.session_id = session_id or new_session_id(source.sensor.sensor_id)
        self.session_dir = sessions_dir(self.root) / self.session_id
        self.policy = policy or SegmentPolicy()
        self.queue: queue.Queue = queue.Queue(maxsize=max(1, queue_frames))
        self.stats_interval_s = stats_interval_s
        self.writer_delay_s = writer_delay_s
        self.recover_leftovers = recover_leftovers
        self.wait_when_full = wait_when_full or bool(getattr(source, "can_wait", False))
        self.counters = RecorderCounters()
        self.latency = LatencyHistogram()
        self._interval_latency = LatencyHistogram()
        self._stop = threading.Event()
        self._source_error: str | None = None
        self._writer_error: str | None = None
        self._stop_seen = False  # the writer took the capture thread's stop token
        self._signals = 0
        self._first_capture_mono: int | None = None
        self._last_capture_mono: int | None = None
        self._session: SessionWriter | None = None
        self._last_frame_ns: int | None = None
        self._sidecars = SidecarEncoder(source.sensor.to_sidecar(), _radiometric_block(source.model))
        self._events = EventBuilder()
        # Analysis beside recording: its own thread and bounded queue; when it falls behind, frames
        # go unanalysed (sidecar source "skipped", counted), capture never waits for it. It runs at
        # most at the source's frame rate so an as-fast-as-possible import does not starve writing.
        self._aq: queue.Queue | None = queue.Queue(maxsize=max(1, analysis_queue)) if analysis else None
        self._detector = HotSpotDetector(source.model, bad_pixel_map=source.bad_pixel_map) if analysis else None
        self.analysis_wait_s = analysis_wait_s
        self._analysis_period_ns = int(1e9 / (analysis_max_fps or source.sensor.frame_rate_hz or 60.0))
        self._next_analysis_ns = 0
        # Control while recording (thermcap ctl): requests are queued to the writer thread, which
        # acts on them between two frames, so a split or a mark never loses or repeats a frame.
        self.ring = ring
        self.stall_s = stall_s
        self._requests: queue.SimpleQueue = queue.SimpleQueue()
        self._paused = threading.Event()
        self._pauses: list[list[int | None]] = []  # [first paused frame's time, first recorded after]
        self._frames_paused = 0
        self._recorder_events: list[dict[str, Any]] = []
        self._triggers = TriggerWatch(triggers) if triggers is not None else None
        self._book: ProtectionBook | None = None
        self._evictor: Evictor | None = None
        self._last_capture_wall = time.monotonic()
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

    def mark(self, note: str = "", reason: str = "manual") -> None:
        """An event at the current frame, on the events topic and in events.json; with --ring its
        window (pre/post) is protected from eviction."""
        self._requests.put(("mark", f"{reason}\0{note}"))

    @property
    def paused(self) -> bool:
        return self._paused.is_set()

    def status(self) -> dict[str, Any]:
        c = self.counters
        seg = self._session.segments[-1].name if self._session and self._session.segments else None
        out: dict[str, Any] = {
            "session_id": self.session_id, "session_dir": str(self.session_dir), "paused": self.paused,
            "frames_captured": c.frames_captured, "frames_written": c.frames_written,
            "frames_paused": self._frames_paused, "dropped": dict(c.dropped),
            "queue_depth": self.queue.qsize(), "queue_capacity": self.queue.maxsize, "segment": seg,
            "segments": len(self._session.segments) if self._session else 0,
            "write_latency_ms": self.latency.summary_ms(), "events": len(self._recorder_events),
            "last_event": self._recorder_events[-1] if self._recorder_events else None,
            "seconds_since_last_frame": round(time.monotonic() - self._last_capture_wall, 3),
        }
        if self._evictor is not None:
            st = self._evictor.state
            out["ring"] = {"evicted_segments": st.evicted_segments, "evicted_bytes": st.evicted_bytes,
                           "blocked": st.blocked, "blocked_reason": st.blocked_reason,
                           "protected_windows": len(self._book.windows) if self._book else 0}
        healthy, reasons = self.health()
        out["healthy"], out["problems"] = healthy, reasons
        return out

    def health(self, max_dropped: int = 0) -> tuple[bool, list[str]]:
        """Unhealthy when frames stop arriving (and we are not paused), when drops exceed
        ``max_dropped``, when the writer failed, or when the ring cannot free space."""
        reasons = []
        quiet = time.monotonic() - self._last_capture_wall
        if not self.paused and self.started.is_set() and quiet > self.stall_s:
            reasons.append(f"no frame from the source for {quiet:.1f} s")
        dropped = self.counters.dropped.get(TOPIC_IMAGE, 0)
        if dropped > max_dropped:
            reasons.append(f"{dropped} frames dropped")
        if self._writer_error:
            reasons.append(self._writer_error)
        if self._evictor is not None and self._evictor.state.blocked:
            reasons.append(f"ring cannot free space: {self._evictor.state.blocked_reason}")
        return not reasons, reasons

    def stop(self) -> None:
        """Ask for a clean stop (Ctrl-C): capture ends, queued frames are written, segments close."""
        self._stop.set()
        self.source.stop()

    def run(self, duration_s: float | None = None,
            progress: Callable[[Recorder], None] | None = None) -> RecordingResult:
        recovered: list[str] = []
        if self.recover_leftovers:
            from recorder.storage.recover import recover_leftovers
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
        except OSError as exc:
            lock.release()
            raise RecordingError(f"cannot write {self.session_dir / 'session.json'}: {exc.strerror or exc}") from exc
        self._session = SessionWriter(self.session_dir, session_meta=meta, extra_topics=self.source.extra_topics,
                                      bad_pixel_map=self.source.bad_pixel_map, policy=self.policy,
                                      on_chunk_written=self._chunk_written, on_segment_closed=self._segment_closed)
        if self.ring is not None:
            self._book = ProtectionBook(self.session_dir)
            self._evictor = Evictor(self.root, self.ring, {self.session_dir: self._book},
                                    log=lambda m: print(f"thermcap: {m}", file=sys.stderr, flush=True))
            self._evictor.start()
        t0 = time.monotonic()
        deadline = None if duration_s is None else t0 + duration_s
        analyst = None
        if self._aq is not None:
            analyst = threading.Thread(target=self._analysis_loop, name="thermcap-analysis", daemon=True)
            analyst.start()
        writer = threading.Thread(target=self._writer_loop, name="thermcap-writer", daemon=True)
        capture = threading.Thread(target=self._capture_loop, args=(deadline,), name="thermcap-capture", daemon=True)
        previous = self._catch_signals()
        writer.start()
        capture.start()
        self._last_capture_wall = time.monotonic()
        self.started.set()
        try:
            while capture.is_alive() or writer.is_alive():
                capture.join(0.25)
                if progress is not None:
                    progress(self)
                if not capture.is_alive():
                    writer.join(0.25)
            if analyst is not None:
                analyst.join()
        finally:
            self._restore_signals(previous)
            if self._evictor is not None:
                self._evictor.stop()
        wall = time.monotonic() - t0
        error = self._writer_error or self._source_error
        events = self._events.finish() + self._recorder_events
        with contextlib.suppress(OSError):  # a full disk: the events can be rebuilt with `thermcap analyze`
            write_json_atomic(SessionLayout.of(self.session_dir).events_json,
                              {"session_id": self.session_id, "events": events})
        result = RecordingResult(
            session_id=self.session_id, session_dir=self.session_dir,
            frames_captured=self.counters.frames_captured, frames_written=self.counters.frames_written,
            dropped=dict(self.counters.dropped), segments=[s.to_dict() for s in self._session.segments],
            wall_s=wall, write_latency_ms=self.latency.summary_ms(), error=error, recovered=recovered,
            analysis_skipped=self.counters.analysis_skipped, events=len(events), timing=self.timing(),
            frames_paused=self._frames_paused,
            evicted_segments=self._evictor.state.evicted_segments if self._evictor else 0,
            evicted_bytes=self._evictor.state.evicted_bytes if self._evictor else 0)
        summary = {**meta, "status": "complete" if error is None else "failed", "ended_ns": time.time_ns(),
                   "pauses": self._pauses,
                   **{k: v for k, v in result.to_dict().items() if k not in ("session_dir", "recovered", "ok")}}
        try:
            write_json_atomic(SessionLayout.of(self.session_dir).session_json, summary)
        except OSError as exc:
            result.error = result.error or f"cannot write session summary: {exc.strerror or exc}"
        lock.release()
        return result

    def timing(self) -> dict[str, Any]:
        """How the frames were timed and whether the source kept its rate: never hidden."""
        declared = float(self.source.sensor.frame_rate_hz or 0.0)
        n = self.counters.frames_captured
        span = None
        if self._first_capture_mono is not None and self._last_capture_mono is not None and n > 1:
            span = (self._last_capture_mono - self._first_capture_mono) / 1e9
        achieved = round((n - 1) / span, 3) if span else None
        return {"time_basis": getattr(self.source, "time_basis", "capture"), "declared_fps": declared,
                "achieved_fps": achieved, "frames_late": int(getattr(self.source, "frames_late", 0))}

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
    def _capture_loop(self, deadline: float | None) -> None:
        counters = self.counters
        try:
            for frame in self.source.frames():
                counters.frames_captured += 1
                mono = frame.capture_mono_ns or time.monotonic_ns()
                if self._first_capture_mono is None:
                    self._first_capture_mono = mono
                self._last_capture_mono = mono
                self._last_capture_wall = time.monotonic()
                if self._paused.is_set():  # read and let go: a paused camera must not back up
                    self._frames_paused += 1
                    if not self._pauses or self._pauses[-1][1] is not None:
                        self._pauses.append([frame.timestamp_ns, None])  # the gap, on the frames' clock
                    if self._stop.is_set() or (deadline is not None and time.monotonic() >= deadline):
                        break
                    continue
                if self._pauses and self._pauses[-1][1] is None:
                    self._pauses[-1][1] = frame.timestamp_ns
                if self._aq is not None:
                    self._offer_analysis(frame)
                try:
                    self.queue.put(frame) if self.wait_when_full else self.queue.put_nowait(frame)
                except queue.Full:
                    counters.drop([TOPIC_IMAGE, TOPIC_METADATA] + [t for t, _ in frame.messages])
                if self._stop.is_set() or (deadline is not None and time.monotonic() >= deadline):
                    break
        except ThermcapError as exc:
            self._source_error = str(exc)
        except Exception as exc:  # a source bug must still end the session cleanly
            self._source_error = f"source failed: {type(exc).__name__}: {exc}"
        finally:
            self.source.close()
            self.queue.put(_STOP)  # blocks only until the writer frees a slot
            if self._aq is not None:
                self._aq.put(_STOP)

    def _offer_analysis(self, frame: CapturedFrame) -> None:
        fut: Future = Future()
        frame.analysis = fut
        assert self._aq is not None
        if self.wait_when_full:  # not real time: every frame is analysed
            self._aq.put((frame.pixels, fut))
            return
        now = time.monotonic_ns()
        if now < self._next_analysis_ns:
            fut.set_result(None)
            return
        try:
            self._aq.put_nowait((frame.pixels, fut))
            self._next_analysis_ns = max(self._next_analysis_ns + self._analysis_period_ns,
                                         now - self._analysis_period_ns)
        except queue.Full:
            fut.set_result(None)

    def _analysis_loop(self) -> None:
        assert self._aq is not None and self._detector is not None
        while True:
            item = self._aq.get()
            if item is _STOP:
                return
            pixels, fut = item
            try:
                fut.set_result(self._detector.detect(pixels))
            except Exception:  # a detector failure must not stop recording: the frame says skipped
                fut.set_result(None)

    def _writer_loop(self) -> None:
        session = self._session
        assert session is not None
        next_stats = time.monotonic() + self.stats_interval_s
        try:
            while True:
                try:
                    item = self.queue.get(timeout=0.05)
                except queue.Empty:
                    session.poll()
                    item = None
                if item is _STOP:
                    self._stop_seen = True
                    self._handle_requests()
                    break
                self._handle_requests()
                if item is not None:
                    if self.writer_delay_s:
                        time.sleep(self.writer_delay_s)
                    if self._evictor is not None and self._evictor.state.blocked:
                        # nothing left to evict: drop and count rather than fill the disk
                        self.counters.drop([TOPIC_IMAGE, TOPIC_METADATA] + [t for t, _ in item.messages])
                        self.counters.disk_dropped += 1
                    else:
                        self._write_frame(item)
                if time.monotonic() >= next_stats:
                    self._write_stats()
                    next_stats += self.stats_interval_s
            self._write_stats()
            session.close()
        except RecordingError as exc:
            self._writer_error = str(exc)
            self._abort(session)
        except Exception as exc:
            self._writer_error = f"writer failed: {type(exc).__name__}: {exc}"
            self._abort(session)

    def _abort(self, session: SessionWriter) -> None:
        self.stop()
        session.abandon()
        if self._stop_seen:  # the capture thread already finished (its stop token was taken)
            return
        # Let the capture thread finish its last put; what it captured is counted as dropped.
        while True:
            try:
                item = self.queue.get(timeout=1.0)
            except queue.Empty:
                continue
            if item is _STOP:
                return
            self.counters.drop([TOPIC_IMAGE, TOPIC_METADATA] + [t for t, _ in item.messages])

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
                self._record_event({"kind": "resume", "at_ns": at, "frames_paused": self._frames_paused})
            elif kind == "mark":
                reason, _, note = arg.partition("\0")
                self._protect(at, "mark", reason, note)

    def _protect(self, at: int, kind: str, reason: str, note: str = "") -> None:
        ev: dict[str, Any] = {"kind": kind, "at_ns": at, "reason": reason, "note": note,
                              "protect_start_ns": None, "protect_end_ns": None}
        if self._book is not None and self.ring is not None:
            w = Window(at - int(self.ring.pre_s * 1e9), at + int(self.ring.post_s * 1e9), reason, note)
            self._book.add(w)
            ev["protect_start_ns"], ev["protect_end_ns"] = w.start_ns, w.end_ns
        self._record_event(ev)

    def _record_event(self, ev: dict[str, Any]) -> None:
        self._recorder_events.append({**ev, "start_ns": ev["at_ns"], "end_ns": ev.get("protect_end_ns") or ev["at_ns"]})
        if self._session is not None:
            self._session.write_message(TOPIC_EVENTS, ev["at_ns"], json.dumps(ev, separators=(",", ":")).encode())

    def _segment_closed(self) -> None:
        if self._evictor is not None:  # on the writer thread, between two segments
            try:
                self._evictor.evict_once()
            except Exception as exc:  # eviction must never end a recording: it says so and goes on
                self._evictor.state.blocked = True
                self._evictor.state.blocked_reason = f"eviction failed: {type(exc).__name__}: {exc}"

    def _write_frame(self, frame: CapturedFrame) -> None:
        ts = frame.timestamp_ns
        blocks = self._sidecar_blocks(frame)
        payload = self._sidecars.encode(blocks)
        self._events.add(ts, blocks)
        if self._triggers is not None:
            for reason in self._triggers.check(blocks):
                self._protect(ts, "trigger", reason)
        extra = [(topic, json.dumps(msg, separators=(",", ":")).encode()) for topic, msg in frame.messages]
        assert self._session is not None
        self._session.write_frame(ts, image_message_parts(frame.pixels, ts), payload, extra,
                                  token=frame.capture_mono_ns or None, sequence=frame.index,
                                  attachments=frame.attachments)
        self.counters.frames_written += 1
        self._last_frame_ns = ts

    def _chunk_written(self, tokens: list[Any]) -> None:
        now = time.monotonic_ns()
        for t in tokens:
            s = (now - t) / 1e9
            self.latency.add(s)
            self._interval_latency.add(s)

    def _write_stats(self) -> None:
        c = self.counters
        stats = {
            "frames_captured": c.frames_captured, "frames_written": c.frames_written,
            "dropped": {TOPIC_IMAGE: 0, TOPIC_METADATA: 0, **c.dropped},
            "queue_depth": self.queue.qsize(), "queue_capacity": self.queue.maxsize,
            "write_latency_ms": {"interval": self._interval_latency.summary_ms(), "session": self.latency.summary_ms()},
            "analysis_skipped": c.analysis_skipped,
            "timing": self.timing(),
            "segment": self._session.segments[-1].index if self._session and self._session.segments else 0,
            "frames_paused": self._frames_paused,
        }
        if self._evictor is not None:
            st = self._evictor.state
            stats["ring"] = {"evicted_segments": st.evicted_segments, "evicted_bytes": st.evicted_bytes,
                             "blocked": st.blocked, "blocked_reason": st.blocked_reason,
                             "frames_dropped_for_disk": c.disk_dropped}
        self._interval_latency = LatencyHistogram()
        assert self._session is not None
        # On the frames' clock (a replayed or simulated session may not be "now"), never before them.
        log_time = self._last_frame_ns if self._last_frame_ns is not None else time.time_ns()
        self._session.write_message(TOPIC_STATS, log_time, json.dumps(stats, separators=(",", ":")).encode())

    # -- sidecar ------------------------------------------------------------------------------
    def _sidecar_blocks(self, frame: CapturedFrame) -> dict[str, Any]:
        """The per-frame sidecar blocks; the encoder adds the session's sensor and radiometric ones."""
        extra = frame.sidecar
        capture = {"timestamp": iso_utc(frame.timestamp_ns), "frame_index": frame.index}
        capture.update(extra.get("capture", {}))
        analysis, targets = extra.get("thermal_analysis") or _NO_ANALYSIS, extra.get("targets", [])
        if frame.analysis is not None:
            try:
                result = frame.analysis.result(timeout=None if self.wait_when_full else self.analysis_wait_s)
            except FutureTimeout:
                result = None
            if result is None:
                self.counters.analysis_skipped += 1
                analysis, targets = _SKIPPED, []
            else:
                analysis, targets = result[1], [d.to_sidecar() for d in result[0]]
        return {
            "capture": capture,
            "environment": extra.get("environment", {}),
            "thermal_analysis": analysis,
            "slew_to_cue": extra.get("slew_to_cue") or _NO_CUE,
            "targets": targets,
        }

    def _session_meta(self, started_ns: int) -> dict[str, Any]:
        return {
            "session_id": self.session_id,
            "started_ns": started_ns,
            "started": iso_utc(started_ns),
            "sensor": {**self.source.sensor.to_sidecar(), "sensor_id": self.source.sensor.sensor_id},
            "radiometric_model": self.source.model.to_dict(),
            "source": self.source.describe(),
            "software_version": __version__,
            "format_version": FORMAT_VERSION,
            **({"ring": {"max_disk": self.ring.max_disk, "min_free": self.ring.min_free,
                         "min_free_percent": self.ring.min_free_percent, "pre_s": self.ring.pre_s,
                         "post_s": self.ring.post_s}} if self.ring is not None else {}),
        }


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
