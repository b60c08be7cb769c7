"""Headerless Gray16 little-endian frames from any readable path or stdin (``raw:PATH``,
``raw:-``): a file, a named FIFO, ``/dev/stdin``, a device.

This is what ``ffmpeg ... -pix_fmt gray16le -f rawvideo -`` or a camera's SDK tool writes, so a
pipe goes straight into a recording. A file or a pipe can wait, so the recorder never drops
from it: it reads the next frame only when the writer has room (back-pressure).

Timestamps (``timestamps``): ``stream`` (the default) stamps frame i at the first frame's
arrival + i/fps, its position in the stream at the declared rate, however fast the file is read;
``arrival`` stamps each frame when it arrives (wall clock, kept monotonic), for a pipe from a
live camera tool. With ``paced`` frames are released at the stated fps (a file replayed in real
time). A short final frame raises TruncatedFrameError naming the byte count; the recorder keeps
every complete frame before it.
"""

from __future__ import annotations

import io
import os
import stat
import sys
import time
from collections.abc import Iterator
from typing import Any, BinaryIO

import numpy as np

from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, Pacer, SensorInfo
from thermcap.recorder.capture.sources.registry import CameraSettings, SourceKind, register_source
from thermcap.recorder.exceptions import SourceError, TruncatedFrameError
from thermcap.recorder.radiometry import DEFAULT_MODEL, RadiometricModel

__all__ = ["RawSource", "read_exactly"]


class RawSource(FrameSource):
    name = "raw"

    def __init__(self, path: str, *, width: int, height: int, fps: float = 60.0, paced: bool = False,
                 sensor_id: str = "GRAY16", sensor_model: str = "raw Gray16 stream",
                 model: RadiometricModel = DEFAULT_MODEL, max_frames: int | None = None,
                 stream: BinaryIO | None = None, timestamps: str = "stream") -> None:
        if width <= 0 or height <= 0:
            raise SourceError(f"raw source {path}: width and height must be positive, got {width}x{height}")
        if fps <= 0:
            raise SourceError(f"raw source {path}: fps must be positive, got {fps}")
        if timestamps not in ("stream", "arrival"):
            raise SourceError(f"raw source {path}: timestamps must be 'stream' or 'arrival', got {timestamps!r}")
        self.can_wait = True
        self.time_basis = "capture" if timestamps == "arrival" else "stream"
        self.path = path
        self.width, self.height, self.fps = width, height, fps
        self.paced = paced
        self.model = model
        self.max_frames = max_frames
        self.sensor = SensorInfo(model=sensor_model, sensor_id=sensor_id, width=width, height=height,
                                 frame_rate_hz=fps, pixel_pitch_um=None, netd_mk=None)
        self._stream = stream
        self.file_remainder = 0
        if stream is None and path != "-":
            # any readable path: a file, a named FIFO, /dev/stdin, a device that gives raw frames
            try:
                st = os.stat(path)
            except FileNotFoundError:
                raise SourceError(f"raw source {path}: no such file") from None
            except OSError as exc:
                raise SourceError(f"raw source {path}: {exc.strerror or exc}") from None
            if stat.S_ISDIR(st.st_mode):
                raise SourceError(f"raw source {path}: a directory, not a stream of frames")
            if not os.access(path, os.R_OK):
                raise SourceError(f"raw source {path}: not readable by this user")
            if stat.S_ISREG(st.st_mode):
                if st.st_size == 0:
                    raise SourceError(f"raw source {path}: the file is empty")
                # Checked again while reading (a growing file may differ); said early so a user
                # learns of a wrong --width/--height before a long recording, not after.
                self.file_remainder = st.st_size % (width * height * 2)

    def describe(self) -> dict:
        return {"source": "raw", "path": self.path, "width": self.width, "height": self.height, "fps": self.fps,
                "time_basis": self.time_basis}

    def _open(self) -> BinaryIO:
        if self._stream is not None:
            return self._stream
        if self.path == "-":
            return sys.stdin.buffer
        return open(self.path, "rb", buffering=0)

    def frames(self) -> Iterator[CapturedFrame]:
        frame_bytes = self.width * self.height * 2
        stream = self._open()
        pacer = Pacer(self.fps, self.paced)
        wall0, mono0 = time.time_ns(), time.monotonic_ns()
        index = 0
        try:
            while not self.stopped and (self.max_frames is None or index < self.max_frames):
                buf = bytearray(frame_bytes)
                got = read_exactly(stream, memoryview(buf))
                if got == 0:
                    return
                if got < frame_bytes:
                    raise TruncatedFrameError(self.path if self.path != "-" else "<stdin>", index, got, frame_bytes)
                mono = pacer.wait(index)
                self.frames_late = pacer.late
                if index == 0:
                    wall0, mono0 = time.time_ns(), mono
                if self.time_basis == "stream":
                    ts = wall0 + round(index * 1e9 / self.fps)
                else:
                    ts = wall0 + (mono - mono0)
                pixels = np.frombuffer(buf, dtype="<u2").reshape(self.height, self.width)
                yield CapturedFrame(index=index, timestamp_ns=ts, pixels=pixels, capture_mono_ns=mono)
                index += 1
        finally:
            if stream is not sys.stdin.buffer and self._stream is None:
                stream.close()


def read_exactly(stream: Any, view: memoryview) -> int:
    """Fill ``view`` unless the stream ends; pipes deliver frames in pieces."""
    total = 0
    while total < view.nbytes:
        try:
            n = stream.readinto(view[total:])
        except (OSError, io.UnsupportedOperation) as exc:
            raise SourceError(f"reading the raw stream failed: {exc}") from exc
        if not n:
            break
        total += n
    return total


def _from_settings(path: str, s: CameraSettings) -> RawSource:
    return RawSource(path, width=s.width, height=s.height, fps=s.fps, paced=bool(s.pace),
                     timestamps=s.timestamps, sensor_id=s.sensor_id or "GRAY16")


register_source(SourceKind("raw", "raw:PATH (raw:- for stdin)", _from_settings))
