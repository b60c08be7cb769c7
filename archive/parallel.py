"""Work on a thread pool in input order, memory bounded: the encoders and decoders release the
GIL, so the archive's formats and codecs use every core through this one helper."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

__all__ = ["ordered_map"]

T = TypeVar("T")
R = TypeVar("R")


def ordered_map(fn: Callable[[T], R], items: Iterable[T], workers: int, window: int | None = None) -> Iterator[R]:
    """``map`` on a thread pool, results in input order, at most ``window`` items in flight
    (bounded memory however long the input). Encoders release the GIL, so this uses every core."""
    if workers <= 1:
        yield from map(fn, items)
        return
    window = window or workers * 4
    with ThreadPoolExecutor(workers, thread_name_prefix="archive-encode") as pool:
        pending: deque = deque()
        for item in items:
            pending.append(pool.submit(fn, item))
            if len(pending) >= window:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
