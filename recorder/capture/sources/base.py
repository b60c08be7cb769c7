"""What every frame source delivers: Gray16 frames with capture times, and what it knows besides.

A source yields ``CapturedFrame`` objects from ``frames()``. It paces itself (a camera or the
simulator at its frame rate) or not (a file read as fast as possible); the recorder never waits
on it for anything but the next frame. A source that knows more than pixels (the simulator's
ground truth and radar, an importer's vendor metadata) attaches it to the frame.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from thermcap.recorder.radiometry import DEFAULT_MODEL, RadiometricModel

__all__ = ["CapturedFrame", "FrameSource", "Pacer", "SensorInfo"]


@dataclass
class SensorInfo:
    """The ICD ``sensor`` block; ``sensor_id`` is the short name used in ICD file names."""

    model: str = "FLIR Boson 640"
    sensor_id: str = "BOSON640"
    type: str = "uncooled_microbolometer"
    serial_number: str = "unknown"
    spectral_range_um: tuple[float, float] = (8.0, 14.0)
    width: int = 640
    height: int = 512
    pixel_pitch_um: float | None = 12.0
    netd_mk: float | None = 50.0
    frame_rate_hz: float = 60.0

    def to_sidecar(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "model": self.model,
            "type": self.type,
            "serial_number": self.serial_number,
            "spectral_range_um": list(self.spectral_range_um),
            "resolution": {"width": self.width, "height": self.height},
            "frame_rate_hz": self.frame_rate_hz,
        }
        if self.pixel_pitch_um is not None:
            out["pixel_pitch_um"] = self.pixel_pitch_um
        if self.netd_mk is not None:
            out["netd_mk"] = self.netd_mk
        return out


@dataclass
class CapturedFrame:
    index: int
    timestamp_ns: int  # capture time, Unix epoch ns (UTC)
    pixels: np.ndarray  # (H, W) uint16, exactly as the sensor produced it
    capture_mono_ns: int = 0  # monotonic clock at capture, for latency accounting
    # Sidecar blocks the source knows (thermal_analysis, slew_to_cue, targets, capture extras).
    sidecar: dict[str, Any] = field(default_factory=dict)
    # Extra messages that belong with this frame: (topic, payload dict), e.g. radar cues.
    messages: list[tuple[str, dict[str, Any]]] = field(default_factory=list)
    # Set by the recorder: a Future with the detector's result, or None when analysis is off.
    analysis: Any = None
    # Files to keep with the frame as MCAP attachments: (name, media type, bytes), e.g. DJI calibration.
    attachments: list[tuple[str, str, bytes]] = field(default_factory=list)


class FrameSource(ABC):
    """A source of Gray16 frames. Subclasses set ``sensor`` and ``model`` before ``frames()``."""

    name: str = "source"
    sensor: SensorInfo
    model: RadiometricModel = DEFAULT_MODEL
    bad_pixel_map: np.ndarray | None = None
    #: topics (besides image and metadata) this source may emit, with their JSON schemas
    extra_topics: ClassVar[dict[str, dict[str, Any]]] = {}
    #: True for input that can be paused (a file, a pipe, an importer): the recorder then waits
    #: for its writer instead of dropping. Only a live camera, which cannot wait, is dropped from.
    can_wait: bool = False
    #: "capture": each frame's time is when it was taken; "stream": its position in the input at
    #: the declared rate (a file replayed faster or slower than it was recorded).
    time_basis: str = "capture"
    #: frames released more than one frame period after they were due (a source that cannot keep
    #: its declared rate says so instead of stamping frames it did not deliver on time)
    frames_late: int = 0

    #: where a source tells what happened to it while it runs (a command that ended and came
    #: back, a camera that reconnected): the recorder sets it and records each as an event
    report: Callable[[dict[str, Any]], None] | None = None

    def segment_attachments(self) -> list[tuple[str, str, bytes]]:
        """(name, media type, bytes) every segment carries from its start: what describes the
        camera as it is now (a GigE camera's GenICam XML); none for most sources."""
        return []

    def tell(self, event: dict[str, Any]) -> None:
        """Pass an event (a ``source_gap``) to the recorder, which records it; nothing without one."""
        if self.report is not None:
            self.report(event)

    @abstractmethod
    def frames(self) -> Iterator[CapturedFrame]:
        """Yield frames as they are captured; stop at the end of the input or when ``stop()`` is called."""

    def stop(self) -> None:
        self._stopped = True

    @property
    def stopped(self) -> bool:
        return getattr(self, "_stopped", False)

    def close(self) -> None:  # noqa: B027 - an optional hook: most sources have nothing to release
        """Release the input (a file, a device); called once capture ends, however it ends."""

    def describe(self) -> dict[str, Any]:
        return {"source": self.name, "time_basis": self.time_basis}

    def health(self) -> dict[str, Any]:
        """What the source went through while it ran (restarts, gaps), for ``ctl status``, the
        recording's result and ``info``; empty for a source with nothing to tell."""
        return {}


class Pacer:
    """Release frame i at start + i/fps on the monotonic clock; never drifts, never sleeps when late.

    ``late`` counts frames that came more than half a period later than the rate allows after
    the one before (the first: after the start): a stall is seen, not hidden behind evenly
    spaced timestamps, and a source that cannot keep its rate has every frame late. A frame
    behind its slot on the schedule is not late by itself: after one stall, the frames that
    catch up would all be (1,573 "late" of 2,593 at 99.99% of the rate, seen)."""

    def __init__(self, fps: float, enabled: bool = True):
        self.period_ns = round(1e9 / fps)
        self.enabled = enabled
        self.start = time.monotonic_ns()
        self.late = 0
        self._last = self.start

    def wait(self, index: int) -> int:
        """Sleep until frame ``index`` is due; returns the monotonic time it is released."""
        now = time.monotonic_ns()
        if not self.enabled:  # read as fast as it comes (a file): no rate to be late for
            return now
        if now - self._last > self.period_ns * 3 // 2:
            self.late += 1
        delay = self.start + index * self.period_ns - now
        if delay > 0:
            time.sleep(delay / 1e9)
            now = time.monotonic_ns()
        self._last = now
        return now
