"""A tool's statistic over a session: the max, mean or min of a region frame by frame, which is
how a user finds when a bearing started heating."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from thermcap.recorder.thermography.measure import Tool, measure

__all__ = ["STATS", "series_point"]

STATS = ("max", "mean", "min")


def series_point(index: int, t: int, crop: np.ndarray, tool: Tool, stat: str,
                 to_celsius: Callable[[int, np.ndarray], np.ndarray]) -> dict[str, Any]:
    """One point from the tool's rectangle alone (``crop``, with ``tool`` in its coordinates):
    a model maps each count on its own, so only those pixels are converted to °C."""
    m = measure(np.asarray(to_celsius(index, np.ascontiguousarray(crop)), dtype=np.float32), tool)
    return {"frame": index, "timestamp_ns": int(t), "celsius": getattr(m, f"{stat}_c")}
