"""The time a live source gave no frames, kept one way for every source that can lose its input.

A supervised command that ended and came back, a GigE camera that went away and was reconnected:
each is a ``source_gap`` event with when it began and ended, its duration, why, and what the
source knows of the frames it missed. The event is reported when the gap closes (at the first
frame after it, or at the stop), since only then is its length known; ``ctl status`` sees an
open one through ``health()``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

__all__ = ["GapLog"]


class GapLog:
    """The gaps of one source: at most one open, the closed ones kept for ``health()``."""

    def __init__(self, on_close: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.closed: list[dict[str, Any]] = []
        self.open_gap: dict[str, Any] | None = None
        self.on_close = on_close

    def open(self, reason: str, start_ns: int | None = None, **facts: Any) -> None:
        """Begin a gap (a second call while one is open keeps the first's start and reason)."""
        if self.open_gap is None:
            self.open_gap = {"kind": "source_gap", "start_ns": start_ns or time.time_ns(), "reason": reason, **facts}

    def close(self, end_ns: int | None = None, **facts: Any) -> dict[str, Any] | None:
        """End the open gap, if any, and report it; returns the event."""
        gap = self.open_gap
        if gap is None:
            return None
        end_ns = end_ns or time.time_ns()
        event = {**gap, **facts, "at_ns": end_ns, "end_ns": end_ns,
                 "duration_s": round((end_ns - gap["start_ns"]) / 1e9, 3)}
        self.closed.append(event)
        self.open_gap = None
        if self.on_close is not None:
            self.on_close(event)
        return event

    def health(self) -> dict[str, Any]:
        open_s = (time.time_ns() - self.open_gap["start_ns"]) / 1e9 if self.open_gap is not None else 0.0
        return {"gaps": len(self.closed) + (self.open_gap is not None),
                "gap_s": round(sum(g["duration_s"] for g in self.closed) + open_s, 3),
                "waiting_for_frames": self.open_gap is not None}
