"""Indexing: what the service knows about each session, so catalog and search never scan files.

``index_root`` walks ``ROOT/sessions``; a session is (re)indexed only when its fingerprint (the
session summary, the manifest, the segment files) changed, inside one transaction, so indexing
twice changes nothing and a session archived while the service was down is picked up at the
next scan. Per-frame rows come from the sidecars (in a stored-ZIP archive when there is one,
else the MCAP source); for zipped archives each frame's byte range is recorded, so a frame is
one ranged read from local disk or S3.

A session's per-frame facts are written as one columnar file beside the archives in the blob
store (``api.reading.frame_columns``); the database keeps the session's row and a row per second
that holds a target (``api.reading.frame_search``), so it grows by seconds, not by frames.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sqlalchemy import delete, insert, select, text
from sqlalchemy.engine import Engine

from thermcap.api import db
from thermcap.api.reading.frame_columns import FrameColumns, frames_key
from thermcap.api.reading.frame_search import target_second_rows
from thermcap.archive.blobs import BlobStore
from thermcap.archive.reading.numbering import number_frames, sidecar_summary
from thermcap.recorder.importers.ros2_bag import is_ros2_bag_folder
from thermcap.recorder.storage.coverage import coverage
from thermcap.recorder.storage.layout import MANIFEST_JSON, SessionLayout, archive_key
from thermcap.recorder.storage.lock import holder, session_status
from thermcap.recorder.storage.reader import list_sessions, read_session_meta, session_segments

__all__ = ["IndexReport", "convert_legacy_frames", "fingerprint", "index_root", "index_session"]


@dataclass
class IndexReport:
    """What one pass over ROOT did, by session folder name (``removed`` by session id)."""

    indexed: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)
    removed: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)  # folder -> the error, so one bad session is visible
    skipped: dict[str, str] = field(default_factory=dict)  # folder -> why it is not served as it is
    damaged: dict[str, list[str]] = field(default_factory=dict)  # folder -> the parts not served, and why

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

#: Bumped whenever what the index derives from the files changes, so old rows are rebuilt.
INDEX_RULES_VERSION = 5  # 2: frames with no graded target have no grade; 3: the frame summary; 4: no frame_blobs;
# 5: frames in a columnar file, target_seconds


def fingerprint(session_dir: Path) -> str:
    h = hashlib.sha256(f"rules:{INDEX_RULES_VERSION}".encode())
    layout = SessionLayout.of(session_dir)
    for p in [layout.session_json, layout.manifest, layout.events_json, layout.analysis_jsonl,
              *session_segments(session_dir)]:
        try:
            st = p.stat()
        except FileNotFoundError:
            h.update(f"{p.name}:-".encode())
            continue
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns}".encode())
    return h.hexdigest()


def _settings_store(root: Path) -> BlobStore:
    """The store the service's settings (``THERMCAP_S3_*``) name for ``root``: where ``serve``
    looks for the frames files."""
    from thermcap.api.settings import Settings
    from thermcap.api.storage import make_store

    return make_store(Settings(root=root))


def index_session(engine: Engine, session_dir: Path, *, force: bool = False,
                  problems: list[str] | None = None, store: BlobStore | None = None) -> bool:
    """Index one session; returns False when it was already indexed as it is. What could not be
    read (a damaged chunk, a segment cut short) is added to ``problems``: the rest is indexed.
    The frames file goes to ``store`` (default: the store the service's settings name for the
    session's data root, as ``serve`` reads it)."""
    problems = [] if problems is None else problems
    session_dir = Path(session_dir)
    store = store if store is not None else _settings_store(session_dir.parent.parent)
    meta = read_session_meta(session_dir)
    sid = meta.get("session_id") or session_dir.name
    fp = fingerprint(session_dir)
    old = _row_state(engine, sid)
    # On local disk the frames file is looked at, not assumed: one deleted by hand is rewritten.
    if old is not None and old[0] == fp and old[1] is not None and not force \
            and (store.kind != "local" or store.head(old[1]) is not None):
        return False
    numbered = number_frames(session_dir, problems)
    manifest, proof = numbered.manifest, numbered.proof
    sidecars, times, segs = numbered.sidecars, numbered.times, numbered.segments
    frame_rows: list[dict[str, Any]] = []
    hashes, sidecar_hashes = proof.pixels, proof.sidecars
    for i, (sc, t) in enumerate(zip(sidecars, times, strict=True)):
        frame_rows.append({"session_id": sid, "idx": i, "timestamp_ns": int(t or 0),
                           "segment": segs[i] if i < len(segs) else None,
                           "pixel_digest": hashes[i] if i < len(hashes) else None,
                           "sidecar_digest": sidecar_hashes[i] if i < len(sidecar_hashes) else None,
                           **sidecar_summary(sc)})
    grades = [r["grade"] for r in frame_rows if r["grade"] is not None]
    sensor = meta.get("sensor") or (manifest or {}).get("session", {}).get("sensor") or {}
    model = meta.get("radiometric_model") or (manifest or {}).get("session", {}).get("radiometric_model")
    src = (manifest or {}).get("source", {})
    first = sidecars[0] if sidecars else {}
    res = (first.get("sensor") or {}).get("resolution") or {}
    valid_times: list[int] = [r["timestamp_ns"] for r in frame_rows]
    row = {
        "id": sid, "path": str(session_dir), "sensor": sensor.get("model"), "sensor_id": sensor.get("sensor_id"),
        "width": res.get("width") or src.get("width"), "height": res.get("height") or src.get("height"),
        "fps": sensor.get("frame_rate_hz"), "start_ns": min(valid_times) if valid_times else None,
        "end_ns": max(valid_times) if valid_times else None, "frames": len(frame_rows),
        "frames_dropped": int(meta.get("frames_dropped") or 0), "radiometric_model": json.dumps(model),
        "status": session_status(session_dir, meta.get("status"))[0], "min_grade": min(grades) if grades else None,
        "max_grade": max(grades) if grades else None,
        "has_targets": any(r["target_count"] for r in frame_rows),
        "has_slew_to_cue": any(r["slew_to_cue"] for r in frame_rows),
        "coverage": json.dumps(coverage(sorted(valid_times))), "source_deleted": bool(src.get("deleted")),
        # a session read with problems is read again at every scan, so they are reported every time
        "fingerprint": f"damaged:{fp}" if problems else fp, "indexed_at": time.time_ns(),
        "summary": json.dumps((manifest or {})["summary"]) if (manifest or {}).get("summary") else None,
    }
    seg_rows = [{"session_id": sid, "name": s.name, "frames": sum(1 for x in segs if x == s.name),
                 "bytes": s.stat().st_size} for s in session_segments(session_dir)]
    arch_rows = [{"session_id": sid, "format": f, "files": json.dumps(e["files"]), "bytes": e["bytes"],
                  "objects": e["objects"], "ratio": e.get("compression_ratio"),
                  "verified": bool(e.get("verified")) and not e.get("damaged")}
                 for f, e in (manifest or {}).get("formats", {}).items()]
    columns = FrameColumns.from_rows(sid, frame_rows, proof.name)
    row["frames_key"] = key = frames_key(sid, row["fingerprint"])
    store.put_bytes(key, columns.to_parquet())  # before the row names it: a reader never finds it missing
    target_rows = target_second_rows(columns)
    event_rows = []
    events_path = SessionLayout.of(session_dir).events_json
    if events_path.is_file():
        try:
            for i, ev in enumerate(json.loads(events_path.read_text()).get("events", [])):
                event_rows.append({"session_id": sid, "seq": i, "kind": ev["kind"], "start_ns": ev["start_ns"],
                                   "end_ns": ev["end_ns"], "detail": json.dumps(ev.get("detail", {}))})
        except (ValueError, KeyError, TypeError):
            pass
    old_key = old[1] if old is not None else None
    try:
        with engine.begin() as conn:
            _delete_session_rows(conn, sid)
            conn.execute(insert(db.sessions), [row])
            for table, rows in ((db.segments, seg_rows), (db.archives, arch_rows), (db.target_seconds, target_rows),
                                (db.events, event_rows)):
                for i in range(0, len(rows), 5000):
                    conn.execute(insert(table), rows[i:i + 5000])
    except Exception:
        # Another indexer of the same session (a second API worker at start-up, a fleet worker)
        # may have committed meanwhile: what the database names now decides, never this attempt.
        now = _row_now(engine, sid)
        if now == (row["fingerprint"], key):
            return False  # that other indexer committed this very state: indexed as it is
        if key != old_key and now is not _UNREADABLE and (now is None or now[1] != key):
            _forget(store, key)  # named by no row: this attempt's alone
        raise
    if old_key and old_key != key:
        _forget(store, old_key)  # readers holding it keep their cached copy; a new read takes the new key
    return True


#: ``_row_now`` could not read the index: nothing is deleted on its word.
_UNREADABLE = ("", "")


def _row_state(engine: Engine, sid: str) -> tuple[str, str | None] | None:
    """The session's (fingerprint, frames key) as committed, or None where it has no row."""
    with engine.connect() as conn:
        row = conn.execute(select(db.sessions.c.fingerprint, db.sessions.c.frames_key)
                           .where(db.sessions.c.id == sid)).first()
    return None if row is None else (row[0], row[1])


def _row_now(engine: Engine, sid: str) -> tuple[str, str | None] | None:
    """``_row_state``, or ``_UNREADABLE`` where the index cannot be read."""
    try:
        return _row_state(engine, sid)
    except Exception:
        return _UNREADABLE


def _forget(store: BlobStore, key: str) -> None:
    """Delete a frames file the index no longer names (gone already is fine: another indexer of
    the same index may have been first)."""
    with contextlib.suppress(FileNotFoundError):
        store.delete(key)


def _delete_session_rows(conn: Any, sid: str) -> None:
    for table in (db.target_seconds, db.archives, db.segments, db.events):
        conn.execute(delete(table).where(table.c.session_id == sid))
    conn.execute(delete(db.sessions).where(db.sessions.c.id == sid))


def convert_legacy_frames(engine: Engine, store: BlobStore) -> list[str]:
    """Write a frames file for every session an index before 0009 kept as rows (``frames_legacy``),
    then drop the rows: a session served from a bucket alone, whose folder is gone and so is
    never indexed again, keeps its frames. Returns the sessions converted."""
    with engine.connect() as conn:
        if not conn.dialect.has_table(conn, "frames_legacy"):
            return []
        sids = [r[0] for r in conn.execute(text("SELECT DISTINCT session_id FROM frames_legacy"))]
    done = []
    for sid in sids:
        with engine.connect() as conn:
            session = conn.execute(select(db.sessions.c.fingerprint, db.sessions.c.frames_key)
                                   .where(db.sessions.c.id == sid)).first()
            legacy = conn.execute(text(
                "SELECT idx, timestamp_ns, segment, grade, slew_to_cue, target_count, max_target_temp_c, sha256, "
                "sidecar_sha256 FROM frames_legacy WHERE session_id = :sid ORDER BY idx"),
                {"sid": sid}).mappings().all()
        if session is not None and session[1] is None:
            rows: list[dict[str, Any]] = [{}] * (max(r["idx"] for r in legacy) + 1)
            for r in legacy:
                hashes = {to: (bytes(r[k]).hex() if isinstance(r[k], bytes | memoryview) else r[k])
                          for k, to in (("sha256", "pixel_digest"), ("sidecar_sha256", "sidecar_digest"))}
                rows[r["idx"]] = {**r, **hashes}
            columns = FrameColumns.from_rows(sid, rows, "sha256")  # the rows' columns were sha256 alone
            key = frames_key(sid, f"legacy:{session[0]}")
            store.put_bytes(key, columns.to_parquet())
            with engine.begin() as conn:
                conn.execute(delete(db.target_seconds).where(db.target_seconds.c.session_id == sid))
                targets = target_second_rows(columns)
                if targets:
                    conn.execute(insert(db.target_seconds), targets)
                conn.execute(db.sessions.update().where(db.sessions.c.id == sid).values(frames_key=key))
                conn.execute(text("DELETE FROM frames_legacy WHERE session_id = :sid"), {"sid": sid})
            done.append(sid)
        else:
            with engine.begin() as conn:  # no session, or indexed anew already: the rows are stale
                conn.execute(text("DELETE FROM frames_legacy WHERE session_id = :sid"), {"sid": sid})
    with engine.begin() as conn:
        conn.execute(text("DROP TABLE frames_legacy"))
    return done


def _id_of(session_dir: Path) -> str:
    try:
        return str(read_session_meta(session_dir).get("session_id") or session_dir.name)
    except Exception:  # an unreadable session.json is reported where the session is indexed
        return session_dir.name


def index_root(engine: Engine, root: Path, *, force: bool = False, store: Any = None) -> IndexReport:
    """Index every session under ROOT; drop sessions whose folder is gone, unless ``store`` is an
    object store holding their uploaded manifest: ``gc`` frees local disk once a session is in the
    bucket, and the catalog keeps serving it from there. Skips unfinished sessions."""
    report = IndexReport()
    store = store if store is not None else _settings_store(Path(root))
    convert_legacy_frames(engine, store)
    present: set[str] = set()
    served: dict[str, str] = {}  # session id -> the folder serving it
    # a folder named as its session id is that session; a copy beside it (`cp -a` for a backup)
    # keeps the id, and one id cannot name two folders' frames: the copy is named, not served
    folders = sorted(list_sessions(root), key=lambda d: (_id_of(d) != d.name, d.name))
    for d in folders:
        layout = SessionLayout.of(d)
        if not layout.session_json.exists() and not layout.archive.exists():
            if is_ros2_bag_folder(d):  # copied in as it was recorded: said, not silently passed over
                report.skipped[d.name] = f"a ROS 2 bag, not a session: `thermcap import {d}` makes it one"
            continue
        if layout.active_segments():
            if holder(d) is not None:
                continue  # being recorded: served once its recorder has finished it
            # a recorder died: its closed segments are served, the unfinished one waits for recover
            report.damaged[d.name] = [f"{len(layout.active_segments())} unfinished segments (*.active) are not "
                                      f"served until `thermcap recover {d}`"]
        meta = read_session_meta(d)
        if isinstance(meta.get("cameras"), dict):  # read as one camera it would show no frame at all
            report.skipped[d.name] = (f"a session of several cameras ({', '.join(sorted(meta['cameras']))}): "
                                      f"served through its per-camera sessions (thermcap split-cameras)")
            continue
        sid = meta.get("session_id") or d.name
        if sid in served:
            report.skipped[d.name] = (f"its session_id {sid!r} is also sessions/{served[sid]}'s (a copy?): not served; "
                                      f"move the copy out of the data root or import it under another id")
            continue
        served[sid] = d.name
        present.add(sid)
        problems: list[str] = []
        try:
            (report.indexed if index_session(engine, d, force=force, problems=problems, store=store)
             else report.unchanged
             ).append(d.name)
        except Exception as exc:  # one broken session must not stop the others
            report.failed[d.name] = f"{type(exc).__name__}: {exc}"
        if problems:
            report.damaged.setdefault(d.name, []).extend(problems)
    with engine.begin() as conn:
        known = {r[0] for r in conn.execute(select(db.sessions.c.id))}
        gone = sorted(known - present)
        if store.kind != "local":
            in_store = {sid for sid in gone if store.head(archive_key(sid, MANIFEST_JSON)) is not None}
            gone = [sid for sid in gone if sid not in in_store]
        keys = [k for sid in gone for k in conn.execute(select(db.sessions.c.frames_key)
                                                        .where(db.sessions.c.id == sid)).scalars() if k]
        for sid in gone:
            _delete_session_rows(conn, sid)
    for key in keys:
        _forget(store, key)
    report.removed = gone
    return report
