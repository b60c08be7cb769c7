"""The data root's address book: every file a root and a session hold, named once.

``ROOT/sessions/<id>/`` holds the recording and everything derived from it; the root holds the
sessions, the index and its frame files, the eviction log and sync's journal. A bucket holds the same
files under the same relative keys (``sessions/<id>/archive/...``). The recorder, the archiver
and the API find them through ``DataRoot``, ``SessionLayout`` and the key helpers here, never by
spelling names, so the layout is changed (and documented, in docs/architecture.md) in one place;
``tests/unit/meta/test_one_address_book.py`` fails for a module that spells them itself.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "ACTIVE_SUFFIX",
    "ANALYSIS_JSONL",
    "ARCHIVE_DIR",
    "BAG_METADATA",
    "EVENTS_JSON",
    "EVICTION_LOG",
    "EXTRAS_MCAP",
    "FOXGLOVE_LAYOUT",
    "FRAMES_INDEX_DIR",
    "INDEX_DB",
    "LOCK_FILE",
    "MANIFEST_COPY_JSON",
    "MANIFEST_JSON",
    "PARTIAL_SUFFIX",
    "PARTS_DIR",
    "PROTECTED_JSON",
    "RADIOMETRY_JSON",
    "REFS_SUFFIX",
    "RESERVE_FILE",
    "SESSIONS_DIR",
    "SESSIONS_PREFIX",
    "SESSION_JSON",
    "SESSION_NAME_RE",
    "SUMMARY_NAME",
    "SYNC_DIR",
    "DataRoot",
    "SessionLayout",
    "archive_key",
    "check_session_name",
    "frames_index_key",
    "session_key",
    "session_of_key",
]

SESSIONS_DIR = "sessions"  # ROOT/sessions/<id>/: one folder per session
SESSIONS_PREFIX = f"{SESSIONS_DIR}/"  # the same, as the start of an object key in a bucket
INDEX_DB = "index.sqlite"  # ROOT/index.sqlite: the API's embedded index (a rebuildable cache)
SYNC_DIR = ".sync"  # ROOT/.sync/: sync's journal (recorder.storage.sync_journal)
FRAMES_INDEX_DIR = "index/frames"  # ROOT/index/frames/<id>/<state>.parquet: the indexer's frame columns
ACTIVE_SUFFIX = ".active"  # a segment being written, or left by a crash for `recover`
PARTIAL_SUFFIX = ".partial"  # an archive format (or extras) not verified yet
SESSION_JSON = "session.json"
EVENTS_JSON = "events.json"
ANALYSIS_JSONL = "analysis.jsonl"
ARCHIVE_DIR = "archive"
MANIFEST_JSON = "manifest.json"
MANIFEST_COPY_JSON = "manifest.copy.json"  # the manifest's second copy (recorder.storage.manifest_file)
EXTRAS_MCAP = "extras.mcap"
LOCK_FILE = ".lock"
RESERVE_FILE = ".reserve"
PROTECTED_JSON = "protected.json"  # event windows eviction, gc and the archiver keep
EVICTION_LOG = "eviction.log"  # ROOT/eviction.log: one JSON line per deleted segment, with why
RADIOMETRY_JSON = "radiometry.json"  # the model's versions after capture (recorder.radiometry.params)
BAG_METADATA = "metadata.yaml"  # rosbag2's description of the segments (recorder.storage.rosbag2)
FOXGLOVE_LAYOUT = "foxglove_layout.json"  # a Foxglove layout for the session (recorder.storage.foxglove_layout)
SUMMARY_NAME = "summary.npz"  # archive/summary.npz: per frame and band, CRC-32s bound to the manifest
PARTS_DIR = ".parts"  # archive/.parts/: per-segment parts of an archive being built (archive.segmented)
REFS_SUFFIX = ".refs.json"  # beside an HDF5 archive in a bucket: its kerchunk references

#: A session id is one folder name under ROOT/sessions: no separator, no "..", nothing hidden.
SESSION_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")


def check_session_name(name: str) -> str:
    """A session id from a flag or a request, refused unless it names one folder inside the root."""
    if not SESSION_NAME_RE.match(name) or ".." in name:
        raise ValueError(f"session id {name!r}: use 1-128 letters, digits, '_', '-' or '.', starting with a letter "
                         f"or digit, without '..' (it names one folder under ROOT/sessions)")
    return name


def session_key(session_id: str, *parts: str) -> str:
    """The object key of a session's file in a bucket: its path relative to the data root."""
    return "/".join((SESSIONS_DIR, session_id, *parts))


def archive_key(session_id: str, *parts: str) -> str:
    """The object key of a file of a session's archive (``archive_key(sid, "png16", "0000.zip")``)."""
    return session_key(session_id, ARCHIVE_DIR, *parts)


def frames_index_key(session_id: str, state: str) -> str:
    """The key (in the root or the bucket) of the indexer's frame columns for one indexed state."""
    return f"{FRAMES_INDEX_DIR}/{session_id}/{state}.parquet"


def session_of_key(key: str) -> str | None:
    """The session a key relative to the data root belongs to, or None for a key outside one."""
    parts = key.split("/")
    return parts[1] if len(parts) > 2 and parts[0] == SESSIONS_DIR and parts[1] else None


@dataclass(frozen=True)
class DataRoot:
    """Paths of one data root."""

    path: Path

    @classmethod
    def of(cls, root: str | os.PathLike) -> DataRoot:
        return cls(Path(root))

    @property
    def sessions(self) -> Path:
        return self.path / SESSIONS_DIR

    def session_dir(self, session_id: str) -> Path:
        """The folder of a session known by id (from the index, a manifest): not checked, so use
        ``session`` for a name that came from a flag or a request."""
        return self.sessions / session_id

    def session(self, name: str) -> SessionLayout:
        """The layout of the session a flag or a request named, refused unless it is one folder
        inside the root."""
        return SessionLayout(self.sessions / check_session_name(name))

    def session_dirs(self) -> list[Path]:
        """Every session folder, by name (including ones no reader takes, like ``.partial``)."""
        try:
            return sorted(d for d in self.sessions.iterdir() if d.is_dir())
        except FileNotFoundError:
            return []

    @property
    def index_db(self) -> Path:
        return self.path / INDEX_DB

    def frames_index(self, session_id: str) -> Path:
        return self.path / FRAMES_INDEX_DIR / session_id

    @property
    def eviction_log(self) -> Path:
        return self.path / EVICTION_LOG

    @property
    def sync_dir(self) -> Path:
        return self.path / SYNC_DIR

    def key_of(self, path: Path) -> str:
        """The object key of a file under the root (the same relative path in every bucket)."""
        return path.relative_to(self.path).as_posix()


@dataclass(frozen=True)
class SessionLayout:
    """Paths inside one session folder."""

    dir: Path

    @classmethod
    def of(cls, session_dir: str | os.PathLike) -> SessionLayout:
        return cls(Path(session_dir))

    @property
    def session_json(self) -> Path:
        return self.dir / SESSION_JSON

    @property
    def events_json(self) -> Path:
        return self.dir / EVENTS_JSON

    @property
    def analysis_jsonl(self) -> Path:
        return self.dir / ANALYSIS_JSONL

    @property
    def protected_json(self) -> Path:
        return self.dir / PROTECTED_JSON

    @property
    def radiometry_json(self) -> Path:
        return self.dir / RADIOMETRY_JSON

    @property
    def bag_metadata(self) -> Path:
        return self.dir / BAG_METADATA

    @property
    def foxglove_layout(self) -> Path:
        return self.dir / FOXGLOVE_LAYOUT

    @property
    def frame_summary(self) -> Path:
        return self.archive / SUMMARY_NAME

    @property
    def parts(self) -> Path:
        return self.archive / PARTS_DIR

    @property
    def reserve(self) -> Path:
        """Disk kept for the end of a recording (session.json, events.json, the layout): taken
        at the start, freed just before they are written, so a full disk cannot lose them."""
        return self.dir / RESERVE_FILE

    @property
    def lock(self) -> Path:
        return self.dir / LOCK_FILE

    @property
    def archive(self) -> Path:
        return self.dir / ARCHIVE_DIR

    @property
    def manifest(self) -> Path:
        return self.archive / MANIFEST_JSON

    @property
    def manifest_copy(self) -> Path:
        return self.archive / MANIFEST_COPY_JSON

    @property
    def extras(self) -> Path:
        return self.archive / EXTRAS_MCAP

    def format_dir(self, format_id: str) -> Path:
        return self.archive / format_id

    def segments(self) -> list[Path]:
        """Finished segments, in order (``.active`` ones are not data yet)."""
        return sorted(self.dir.glob("[0-9][0-9][0-9][0-9].mcap"))

    def active_segments(self) -> list[Path]:
        return sorted(self.dir.glob(f"[0-9][0-9][0-9][0-9].mcap{ACTIVE_SUFFIX}"))
