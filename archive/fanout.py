"""One decode of the source, many consumers: the frame stream teed to every format's writer.

Each archive format used to read (decompress and decode) the whole MCAP source again. ``fan_out``
reads it once and hands every frame to each consumer through its own bounded queue, so memory
stays at ``depth`` frames per consumer however long the session. A consumer that stops early
(its writer failed) is detached: the others go on, and the producer never blocks on it.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import Generic, TypeVar

__all__ = ["fan_out"]

T = TypeVar("T")
R = TypeVar("R")
_END = object()


class _Branch(Generic[T]):
    def __init__(self, depth: int) -> None:
        self.q: queue.Queue = queue.Queue(maxsize=depth)
        self.detached = threading.Event()

    def __iter__(self) -> Iterator[T]:
        while True:
            item = self.q.get()
            if item is _END:
                return
            if isinstance(item, _Failure):
                raise item.exc
            yield item


class _Failure:
    def __init__(self, exc: BaseException) -> None:
        self.exc = exc


def fan_out(source: Iterable[T], consumers: list[Callable[[Iterable[T]], R]], *,
            depth: int = 8, copy: Callable[[T], T] | None = None) -> list[R | BaseException]:
    """Run each consumer on its own thread over the same stream, read once from ``source``.

    ``copy`` gives each consumer its own item (a shallow copy is enough when the payload is
    read-only), so a consumer that rebinds a field cannot change what the others see. Returns
    each consumer's result, or the exception it raised (in consumer order). An error in the
    source is raised in every consumer that is still reading."""
    branches: list[_Branch[T]] = [_Branch(depth) for _ in consumers]
    results: list[R | BaseException] = [RuntimeError("consumer did not finish")] * len(consumers)

    def run(i: int) -> None:
        try:
            results[i] = consumers[i](branches[i])
        except BaseException as exc:  # reported to the caller, never lost in the thread
            results[i] = exc
        finally:
            branches[i].detached.set()
            while True:  # let the producer finish: drain what it still sends us
                try:
                    if branches[i].q.get_nowait() is _END:
                        break
                except queue.Empty:
                    break

    threads = [threading.Thread(target=run, args=(i,), name=f"archive-fanout-{i}", daemon=True)
               for i in range(len(consumers))]
    for t in threads:
        t.start()

    def put(branch: _Branch[T], item: object) -> None:
        while not branch.detached.is_set():
            try:
                branch.q.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    try:
        for item in source:
            if all(b.detached.is_set() for b in branches):
                break
            for b in branches:
                put(b, copy(item) if copy is not None else item)
        end: object = _END
    except BaseException as exc:
        end = _Failure(exc)
    for b in branches:
        put(b, end)
    for t in threads:
        t.join()
    return results
