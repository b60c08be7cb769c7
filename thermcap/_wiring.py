"""The few places where a lower room must reach a higher one at run time, connected here.

Imports run recorder -> archive -> api. Two needs run the other way: the recorder's readers
(exports, reports) must read a session from its archive once the MCAP source is deleted, and
``thermcap archive`` must let the API index a session it just verified. Each lower room offers
a small registry; this module, above all three, fills it. The registries are import-light and
the callables import their room on first call, so ``import thermcap`` stays fast.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

from thermcap.archive.hooks import register_on_archived
from thermcap.recorder.storage.archive_readers import register_archive_reader

__all__ = ["connect"]


def _archived_frames(session_dir: Path) -> Iterable[Any] | None:
    from thermcap.archive.reading import archived_frames

    return archived_frames(session_dir)


def _index_archived(session_dir: Path, root: Path) -> None:
    from thermcap.api.cli import on_archived

    on_archived(session_dir, root)


def connect() -> None:
    register_archive_reader(_archived_frames)
    register_on_archived("index", _index_archived)
