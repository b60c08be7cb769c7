"""Where the detector runs beside a recording: in a child process, or in a thread when no child
can start.

A thread shares the interpreter lock with the capture and writer threads, so on a scene that
costs the detector as much as the writer costs a frame, their costs add up and a file source
records at a fraction of its rate (measured: 0.22x on noise at 320x256). A child process runs
the detector on the other core; the recorder only copies each frame into a shared slot.

Both runners answer through the frame's ``Future``: ``(detections, thermal_analysis)``,
:class:`Unanalysable` for a frame without temperatures, or ``None`` when the frame was not
analysed (no free slot for a live source, a detector failure); the writer counts those as
skipped. The detector's state (target ids kept across frames) lives wherever it runs, and
frames reach it in order.
"""

from __future__ import annotations

import queue
import threading
import time
from concurrent.futures import Future
from typing import Protocol

import numpy as np

from thermcap.recorder.analysis import detector_kernels
from thermcap.recorder.analysis.answers import Unanalysable, analyse_one
from thermcap.recorder.analysis.detector import HotSpotDetector

__all__ = ["DetectorRunner", "ThreadRunner", "Unanalysable", "analyse_one", "start_runner"]


class DetectorRunner(Protocol):
    kind: str  # "process" or "thread": said in the session's timing block
    slots: int  # frames it may hold at once
    #: once closed: {"kernels": detector_kernels.state(), "frames_before_kernels": frames answered
    #: on the numpy path while the compiled passes were being built}
    kernels: dict[str, object]

    def submit(self, pixels: np.ndarray, fut: Future, *, wait: bool) -> bool:
        """Hand one frame over. ``wait`` (a source that can wait) blocks for room; otherwise a
        full runner returns False and the caller marks the frame skipped."""

    def close(self, timeout_s: float) -> None:
        """Finish the frames handed over (within ``timeout_s``), then stop."""

    @property
    def cpu_s(self) -> float:
        """CPU seconds the detector has used (a child's are not in the recorder's own)."""

    @property
    def native_ids(self) -> dict[str, int]:
        """Threads of this process that run the detector (for per-thread CPU accounting)."""


class ThreadRunner:
    """The detector in a thread of the recording process, behind a bounded queue."""

    kind = "thread"

    def __init__(self, detector: HotSpotDetector, slots: int, name: str = "thermcap-analysis") -> None:
        self._detector = detector
        self.slots = max(1, slots)
        self._queue: queue.Queue = queue.Queue(maxsize=self.slots)
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._tid: int | None = None
        self._cpu = 0.0
        self.kernels: dict[str, object] = {}  # as ProcessRunner.kernels
        self._before_kernels = 0
        self._thread.start()

    def submit(self, pixels: np.ndarray, fut: Future, *, wait: bool) -> bool:
        if wait:
            self._queue.put((pixels, fut))
            return True
        try:
            self._queue.put_nowait((pixels, fut))
        except queue.Full:
            return False
        return True

    def close(self, timeout_s: float) -> None:
        self._queue.put(None)
        self._thread.join(timeout=timeout_s)

    @property
    def cpu_s(self) -> float:
        return self._cpu

    @property
    def native_ids(self) -> dict[str, int]:
        return {"analysis": self._tid} if self._tid is not None else {}

    def _loop(self) -> None:
        self._tid = threading.get_native_id()
        detector_kernels.warm_in_background()  # numpy answers until the compiled passes run
        self._detector.prime()
        while True:
            item = self._queue.get()
            if item is None:
                self.kernels = {"kernels": detector_kernels.state(), "frames_before_kernels": self._before_kernels}
                return
            pixels, fut = item
            self._before_kernels += detector_kernels.state() == "warming"
            t = time.thread_time()
            result = analyse_one(self._detector, pixels)
            self._cpu += time.thread_time() - t
            fut.set_result(result)


def start_runner(detector: HotSpotDetector, slots: int, frame_bytes: int, name: str,
                 prefer: str = "process") -> tuple[DetectorRunner, str | None]:
    """A runner for one camera's detector: a child process where one starts, else a thread.
    Returns the runner and, when the thread was the fallback, why."""
    if prefer == "process":
        from thermcap.recorder.analysis.process_runner import ProcessRunner, RunnerUnavailable

        try:
            return ProcessRunner(detector, slots, frame_bytes, name=name), None
        except RunnerUnavailable as exc:
            return ThreadRunner(detector, slots, name=name), str(exc)
    return ThreadRunner(detector, slots, name=name), None
