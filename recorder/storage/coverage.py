"""When a session has frames, and where it has none: one definition for the index, the API and
the workbench.

A gap is a step between two frames of more than ``GAP_PERIODS`` frame periods (the median step):
at least two frames' worth of time with nothing. Jitter does not reach it: a frame stamped when
it arrives may come up to a period late and the next on time, a step of under two periods, and
at 1.5 periods (the threshold before) a 31 s session from a pipe showed 705 "gaps" with nothing
dropped. A gap's length is the time without frames beyond the one period a step always takes.
A single missing frame is not a gap here; the counts say it (dropped, frames missed by the
camera's ids, the source's gaps).
"""

from __future__ import annotations

import statistics
from itertools import pairwise

__all__ = ["GAP_PERIODS", "coverage", "gaps"]

GAP_PERIODS = 2.5


def coverage(times: list[int]) -> list[list[int]]:
    """[start_ns, end_ns] spans with frames, in order; ``times`` sorted."""
    if not times:
        return []
    if len(times) < 3:
        return [[times[0], times[-1]]]
    limit = GAP_PERIODS * statistics.median(b - a for a, b in pairwise(times))
    spans, start = [], times[0]
    for a, b in pairwise(times):
        if b - a > limit:
            spans.append([start, a])
            start = b
    spans.append([start, times[-1]])
    return spans


def gaps(spans: list[list[int]], period_ns: float) -> list[tuple[int, int, float]]:
    """(last frame before, first frame after, seconds without frames) between ``coverage`` spans."""
    return [(a[1], b[0], max(0.0, (b[0] - a[1] - period_ns) / 1e9)) for a, b in pairwise(spans)]
