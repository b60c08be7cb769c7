"""A session folder is also a rosbag2 bag: ``metadata.yaml`` as ``ros2 bag info`` and ``ros2 bag
reindex`` write it (version 5, the oldest with per-file entries, so Humble and later read it).

It is rewritten from the finished segments' MCAP summaries whenever the set of segments
changes: a segment closes, the ring evicts one, ``recover`` finishes one, the archiver or ``gc``
deletes them (then it goes, since there is no bag left). Summaries are cached by file size and
mtime, so a rewrite after a rotation reads only the new segment's summary.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from thermcap.recorder.storage.atomic import write_text_atomic
from thermcap.recorder.storage.layout import BAG_METADATA, SessionLayout

__all__ = ["BAG_METADATA", "bag_metadata_text", "write_bag_metadata"]

VERSION = 5

_cache: dict[tuple[str, int, int], dict[str, Any]] = {}
_lock = threading.Lock()  # the writer (a segment closed) and the evictor (one deleted) both rewrite


def _summary(seg: Path) -> dict[str, Any] | None:
    try:
        st = seg.stat()
    except FileNotFoundError:  # evicted or deleted while we listed: not part of the bag
        return None
    key = (str(seg), st.st_size, st.st_mtime_ns)
    if key not in _cache:
        try:
            with open(seg, "rb") as f:
                summary = make_reader(f).get_summary()
        except Exception:  # an unreadable segment is not listed: a bag must only name readable files
            return None
        if summary is None or summary.statistics is None:
            return None
        stats = summary.statistics
        topics: dict[str, dict[str, Any]] = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            t = topics.setdefault(ch.topic, {"type": schema.name if schema else "", "format": ch.message_encoding,
                                             "count": 0})
            t["count"] += stats.channel_message_counts.get(cid, 0)
        if len(_cache) > 4096:
            _cache.clear()
        _cache[key] = {"start": stats.message_start_time, "end": stats.message_end_time,
                       "count": stats.message_count, "topics": topics}
    return _cache[key]


def _q(s: str) -> str:
    return "'" + s.replace("'", "''") + "'"


def bag_metadata_text(segments: list[Path]) -> str | None:
    """The metadata.yaml for these segments, or None when none is readable."""
    files: list[tuple[str, dict[str, Any]]] = []
    topics: dict[str, dict[str, Any]] = {}
    for seg in segments:
        s = _summary(seg)
        if s is None:
            continue
        files.append((seg.name, s))
        for name, t in s["topics"].items():
            agg = topics.setdefault(name, {"type": t["type"], "format": t["format"], "count": 0})
            agg["count"] += t["count"]
    if not files:
        return None
    with_msgs = [s for _, s in files if s["count"]]
    start = min((s["start"] for s in with_msgs), default=0)
    end = max((s["end"] for s in with_msgs), default=0)
    lines = ["rosbag2_bagfile_information:", f"  version: {VERSION}", "  storage_identifier: mcap",
             "  duration:", f"    nanoseconds: {max(0, end - start)}", "  starting_time:",
             f"    nanoseconds_since_epoch: {start}", f"  message_count: {sum(s['count'] for _, s in files)}",
             "  topics_with_message_count:"]
    for name in sorted(topics):
        t = topics[name]
        lines += ["    - topic_metadata:", f"        name: {_q(name)}", f"        type: {_q(t['type'])}",
                  f"        serialization_format: {_q(t['format'])}", "        offered_qos_profiles: ''",
                  f"      message_count: {t['count']}"]
    lines += ["  compression_format: ''", "  compression_mode: ''", "  relative_file_paths:"]
    lines += [f"    - {_q(name)}" for name, _ in files]
    lines.append("  files:")
    for name, s in files:
        lines += [f"    - path: {_q(name)}", "      starting_time:", f"        nanoseconds_since_epoch: {s['start']}",
                  "      duration:", f"        nanoseconds: {max(0, s['end'] - s['start'])}",
                  f"      message_count: {s['count']}"]
    return "\n".join(lines) + "\n"


def write_bag_metadata(session_dir: str | os.PathLike) -> Path | None:
    """Rewrite (or remove, with no segment left) the session's metadata.yaml; atomic. It is
    derived data: a failure here (a full disk) is the caller's to ignore, the next change writes
    it again."""
    d = Path(session_dir)
    path = d / BAG_METADATA
    with _lock:
        text = bag_metadata_text(SessionLayout.of(d).segments()) if d.is_dir() else None
        if text is None:
            path.unlink(missing_ok=True)
            return None
        write_text_atomic(path, text, fsync=False, unique=True)  # derived: the next change writes it again
    return path
