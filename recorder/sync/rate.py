"""The bandwidth cap: a token bucket whose rate may change with the time of day.

``--max-rate 2MB/s`` caps every byte sent; ``--max-rate "08:00-18:00=512KB/s,4MB/s"`` caps it
to 512 KB/s in working hours (local time) and 4 MB/s otherwise. The bucket holds at most a
quarter of a second of credit, so the link never sees a burst much above the cap.
"""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime

from thermcap.recorder.exceptions import ThermcapError

__all__ = ["RateLimit", "parse_rate"]

_UNITS = {"": 1, "B": 1, "K": 1000, "KB": 1000, "KIB": 1024, "M": 1_000_000, "MB": 1_000_000, "MIB": 1 << 20,
          "G": 1_000_000_000, "GB": 1_000_000_000, "GIB": 1 << 30}


def _bytes_per_s(text: str) -> float:
    m = re.fullmatch(r"\s*([0-9.]+)\s*([a-zA-Z]*?)(?:/s)?\s*", text)
    if not m or m.group(2).upper() not in _UNITS:
        raise ThermcapError(f"--max-rate: {text!r} is not a rate such as 2MB/s, 512KB/s or 1MiB/s")
    rate = float(m.group(1)) * _UNITS[m.group(2).upper()]
    if rate <= 0:
        raise ThermcapError(f"--max-rate: {text!r} must be above zero")
    return rate


@dataclass(frozen=True)
class _Window:
    start_min: int
    end_min: int
    rate: float

    def covers(self, minute: int) -> bool:
        if self.start_min <= self.end_min:
            return self.start_min <= minute < self.end_min
        return minute >= self.start_min or minute < self.end_min  # across midnight


def _minute(hhmm: str) -> int:
    h, m = hhmm.split(":")
    if not (0 <= int(h) <= 24 and 0 <= int(m) < 60):
        raise ValueError(hhmm)
    return int(h) * 60 + int(m)


def parse_rate(text: str | None) -> RateLimit:
    """``None`` or ``""``: no cap. Otherwise a rate, or time windows ``HH:MM-HH:MM=RATE`` with a
    default rate, comma-separated."""
    if not text:
        return RateLimit()
    windows, default = [], None
    for part in text.split(","):
        if "=" in part:
            span, rate = part.split("=", 1)
            try:
                a, b = span.strip().split("-")
                windows.append(_Window(_minute(a), _minute(b), _bytes_per_s(rate)))
            except ValueError:
                raise ThermcapError(f"--max-rate: {part!r} is not a window such as 08:00-18:00=1MB/s") from None
        else:
            default = _bytes_per_s(part)
    return RateLimit(tuple(windows), default)


class RateLimit:
    def __init__(self, windows: tuple[_Window, ...] = (), default: float | None = None,
                 clock: Callable[[], float] = time.monotonic, now: Callable[[], datetime] = datetime.now) -> None:
        self.windows, self.default = windows, default
        self._clock, self._now = clock, now
        self._tokens = 0.0
        self._at = clock()
        self._lock = threading.Lock()

    def rate(self) -> float | None:
        """Bytes per second allowed now (None: no cap)."""
        minute = (lambda d: d.hour * 60 + d.minute)(self._now())
        for w in self.windows:
            if w.covers(minute):
                return w.rate
        return self.default

    def take(self, n: int) -> None:
        """Wait until ``n`` bytes may be sent."""
        while True:
            rate = self.rate()
            if rate is None:
                return
            with self._lock:
                now = self._clock()
                self._tokens = min(self._tokens + (now - self._at) * rate, rate / 4)
                self._at = now
                if self._tokens >= n or (n > rate / 4 and self._tokens >= rate / 4):
                    self._tokens -= n
                    return
                wait = (min(n, rate / 4) - self._tokens) / rate
            time.sleep(max(wait, 0.001))
