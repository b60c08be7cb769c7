"""A tool's statistic over a session: the max, mean or min of a region frame by frame, which is
how a user finds when a bearing started heating."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from recorder.thermography.measure import Box, Line, Spot, Tool, ToolError, bounds, measure, shifted

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
        h, w = counts.shape
        if isinstance(tool, (Spot, Box)) and not (bounds(tool, (h, w)) == _unclipped(tool)):
            raise ToolError(f"{type(tool).__name__.lower()} is outside the {w}x{h} frame")
        x0, y0, x1, y1 = bounds(tool, (h, w))
        crop = np.ascontiguousarray(counts[y0:y1, x0:x1])
        part = tool if isinstance(tool, Line) else shifted(tool, x0, y0)
        if isinstance(tool, Line):  # a line's samples are placed on the whole frame: keep it whole
            crop, part = counts, tool
        m = measure(np.asarray(to_celsius(index, crop), dtype=np.float32), part)
        out.append({"frame": index, "timestamp_ns": int(t), "celsius": getattr(m, f"{stat}_c")})
    return out


def _unclipped(tool: Tool) -> tuple[int, int, int, int]:
    if isinstance(tool, Spot):
        return tool.x, tool.y, tool.x + 1, tool.y + 1
    assert isinstance(tool, Box)
    return tool.x0, tool.y0, tool.x1 + 1, tool.y1 + 1
