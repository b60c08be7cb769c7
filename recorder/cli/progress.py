"""Progress for long CLI work: a rich bar on a terminal, a line every few seconds in a log (a
systemd journal, a CI log, a pipe), nothing with ``--quiet`` or ``--json``. Either way the
caller uses the same three calls as rich's ``Progress``: ``add_task``, ``update``/``advance``,
``remove_task``."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import click

__all__ = ["progress", "verbosity"]


def verbosity() -> int:
    """-1 with ``thermcap --quiet``, 1+ with ``--verbose``, else 0."""
    ctx = click.get_current_context(silent=True)
    obj = ctx.find_root().obj if ctx is not None else None
    return int(obj.get("verbosity", 0)) if isinstance(obj, dict) else 0


class _LogLines:
    """rich's Progress calls, as plain lines on stderr at most every ``every_s`` per task."""

    def __init__(self, every_s: float) -> None:
        self.every_s = every_s
        self._tasks: dict[int, dict[str, Any]] = {}
        self._next = 0

    def add_task(self, description: str, total: float | None = None, **_: Any) -> int:
        self._next += 1
        self._tasks[self._next] = {"description": description, "completed": 0, "total": total, "shown": 0.0}
        return self._next

    def update(self, task: int, *, description: str | None = None, completed: float | None = None,
               total: float | None = None, advance: float | None = None, **_: Any) -> None:
        t = self._tasks[task]
        if description is not None:
            t["description"] = description
        if total is not None:
            t["total"] = total
        if completed is not None:
            t["completed"] = completed
        if advance:
            t["completed"] += advance
        now = time.monotonic()
        if now - t["shown"] >= self.every_s:
            t["shown"] = now
            done = f" {int(t['completed'])}/{int(t['total'])}" if t["total"] else ""
            click.echo(f"... {t['description']}{done}", err=True)

    def advance(self, task: int, advance: float = 1) -> None:
        self.update(task, advance=advance)

    def remove_task(self, task: int) -> None:
        self._tasks.pop(task, None)


@contextmanager
def progress(*columns: Any, as_json: bool = False, every_s: float = 5.0) -> Iterator[Any]:
    if as_json or verbosity() < 0:
        from rich.progress import Progress

        with Progress(disable=True) as quiet:
            yield quiet
        return
    if sys.stderr.isatty():
        from rich.progress import Progress

        with Progress(*columns, transient=True) as bar:
            yield bar
        return
    yield _LogLines(every_s)
