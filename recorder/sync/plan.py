"""What a vehicle ships, in the order it ships it.

Events, session metadata and protected windows go first (small, and what an operator at the
depot looks at before anything else), then closed segments oldest first. A segment still being
written (``.active``) is not data yet and never goes. Keys are paths relative to the data root,
the same as the archive's blob keys, so a synced session sits in the bucket where an archived
one would.
"""

from __future__ import annotations

import stat
from dataclasses import dataclass
from pathlib import Path

from thermcap.recorder.storage.layout import (
    BAG_METADATA,
    EVENTS_JSON,
    FOXGLOVE_LAYOUT,
    PROTECTED_JSON,
    SESSION_JSON,
    DataRoot,
    SessionLayout,
)

__all__ = ["SyncItem", "plan_root"]

_METADATA = (EVENTS_JSON, SESSION_JSON, PROTECTED_JSON, BAG_METADATA, FOXGLOVE_LAYOUT)


@dataclass(frozen=True)
class SyncItem:
    key: str  # relative to the data root, '/'-separated
    path: Path
    size: int
    mtime_ns: int
    session: str
    segment: bool  # an MCAP segment (immutable once closed) rather than metadata (rewritten)


def plan_root(root: Path, sessions: list[str] | None = None) -> list[SyncItem]:
    dirs = [d for d in DataRoot.of(root).session_dirs() if sessions is None or d.name in sessions]
    meta: list[SyncItem] = []
    segs: list[tuple[int, str, SyncItem]] = []
    for d in dirs:
        for name in _METADATA:
            if (meta_item := _item(root, d / name, d.name, segment=False)) is not None:
                meta.append(meta_item)
        for seg in SessionLayout.of(d).segments():
            if (item := _item(root, seg, d.name, segment=True)) is not None:
                segs.append((item.mtime_ns, item.key, item))
    meta.sort(key=lambda i: (_METADATA.index(i.path.name), i.key))
    return meta + [i for _, _, i in sorted(segs)]


def _item(root: Path, path: Path, session: str, *, segment: bool) -> SyncItem | None:
    """The file as it is now, or None if it is gone: a ring evicts segments (and a whole
    session's files) at any moment, so a listing is never trusted to still hold."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    if not stat.S_ISREG(st.st_mode):
        return None
    return SyncItem(DataRoot.of(root).key_of(path), path, st.st_size, st.st_mtime_ns, session, segment)
