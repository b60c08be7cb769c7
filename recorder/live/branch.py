"""The live view as a side branch of the recorder: it may lose frames, the recording may not.

The writer thread offers each written frame with ``offer`` (a clock check and a ``put_nowait``,
never a wait). Frames beyond ``max_fps`` are skipped by design; frames that find the branch
busy are dropped and counted. A thread of its own subsamples and publishes; the viewers'
sockets are the SDK's, with their own bounded buffers. Nothing here can slow capture or
writing, whatever the viewers do.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from thermcap.recorder.live.publisher import LiveOptions, LivePublisher
from thermcap.recorder.radiometry import RadiometricModel

__all__ = ["LiveBranch", "LiveCounters"]

_STOP = object()


@dataclass
class LiveCounters:
    offered: int = 0
    published: int = 0
    skipped_for_rate: int = 0  # by design: the live stream runs at --live-fps
    dropped: int = 0  # the branch was still busy with an earlier frame
    errors: int = 0
    last_error: str | None = None

    viewers: int = 0

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class LiveBranch:
    def __init__(self, options: LiveOptions | None = None, publisher: LivePublisher | None = None,
                 depth: int = 2) -> None:
        self.options = options or LiveOptions()
        self.publisher = publisher or LivePublisher(self.options)
        self.counters = LiveCounters()
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, depth))
        self._period_ns = int(1e9 / self.options.max_fps) if self.options.max_fps > 0 else 0
        self._next_ns: dict[str | None, int] = {}
        self.thread_id: int | None = None
        self._thread = threading.Thread(target=self._loop, name="thermcap-live", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return self.publisher.url

    def snapshot(self) -> dict[str, Any]:
        """The counters, with how many viewers are subscribed now."""
        self.counters.viewers = self.publisher.viewers
        return self.counters.to_dict()

    def add_camera(self, camera: str | None, model: RadiometricModel | None) -> None:
        self.publisher.add_camera(camera, model)

    def offer(self, camera: str | None, timestamp_ns: int, pixels: np.ndarray, frame_index: int,
              sidecar: bytes | None) -> None:
        """Called on the writer thread: never blocks, never raises."""
        self.counters.offered += 1
        now = time.monotonic_ns()
        if self._period_ns and now < self._next_ns.get(camera, 0):
            self.counters.skipped_for_rate += 1
            return
        try:
            self._queue.put_nowait(("frame", camera, timestamp_ns, pixels, frame_index, sidecar))
        except queue.Full:
            self.counters.dropped += 1
            return
        nxt = self._next_ns.get(camera, 0) + self._period_ns
        self._next_ns[camera] = max(nxt, now)  # never a burst to catch up after a quiet spell

    def offer_event(self, timestamp_ns: int, event: dict[str, Any]) -> None:
        try:
            self._queue.put_nowait(("event", timestamp_ns, event))
        except queue.Full:
            self.counters.dropped += 1

    def close(self) -> None:
        self._queue.put(_STOP)  # the loop empties the queue quickly: this waits at most one frame
        self._thread.join(timeout=5)
        self.publisher.close()

    def _loop(self) -> None:
        self.thread_id = threading.get_native_id()
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            try:
                if item[0] == "frame":
                    _, camera, ts, pixels, index, sidecar = item
                    self.publisher.publish_frame(camera, ts, pixels, index, sidecar)
                    self.counters.published += 1
                else:
                    self.publisher.publish_event(item[1], item[2])
            except Exception as exc:  # a viewer problem is the viewer's: recording goes on
                self.counters.errors += 1
                self.counters.last_error = f"{type(exc).__name__}: {exc}"
