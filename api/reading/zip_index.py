"""Where each frame sits in each verified stored-ZIP copy of a served session: the central
directories (``archive.reading.zip_directory``), per session as the index lists its copies."""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

from thermcap.archive.formats.base import locate
from thermcap.archive.manifest import record_digest
from thermcap.archive.reading.zip_directory import ZIPPED_FORMATS, ReadRange, ZipIndexCache
from thermcap.recorder.storage.layout import archive_key

__all__ = ["ZIPPED_FORMATS", "ArchiveLocations"]


def _range_reader(store: Any, key: str) -> ReadRange:
    def read(start: int, end: int) -> bytes:
        return bytes(store.get_range(key, start, end))
    return read


@dataclass
class _SessionZips:
    indexed_at: int
    checked: float
    files: dict[str, list[dict[str, Any]]]  # format -> the manifest's file list ({path, frames}), session order
    sizes: dict[tuple[str, str], tuple[int, str]]  # (format, file) -> (bytes, digest), as the manifest says


class ArchiveLocations:
    """A frame's place in each verified stored-ZIP copy of its session, from the archives' own
    central directories: what the index no longer keeps a row per frame for. A session's list of
    copies is looked at again when its index row changes (checked at most every ``check_s``), so
    a copy that scrub marks damaged stops being offered."""

    def __init__(self, engine: Any, store: Any, *, check_s: float = 2.0, keep_sessions: int = 64) -> None:
        self.engine, self.store, self.check_s = engine, store, check_s
        self.entries = ZipIndexCache()
        self._sessions: OrderedDict[str, _SessionZips] = OrderedDict()
        self._keep = keep_sessions
        self._lock = threading.Lock()

    def _session(self, session_id: str) -> _SessionZips | None:
        import json
        import time

        from sqlalchemy import select

        from thermcap.api import db

        now = time.monotonic()
        with self._lock:
            s = self._sessions.get(session_id)
            if s is not None and now - s.checked < self.check_s:
                return s
        with self.engine.connect() as conn:
            indexed_at = conn.execute(select(db.sessions.c.indexed_at).where(db.sessions.c.id == session_id)).scalar()
            if indexed_at is None:
                return None
            if s is not None and s.indexed_at == indexed_at:
                s.checked = now
                return s
            rows = conn.execute(select(db.archives.c.format, db.archives.c.files).where(
                db.archives.c.session_id == session_id, db.archives.c.verified.is_(True),
                db.archives.c.format.in_(ZIPPED_FORMATS))).all()
        files = {fmt: json.loads(text) for fmt, text in rows}
        sizes = {(fmt, str(r["path"])): (int(r.get("bytes") or 0), str((record_digest(r) or ("", ""))[1]))
                 for fmt, recs in files.items() for r in recs}
        s = _SessionZips(int(indexed_at), now, files, sizes)
        with self._lock:
            self._sessions[session_id] = s
            while len(self._sessions) > self._keep:
                self._sessions.popitem(last=False)
        return s

    def formats(self, session_id: str) -> list[str]:
        s = self._session(session_id)
        return list(s.files) if s is not None else []

    def blob(self, session_id: str, fmt: str, idx: int) -> dict[str, Any] | None:
        """{format, file, offset, length, crc32, sidecar_offset, sidecar_length}, or None where
        this format has no readable copy of the frame (a missing file is not an error here: the
        reader tries the next copy)."""
        s = self._session(session_id)
        if s is None or fmt not in s.files:
            return None
        try:
            rel, k = locate(s.files[fmt], idx)
        except IndexError:
            return None
        key = archive_key(session_id, fmt, rel)
        try:
            size, sha = s.sizes.get((fmt, rel), (0, ""))
            if not size:
                head = self.store.head(key)
                if head is None:
                    return None
                size = int(head["size"])
            entries = self.entries.get(key, size, _range_reader(self.store, key), sha)
        except (FileNotFoundError, ValueError, OSError):
            return None
        return {"format": fmt, "file": rel, **entries.blob(k)} if k < entries.frames else None

    def blobs(self, session_id: str, idx: int) -> dict[str, dict[str, Any]]:
        out = {}
        for fmt in self.formats(session_id):
            b = self.blob(session_id, fmt, idx)
            if b is not None:
                out[fmt] = b
        return out
