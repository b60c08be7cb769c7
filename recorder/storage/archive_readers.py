"""Where a session's frames come from once its MCAP segments are gone.

The recorder cannot import the archive (imports run recorder -> archive -> api), yet exports and
reports must read a session whose source was deleted after archiving. The ``thermcap`` facade,
which sees every room, registers the archive's reader here when it is imported; this module
stays import-light because that happens on every ``import thermcap``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

__all__ = ["ARCHIVE_READERS", "ArchiveReader", "register_archive_reader"]

# reader(session_dir) -> the session's frames (SessionFrame), or None when it holds no copy
ArchiveReader = Callable[[Path], Iterable[Any] | None]
ARCHIVE_READERS: list[ArchiveReader] = []


def register_archive_reader(reader: ArchiveReader) -> None:
    if reader not in ARCHIVE_READERS:
        ARCHIVE_READERS.append(reader)
