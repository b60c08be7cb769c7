"""A tool's statistic over a session: the max, mean or min of a region frame by frame, which is
how a user finds when a bearing started heating."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from recorder.thermography.measure import Tool, measure

__all__ = ["STATS", "region_series"]

STATS = ("max", "mean", "min")


def region_series(frames: Iterable[tuple[int, int, np.ndarray]], tool: Tool, stat: str,
                  to_celsius: Callable[[int, np.ndarray], np.ndarray]) -> list[dict[str, Any]]:
    """``frames``: (index, log time ns, counts); ``to_celsius(index, counts)`` (a frame's model
    may be re-parameterised). One point per frame: its time and the statistic."""
    if stat not in STATS:
        raise ValueError(f"stat must be one of {', '.join(STATS)}, got {stat!r}")
    out = []
    for index, t, counts in frames:
        m = measure(np.asarray(to_celsius(index, counts), dtype=np.float32), tool)
        out.append({"frame": index, "timestamp_ns": int(t), "celsius": getattr(m, f"{stat}_c")})
    return out
