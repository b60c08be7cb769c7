"""A tool's statistic over a session: the max, mean or min of a region frame by frame, which is
how a user finds when a bearing started heating."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from recorder.thermography.measure import Tool, bounds, measure, shifted

__all__ = ["STATS", "region_series", "series_point"]

STATS = ("max", "mean", "min")


def series_point(index: int, t: int, crop: np.ndarray, tool: Tool, stat: str,
                 to_celsius: Callable[[int, np.ndarray], np.ndarray]) -> dict[str, Any]:
    """One point from the tool's rectangle alone (``crop``, with ``tool`` in its coordinates):
    a model maps each count on its own, so only those pixels are converted to °C."""
    m = measure(np.asarray(to_celsius(index, np.ascontiguousarray(crop)), dtype=np.float32), tool)
    return {"frame": index, "timestamp_ns": int(t), "celsius": getattr(m, f"{stat}_c")}


def region_series(frames: Iterable[tuple[int, int, np.ndarray]], tool: Tool, stat: str,
                  to_celsius: Callable[[int, np.ndarray], np.ndarray]) -> list[dict[str, Any]]:
    """``frames``: (index, log time ns, counts); ``to_celsius(index, counts)`` (a frame's model
    may be re-parameterised). One point per frame: its time and the statistic."""
    if stat not in STATS:
        raise ValueError(f"stat must be one of {', '.join(STATS)}, got {stat!r}")
    out = []
    for index, t, counts in frames:
        x0, y0, x1, y1 = bounds(tool, counts.shape)
        out.append(series_point(index, t, counts[y0:y1, x0:x1], shifted(tool, x0, y0), stat, to_celsius))
    return out
