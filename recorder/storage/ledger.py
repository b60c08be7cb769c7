"""What a session says it wrote, against what is on disk: its ledger.

The recorder lists every segment it closed in ``session.json`` (name and frames). A segment can
leave the folder in four accounted ways: the ring evicted it, sync freed it once the cloud
confirmed it (both leave a line in ``ROOT/eviction.log``), ``archive --delete-source`` deleted
it after a verified archive (the manifest says so), or ``recover`` set it aside as unreadable
(``NNNN.mcap.unreadable`` stays). A listed segment gone in none of these ways is lost, and must
be said, never counted around: ``info`` says it, and nothing deletes the rest of the session on
the evidence of an archive that never held it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.layout import DataRoot, SessionLayout
from thermcap.recorder.storage.manifest_file import read_manifest_file

__all__ = ["LostSegment", "deletions", "lost_segments", "record_freed"]


@dataclass(frozen=True)
class LostSegment:
    name: str
    frames: int


def lost_segments(session_dir: str | Path, meta: dict[str, Any] | None = None) -> list[LostSegment]:
    """The segments ``session.json`` lists with frames that are gone from the folder with no
    record of why."""
    d = Path(session_dir)
    if meta is None:
        try:
            meta = json.loads(SessionLayout.of(d).session_json.read_text())
        except (OSError, ValueError):
            return []
    listed = [s for s in meta.get("segments") or [] if isinstance(s, dict) and s.get("name") and s.get("frames")]
    if not listed:
        return []
    if _source_deleted_by_archive(d):
        return []
    accounted = _deleted_on_record(d)
    lost = []
    for seg in listed:
        name = str(seg["name"])
        if any((d / f"{name}{suffix}").exists() for suffix in ("", ".active", ".unreadable")):
            continue
        if name in accounted:
            continue
        lost.append(LostSegment(name, int(seg["frames"])))
    return lost


def _source_deleted_by_archive(d: Path) -> bool:
    try:
        manifest = read_manifest_file(d) or {}
    except McapFileError:
        return False
    return bool((manifest.get("source") or {}).get("deleted"))


def _deleted_on_record(d: Path) -> set[str]:
    return {str(entry["segment"]) for entry in deletions(d)}


def deletions(session_dir: str | Path) -> list[dict[str, Any]]:
    """This session's lines of ``ROOT/eviction.log``: a segment each, deleted by the ring or freed
    by sync (``freed_by``), with why. Written as each goes, so it survives a crash that
    ``session.json``'s end-of-run counts do not."""
    d = Path(session_dir).resolve()
    out: list[dict[str, Any]] = []
    try:
        with open(DataRoot.of(d.parent.parent).eviction_log) as f:
            for line in f:
                try:
                    entry = json.loads(line)
                except ValueError:
                    continue
                if isinstance(entry, dict) and entry.get("session") == d.name and entry.get("segment"):
                    out.append(entry)
    except OSError:
        pass
    return out


def record_freed(root: str | Path, session: str, segment: str, size: int, by: str, why: str) -> None:
    """A segment deleted by something other than the ring (sync, once the cloud confirmed it), in
    the same ``eviction.log`` the ring writes: the one record of segments that left a session."""
    import time

    from thermcap.recorder.icd.names import iso_utc

    entry = {"at": iso_utc(time.time_ns()), "session": session, "segment": segment, "bytes": size,
             "freed_by": by, "reason": why}
    with open(DataRoot.of(root).eviction_log, "a") as f:
        f.write(json.dumps(entry) + "\n")
