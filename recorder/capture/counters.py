"""Recorder counters and a constant-memory latency histogram.

Counts are plain ints, each written by one thread only (the writer: written, skipped), except
those several capture threads share (captured, dropped), which take a lock. The histogram has
fixed log-spaced bins, so an hour-long session's p99 costs the same memory as a second's.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any

__all__ = ["LatencyHistogram", "RecorderCounters"]


class LatencyHistogram:
    """Log-spaced bins from 10 us to 100 s, about 4% wide: percentiles to that resolution."""

    _LO = 1e-5
    _STEP = 1.04

    def __init__(self) -> None:
        self.bins = [0] * (int(math.log(1e7) / math.log(self._STEP)) + 2)
        self.count = 0
        self.max_s = 0.0
        self.sum_s = 0.0

    def add(self, seconds: float) -> None:
        i = 0 if seconds <= self._LO else min(len(self.bins) - 1,
                                              int(math.log(seconds / self._LO) / math.log(self._STEP)) + 1)
        self.bins[i] += 1
        self.count += 1
        self.sum_s += seconds
        if seconds > self.max_s:
            self.max_s = seconds

    def percentile(self, q: float) -> float | None:
        if not self.count:
            return None
        rank = q / 100.0 * self.count
        seen = 0
        for i, n in enumerate(self.bins):
            seen += n
            if seen >= rank and n:
                return min(self.max_s, self._LO * self._STEP ** i)
        return self.max_s

    def summary_ms(self) -> dict[str, Any]:
        def ms(v: float | None) -> float | None:
            return None if v is None else round(v * 1000, 3)
        return {"count": self.count, "p50": ms(self.percentile(50)), "p99": ms(self.percentile(99)),
                "max": ms(self.max_s if self.count else None),
                "mean": ms(self.sum_s / self.count if self.count else None)}


@dataclass
class RecorderCounters:
    frames_captured: int = 0
    frames_written: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    analysis_skipped: int = 0
    analysis_unavailable: int = 0  # frames with no temperature to analyse (a DJI layout without DJI's SDK)
    disk_dropped: int = 0  # frames the writer let go because the ring could not free space
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def captured(self) -> None:
        with self._lock:  # one capture thread per camera
            self.frames_captured += 1

    def drop(self, topics: list[str]) -> None:
        # capture (queue full) and the writer (ring blocked) may both drop: one lock for the dict
        with self._lock:
            for t in topics:
                self.dropped[t] = self.dropped.get(t, 0) + 1

    @property
    def frames_dropped(self) -> int:
        """Frames of every camera dropped (the image topics' drops)."""
        from thermcap.recorder.icd.topics import sum_image_topics
        return sum_image_topics(self.dropped)
