"""``thermcap split-cameras``: one single-camera session per camera of a session of several.

Each camera's messages are copied into ``sessions/<id>.<camera>/`` in the plain layout:
``/thermal/<camera>/image`` becomes ``/thermal/image`` (and so for its sidecar and its other
topics); the shared ``/recorder/events`` and ``/recorder/stats`` come along; the camera's
attachments lose their ``<camera>/`` prefix. Message bytes and log times are copied, never
re-encoded, so every frame and sidecar of the new session hashes as it did, and the archiver,
the index and the API handle it like any other session. The copy is written under a
``.partial`` name, compared frame by frame with the source, and only then renamed; with
``delete_source`` the original segments go only once every camera's copy compared equal.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from thermcap.recorder.exceptions import McapFileError, ThermcapError
from thermcap.recorder.icd.topics import TOPIC_EVENTS, TOPIC_STATS, camera_topics
from thermcap.recorder.storage.atomic import fsync_dir, write_json_atomic
from thermcap.recorder.storage.layout import PARTIAL_SUFFIX, SessionLayout
from thermcap.recorder.storage.lock import holder, lock_session
from thermcap.recorder.storage.reader import (
    archived_frame_count,
    count_frames,
    iter_session_frames,
    read_session_meta,
    session_cameras,
    session_segments,
)
from thermcap.recorder.storage.rosbag2 import write_bag_metadata
from thermcap.recorder.storage.segments import SESSION_METADATA
from thermcap.recorder.storage.writer import ChunkedWriter, Compression

__all__ = ["SplitResult", "camera_session_id", "split_cameras"]

_SHARED = (TOPIC_EVENTS, TOPIC_STATS)


def camera_session_id(session_id: str, camera: str) -> str:
    return f"{session_id}.{camera}"


@dataclass
class SplitResult:
    session: str
    cameras: dict[str, str] = field(default_factory=dict)  # camera -> its session folder
    frames: dict[str, int] = field(default_factory=dict)
    already: list[str] = field(default_factory=list)  # split by an earlier run
    source_deleted: bool = False

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _rename(topic: str, camera: str) -> str | None:
    """The single-camera topic for ``camera``'s ``topic``; None for another camera's."""
    prefix = f"/thermal/{camera}/"
    if topic.startswith(prefix):
        rest = topic[len(prefix) - 1:]
        return {"/image": "/thermal/image", "/metadata": "/thermal/metadata"}.get(rest, rest)
    if topic in _SHARED:
        return topic
    return None


def _copy_segment(src: Path, dst: Path, camera: str, session_meta: dict[str, str]) -> int:
    """Copy one camera's part of a segment; returns the frames copied."""
    frames = 0
    with open(src, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        if summary is None:
            raise McapFileError(f"{src}: no summary; run `thermcap recover` first")
        writer = ChunkedWriter(dst, compression=Compression.ZSTD, compression_level=1, workers=2)
        writer.start(profile="ros2")
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for cid, ch in sorted(summary.channels.items()):
            topic = _rename(ch.topic, camera)
            if topic is None:
                continue
            if ch.schema_id and ch.schema_id not in schema_ids:
                s = summary.schemas[ch.schema_id]
                schema_ids[ch.schema_id] = writer.register_schema(s.name, s.encoding, s.data)
            channel_ids[cid] = writer.register_channel(topic, ch.message_encoding, schema_ids.get(ch.schema_id, 0),
                                                       dict(ch.metadata))
        image = camera_topics(camera).image
        for _, ch, msg in reader.iter_messages(topics=[summary.channels[c].topic for c in channel_ids]):
            writer.add_message(channel_ids[ch.id], msg.log_time, bytes(msg.data), publish_time=msg.publish_time,
                               sequence=msg.sequence)
            frames += ch.topic == image
        for att in reader.iter_attachments():
            name = att.name
            if "/" in name:
                owner, _, name = name.partition("/")
                if owner != camera:
                    continue
            writer.add_attachment(name, att.media_type, bytes(att.data), log_time=att.log_time,
                                  create_time=att.create_time)
        for rec in reader.iter_metadata():
            writer.add_metadata(rec.name, session_meta if rec.name == SESSION_METADATA else dict(rec.metadata))
        writer.finish(fsync=True)
    return frames


def _frame_hashes(session_dir: Path, camera: str | None) -> list[tuple[int, str, str]]:
    return [(f.log_time, hashlib.sha256(f.pixels.tobytes()).hexdigest(), hashlib.sha256(f.sidecar).hexdigest())
            for f in iter_session_frames(session_dir, camera)]


def split_cameras(session_dir: str | Path, *, delete_source: bool = False) -> SplitResult:
    session_dir = Path(session_dir)
    cameras = session_cameras(session_dir)
    if not cameras:
        raise ThermcapError(f"{session_dir}: a session of one camera; there is nothing to split")
    layout = SessionLayout.of(session_dir)
    if layout.active_segments():
        raise ThermcapError(f"{session_dir}: has unfinished segments (*.active); recording, or run `thermcap recover`")
    lock = lock_session(session_dir, "split-cameras")
    if lock is None:
        raise ThermcapError(f"{session_dir}: {holder(session_dir) or 'another process'} holds this session")
    try:
        return _split_locked(session_dir, cameras, delete_source)
    except OSError as exc:
        raise ThermcapError(f"{exc.filename or session_dir}: {exc.strerror or exc}; the source is untouched") from None
    finally:
        lock.release()


def _split_locked(session_dir: Path, cameras: list[str], delete_source: bool) -> SplitResult:
    meta = read_session_meta(session_dir)
    sid = meta.get("session_id", session_dir.name)
    result = SplitResult(session=sid)
    segments = session_segments(session_dir)
    if not segments and not meta.get("split_into"):
        raise ThermcapError(f"{session_dir}: no segments to split")
    events = _read_json(SessionLayout.of(session_dir).events_json).get("events", [])
    compared: set[str] = set()  # copies made and compared with the source in this run
    for cam in cameras:
        out = session_dir.parent / camera_session_id(sid, cam)
        result.cameras[cam] = str(out)
        if SessionLayout.of(out).session_json.is_file():
            result.already.append(cam)  # counted from its summaries, or its archive once archived
            result.frames[cam] = sum(count_frames(out).values()) or archived_frame_count(out) or 0
            continue
        if not segments:
            raise ThermcapError(f"{session_dir}: its segments are gone but {out.name} was never made")
        tmp = out.with_name(out.name + PARTIAL_SUFFIX)
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        # the session's figures are for all cameras: keep only this camera's
        cam_meta = {k: v for k, v in meta.items() if k not in ("cameras", "split_into", "segments", "frames_captured",
                                                               "frames_written", "frames_dropped", "dropped")}
        cam_meta.update(meta["cameras"][cam])
        for k in ("image_topic", "metadata_topic"):
            cam_meta.pop(k, None)
        cam_meta.update(session_id=out.name, camera=cam, split_from=sid,
                        dropped={("/thermal/" + t.split("/", 3)[3] if t.startswith(f"/thermal/{cam}/") else t): n
                                 for t, n in (meta.get("dropped") or {}).items()
                                 if t.startswith(f"/thermal/{cam}/")})
        mcap_meta = {k: v if isinstance(v, str) else json.dumps(v) for k, v in cam_meta.items()
                     if k in ("session_id", "started_ns", "started", "sensor", "radiometric_model", "source",
                              "software_version", "format_version", "camera", "split_from")}
        frames = 0
        for seg in segments:
            frames += _copy_segment(seg, tmp / seg.name, cam, mcap_meta)
        write_json_atomic(SessionLayout.of(tmp).events_json,
                          {"session_id": out.name, "events": [e for e in events if e.get("camera") in (None, cam)]})
        if SessionLayout.of(session_dir).protected_json.is_file():
            shutil.copy2(SessionLayout.of(session_dir).protected_json, SessionLayout.of(tmp).protected_json)
        write_json_atomic(SessionLayout.of(tmp).session_json, cam_meta)
        with contextlib.suppress(OSError):  # derived data: a failure must not undo the work above
            write_bag_metadata(tmp)
        if _frame_hashes(tmp, None) != _frame_hashes(session_dir, cam):
            shutil.rmtree(tmp)
            raise ThermcapError(f"{session_dir}: the copy of camera {cam} does not read back as the source; "
                                f"nothing was kept")
        fsync_dir(tmp)
        os.rename(tmp, out)
        fsync_dir(session_dir.parent)
        compared.add(cam)
        result.frames[cam] = frames
    meta["split_into"] = {cam: Path(p).name for cam, p in result.cameras.items()}
    write_json_atomic(SessionLayout.of(session_dir).session_json, meta)
    if delete_source and segments:
        for cam in [c for c in cameras if c not in compared]:  # made by an earlier run: compare them now
            if _frame_hashes(Path(result.cameras[cam]), None) != _frame_hashes(session_dir, cam):
                raise ThermcapError(f"{result.cameras[cam]}: differs from the source; the source was kept")
        for seg in segments:
            seg.unlink()
        fsync_dir(session_dir)
        with contextlib.suppress(OSError):  # derived data: a failure must not undo the work above
            write_bag_metadata(session_dir)
        meta["split_source_deleted"] = True
        write_json_atomic(SessionLayout.of(session_dir).session_json, meta)
        result.source_deleted = True
    return result


def _read_json(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}
