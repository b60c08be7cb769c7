"""Files replaced whole: written beside themselves under a temporary name, then renamed over.

A reader sees the old file or the new one, never half of one; a write that fails (a full disk)
leaves the old file as it was and no temporary file beside it. Every file thermcap rewrites in
place (session.json, the manifest, metadata.yaml, the export's summary, the Foxglove layout)
goes through here.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO, Any

__all__ = ["fsync_dir", "fsync_tree", "replacing", "write_json_atomic", "write_text_atomic"]


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path: Path) -> None:
    """Make a rename in ``path`` survive a power cut."""
    _fsync(path)


def fsync_tree(path: Path) -> None:
    """Every file under ``path`` to disk, then ``path`` itself: a folder written whole before it
    is renamed into place."""
    for p in path.rglob("*"):
        if p.is_file():
            _fsync(p)
    _fsync(path)


@contextmanager
def replacing(path: Path, *, fsync: bool = True, unique: bool = False, newline: str | None = None) -> Iterator[IO[str]]:
    """A text file to write ``path``'s new contents into; on leaving the block it replaces
    ``path`` (flushed, and fsynced with its folder unless ``fsync=False``: only where the disk is
    known not to answer fsync, or for derived files a later write makes again). An exception in
    the block or in the write removes the temporary file and is raised. ``unique``: the
    temporary name carries the process id, for a file two processes may rewrite at once."""
    path = Path(path)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp" if unique else f"{path.name}.tmp")
    try:
        with open(tmp, "w", newline=newline) as f:
            yield f
            f.flush()
            if fsync:
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:  # a full disk: the old file stays, and no half-written .tmp beside it
        with suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise
    if fsync:
        fsync_dir(path.parent)


def write_text_atomic(path: Path, text: str, *, fsync: bool = True, unique: bool = False) -> None:
    with replacing(path, fsync=fsync, unique=unique) as f:
        f.write(text)


def write_json_atomic(path: Path, data: Any, *, fsync: bool = True, indent: int = 2) -> None:
    with replacing(path, fsync=fsync) as f:
        json.dump(data, f, indent=indent, sort_keys=False)
        f.write("\n")
