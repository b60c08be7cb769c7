"""Raw Gray16 frames from a command that is kept running (``exec:COMMAND``): ffmpeg reading a
V4L2 camera (``ffmpeg -f v4l2 -input_format y16 -i /dev/video0 -f rawvideo -``), a vendor's
capture tool, anything that writes headerless little-endian Gray16 to its standard output.

On a vehicle a USB camera resets, a driver reloads, a tool crashes: a recording that ended with
its pipe would lose everything after. Here the command is supervised: when it ends, for any
reason, the frames it delivered are kept, a frame it left half-written is counted and dropped
(never written as a frame), the command is started again after a backoff that doubles from
``backoff_s`` to ``max_backoff_s`` (and starts over once a run has delivered frames), and the
time without frames is reported as a ``source_gap`` event with its duration, the command's exit
status and the last line it printed on its standard error. The recording ends only when it is
asked to (Ctrl-C, ``--duration``, ``thermcap ctl stop``).

Frames are stamped when they arrive (``time_basis`` "capture"). A pipe can wait, so the recorder
never drops from it: the command is made to wait by the pipe when the writer is behind.
"""

from __future__ import annotations

import collections
import contextlib
import os
import shlex
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from typing import IO, Any

import numpy as np

from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, SensorInfo
from thermcap.recorder.capture.sources.gaps import GapLog
from thermcap.recorder.capture.sources.raw import read_exactly
from thermcap.recorder.capture.sources.registry import CameraSettings, SourceKind, register_source
from thermcap.recorder.exceptions import SourceError
from thermcap.recorder.radiometry import DEFAULT_MODEL, RadiometricModel

__all__ = ["CommandSource"]

_STDERR_LINES = 20  # what is kept of a command's standard error, for the gap's reason


class CommandSource(FrameSource):
    name = "exec"

    def __init__(self, command: str, *, width: int, height: int, fps: float = 60.0, sensor_id: str = "GRAY16",
                 sensor_model: str = "Gray16 from a command", model: RadiometricModel = DEFAULT_MODEL,
                 max_frames: int | None = None, backoff_s: float = 0.5, max_backoff_s: float = 30.0) -> None:
        try:
            self.argv = shlex.split(command)
        except ValueError as exc:
            raise SourceError(f"exec source {command!r}: {exc}") from None
        if not self.argv:
            raise SourceError("exec source: no command given (exec:COMMAND ARGS...)")
        if shutil.which(self.argv[0]) is None:
            raise SourceError(f"exec source: {self.argv[0]}: no such program on PATH")
        if width <= 0 or height <= 0:
            raise SourceError(f"exec source: width and height must be positive, got {width}x{height}")
        if fps <= 0:
            raise SourceError(f"exec source: fps must be positive, got {fps}")
        self.command = command
        self.width, self.height, self.fps = width, height, fps
        self.model = model
        self.max_frames = max_frames
        self.backoff_s, self.max_backoff_s = backoff_s, max_backoff_s
        self.can_wait = True
        self.time_basis = "capture"
        self.sensor = SensorInfo(model=sensor_model, sensor_id=sensor_id, width=width, height=height,
                                 frame_rate_hz=fps, pixel_pitch_um=None, netd_mk=None)
        self.restarts = 0  # times the command was started again after it ended
        self.incomplete_frames = 0  # frames a command's end left half-written: counted, never written
        self.gaps = GapLog(on_close=self.tell)  # since the command last ended, until a frame
        self._proc: subprocess.Popen | None = None
        self._lock = threading.Lock()
        self._wake = threading.Event()

    def describe(self) -> dict[str, Any]:
        return {"source": "exec", "command": self.command, "width": self.width, "height": self.height,
                "fps": self.fps, "time_basis": self.time_basis}

    def health(self) -> dict[str, Any]:
        return {"restarts": self.restarts, "incomplete_frames": self.incomplete_frames, **self.gaps.health()}

    def stop(self) -> None:
        super().stop()
        self._wake.set()
        with self._lock:
            if self._proc is not None:
                _end(self._proc)

    def frames(self) -> Iterator[CapturedFrame]:
        frame_bytes = self.width * self.height * 2
        index = 0
        delay = self.backoff_s
        while not self.stopped and (self.max_frames is None or index < self.max_frames):
            proc, stderr = self._start()
            delivered = 0
            try:
                assert proc.stdout is not None
                while not self.stopped and (self.max_frames is None or index < self.max_frames):
                    buf = bytearray(frame_bytes)
                    got = read_exactly(proc.stdout, memoryview(buf))
                    if got < frame_bytes:
                        self.incomplete_frames += got > 0
                        break
                    ts = time.time_ns()
                    self.gaps.close(ts, restarts=self.restarts)
                    pixels = np.frombuffer(buf, dtype="<u2").reshape(self.height, self.width)
                    yield CapturedFrame(index=index, timestamp_ns=ts, pixels=pixels,
                                        capture_mono_ns=time.monotonic_ns())
                    index += 1
                    delivered += 1
            finally:
                with self._lock:
                    code = _end(proc)
                    self._proc = None
            if self.stopped or (self.max_frames is not None and index >= self.max_frames):
                break
            if delivered:
                delay = self.backoff_s
            last = stderr[-1] if stderr else ""
            self.gaps.open(f"{self.argv[0]} exited ({_status(code)})" + (f": {last}" if last else ""),
                           exit_code=code, frames_before=index)
            self.restarts += 1
            self._wake.wait(delay)
            delay = min(delay * 2, self.max_backoff_s)
        gap = self.gaps.open_gap
        if gap is not None:  # stopped before a frame came back: the gap ends with the recording
            self.gaps.close(reason=gap["reason"] + "; no frame came before the stop", restarts=self.restarts)

    def close(self) -> None:
        with self._lock:
            if self._proc is not None:
                _end(self._proc)

    def _start(self) -> tuple[subprocess.Popen, collections.deque[str]]:
        stderr: collections.deque[str] = collections.deque(maxlen=_STDERR_LINES)
        try:
            proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, bufsize=0, start_new_session=True)
        except OSError as exc:
            raise SourceError(f"exec source: {self.argv[0]}: {exc.strerror or exc}") from None
        threading.Thread(target=_drain, args=(proc.stderr, stderr), name="thermcap-exec-stderr", daemon=True).start()
        with self._lock:
            self._proc = proc
        if self.stopped:  # a stop that came while it started
            with self._lock:
                _end(proc)
        return proc, stderr


def _drain(stream: IO[bytes] | None, keep: collections.deque[str]) -> None:
    if stream is None:
        return
    with contextlib.suppress(OSError, ValueError):
        for line in stream:
            text = line.decode(errors="replace").strip()
            if text:
                keep.append(text[:500])


def _end(proc: subprocess.Popen) -> int | None:
    """End the command's whole process group (a shell and what it started), politely first."""
    if proc.poll() is None:
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(OSError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5.0)
    with contextlib.suppress(OSError):
        if proc.stdout is not None:
            proc.stdout.close()
    return proc.returncode


def _status(code: int | None) -> str:
    if code is None:
        return "status unknown"
    if code < 0:
        with contextlib.suppress(ValueError):
            return f"killed by {signal.Signals(-code).name}"
    return f"exit code {code}"


def _from_settings(command: str, s: CameraSettings) -> CommandSource:
    return CommandSource(command, width=s.width, height=s.height, fps=s.fps,
                         sensor_id=s.sensor_id or "GRAY16")


register_source(SourceKind("exec", "exec:COMMAND", _from_settings, whole_rest=True))
