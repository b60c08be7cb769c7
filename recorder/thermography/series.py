"""A tool's statistic over a session: the max, mean or min of a region frame by frame, which is
how a user finds when a bearing started heating."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from recorder.thermography.measure import Tool, bounds, measure, shifted

__all__ = ["STATS", "region_series"]

STATS = ("max", "mean", "min")


def region_series(frames: Iterable[tuple[int, int, np.ndarray]], tool: Tool, stat: str,
                  to_celsius: Callable[[int, np.ndarray], np.ndarray]) -> list[dict[str, Any]]:
    """``frames``: (index, log time ns, counts); ``to_celsius(index, counts)`` (a frame's model
    may be re-parameterised). One point per frame: its time and the statistic. Only the tool's
    rectangle is converted to °C (a model maps each count on its own), so a small box over a
    long session costs the decode, not the radiometry of every pixel."""
    if stat not in STATS:
        raise ValueError(f"stat must be one of {', '.join(STATS)}, got {stat!r}")
    out = []
    for index, t, counts in frames:
        x0, y0, x1, y1 = bounds(tool, counts.shape)
        crop = np.ascontiguousarray(counts[y0:y1, x0:x1])
        m = measure(np.asarray(to_celsius(index, crop), dtype=np.float32), shifted(tool, x0, y0))
        out.append({"frame": index, "timestamp_ns": int(t), "celsius": getattr(m, f"{stat}_c")})
    return out
