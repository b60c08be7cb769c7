"""Read a recorded session back: frames with their sidecars, in capture order.

This is the one place that knows how a session folder maps to frames, so the archiver and
the API read sessions the same way the recorder wrote them.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader

from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.icd.topics import camera_topics, decode_image, is_image_topic
from thermcap.recorder.storage.archive_readers import ARCHIVE_READERS
from thermcap.recorder.storage.chunks import SegmentIndex, iter_messages, read_through
from thermcap.recorder.storage.layout import PARTIAL_SUFFIX, DataRoot, SessionLayout

__all__ = [
    "SessionFrame",
    "archived_frame_count",
    "count_frames",
    "frame_files",
    "iter_segment_frames",
    "iter_session_frames",
    "list_sessions",
    "read_session_meta",
    "resolve_session",
    "segment_span",
    "session_cameras",
    "session_segments",
]


@dataclass
class SessionFrame:
    index: int  # position in the session, from 0
    segment: str  # segment file name, e.g. "0003.mcap"
    log_time: int
    pixels: np.ndarray  # (H, W) uint16, read-only view
    sidecar: bytes  # the JSON sidecar exactly as recorded (b"" if it is missing)

    def sidecar_dict(self) -> dict[str, Any]:
        return json.loads(self.sidecar) if self.sidecar else {}


def session_segments(session_dir: str | Path) -> list[Path]:
    """The finished segments of a session, in order (``.active`` ones are not data yet)."""
    d = Path(session_dir)
    if not d.is_dir():
        raise McapFileError(f"{d}: no such session folder")
    return SessionLayout.of(d).segments()


def archived_frame_count(session_dir: str | Path) -> int | None:
    """How many frames the archive manifest says the session holds (its count survives
    ``--delete-source``); None where there is no readable manifest."""
    try:
        from thermcap.recorder.storage.manifest_file import read_manifest_file

        manifest = read_manifest_file(session_dir) or {}
        return int(manifest["source"]["frames"])
    except (McapFileError, KeyError, TypeError, ValueError):
        return None


def read_session_meta(session_dir: str | Path) -> dict[str, Any]:
    path = SessionLayout.of(Path(session_dir)).session_json
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    except ValueError as exc:
        raise McapFileError(f"{path}: not valid JSON ({exc})") from exc


def session_cameras(session_dir: str | Path) -> list[str]:
    """The camera names of a session of several cameras (``/thermal/<name>/...``); [] for the
    single-camera layout."""
    cams = read_session_meta(session_dir).get("cameras")
    return sorted(cams) if isinstance(cams, dict) else []


def iter_segment_frames(path: Path, *, first_index: int = 0, camera: str | None = None,
                        others: Callable[[Any, Any, Any], None] | None = None) -> Iterator[SessionFrame]:
    """Frames of one segment (of one named camera); each image is paired with the sidecar that
    has its log time. ``others(schema, channel, message)`` is given every message but the images,
    sidecars included, from the same read: the archiver keeps them without decompressing the
    segment a second time."""
    topics = camera_topics(camera)
    wanted = (topics.image, topics.metadata)
    try:
        pending: dict[int, tuple[np.ndarray | None, bytes | None]] = {}
        index = first_index
        for schema, channel, msg in _segment_messages(path, None if others is not None else wanted):
            if others is not None:
                if channel.topic != topics.image:
                    others(schema, channel, msg)
                if channel.topic not in wanted:
                    continue
            img, meta = pending.get(msg.log_time, (None, None))
            if channel.topic == topics.image:
                img = decode_image(msg.data)[1]
            else:
                meta = json_payload(channel.message_encoding, msg.data)
            if img is not None and meta is not None:
                pending.pop(msg.log_time, None)
                yield SessionFrame(index, path.name, msg.log_time, img, meta)
                index += 1
            else:
                pending[msg.log_time] = (img, meta)
            # An image whose sidecar never comes (should not happen) is still a frame.
            for t in [t for t in pending if t < msg.log_time and pending[t][0] is not None]:
                orphan = pending.pop(t)[0]
                assert orphan is not None
                yield SessionFrame(index, path.name, t, orphan, b"")
                index += 1
        for t in sorted(pending):
            orphan = pending[t][0]
            if orphan is not None:
                yield SessionFrame(index, path.name, t, orphan, b"")
                index += 1
    except McapFileError:
        raise
    except Exception as exc:
        raise McapFileError(f"{path}: cannot read frames ({type(exc).__name__}: {exc})") from exc


def _segment_messages(path: Path, topics: tuple[str, ...] | None) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) of every message of ``topics`` (all where None), in log-time
    order: from the segment's chunk index, one chunk at a time (``chunks.iter_messages``), where
    its chunks follow each other in time as the recorder writes them; through mcap's reader for
    any other file (no summary, overlapping chunks), which gives the same messages in the same
    order. A message's data may be a view into its chunk rather than bytes."""
    try:
        index = SegmentIndex.load(path)
    except McapFileError:
        index = None  # mcap's reader says what is wrong, or reads what it can
    if index is None or not index.chunks_in_time_order:
        yield from read_through(path, None if topics is None else list(topics))
        return
    summary_channels, schemas = index.channels, index.schemas
    ids = None if topics is None else {cid for cid, ch in summary_channels.items() if ch.topic in topics}
    for msg in iter_messages(index, ids):
        channel = summary_channels[msg.channel_id]  # KeyError, as in mcap's reader: a message of no channel
        yield schemas.get(channel.schema_id) if channel.schema_id else None, channel, msg


def iter_session_frames(session_dir: str | Path, camera: str | None = None) -> Iterator[SessionFrame]:
    """Every frame of a session (of one camera, in a session of several), from its MCAP
    segments, or once they are deleted after archiving, from the archive. The ``thermcap``
    facade registers the archive's reader (``register_archive_reader``), so the recorder reads
    archives without importing them."""
    cameras = session_cameras(session_dir)
    if camera is None and cameras:  # reading /thermal/image here would find nothing, silently
        raise McapFileError(f"{session_dir}: a session of several cameras ({', '.join(cameras)}); name one")
    if camera is not None and camera not in cameras:
        raise McapFileError(f"{session_dir}: no camera {camera!r} (cameras: {', '.join(cameras) or 'one, unnamed'})")
    segments = session_segments(session_dir)
    if segments:
        index = 0
        for seg in segments:
            for frame in iter_segment_frames(seg, first_index=index, camera=camera):
                yield frame
                index = frame.index + 1
        return
    for read_archive in ARCHIVE_READERS:
        frames = read_archive(Path(session_dir))
        if frames is not None:
            yield from frames
            return


def frame_files(session_dir: str | Path) -> list[Path]:
    """The MCAP files that hold a session's other topics and attachments: its segments, or the
    archive's extras.mcap once they are deleted."""
    segments = session_segments(session_dir)
    if segments:
        return segments
    extras = SessionLayout.of(session_dir).extras
    return [extras] if extras.is_file() else []


def segment_span(seg: Path, camera: str | None = None) -> tuple[int, int, int]:
    """(first message time, last message time, frames) of a finished segment, from its summary
    (no decompression): frames of every camera, or of the one named. A cut or damaged file is an
    McapFileError naming it."""
    try:
        with open(seg, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception as exc:  # a cut or damaged file may fail anywhere inside the reader
        raise McapFileError(f"{seg}: no readable summary ({type(exc).__name__}: {exc}); is it cut short? "
                            f"`thermcap recover {seg}` keeps every complete chunk") from None
    if summary is None or summary.statistics is None:
        raise McapFileError(f"{seg}: no summary; is it a finished segment?")
    st = summary.statistics
    want = camera_topics(camera).image if camera is not None else None
    ids = [c.id for c in summary.channels.values() if (c.topic == want if want else is_image_topic(c.topic))]
    return st.message_start_time, st.message_end_time, sum(st.channel_message_counts.get(i, 0) for i in ids)


def count_frames(session_dir: str | Path, camera: str | None = None) -> dict[str, int]:
    """Frames per segment (of every camera, or the one named), from the MCAP summaries."""
    return {seg.name: segment_span(seg, camera)[2] for seg in session_segments(session_dir)}


def resolve_session(arg: str | Path, root: str | Path) -> Path:
    """A session folder from a path or an id under ``root/sessions``: one that holds a session
    (its ``session.json``, segments or archive), checked before any command writes in it (a lock,
    an ``archive/`` folder), so a path given by mistake (``/etc``) is refused as it is."""
    p = Path(arg)
    candidate = DataRoot.of(root).session_dir(str(arg))
    found = p if p.is_dir() else candidate if "/" not in str(arg) and candidate.is_dir() else None
    if found is None:
        raise McapFileError(f"{arg}: no such session (not a folder, and not an id under {DataRoot.of(root).sessions})")
    layout = SessionLayout.of(found)
    if not (layout.session_json.is_file() or layout.manifest.is_file() or session_segments(found)
            or layout.active_segments()):
        raise McapFileError(f"{arg}: not a session (no session.json, segments or archive in {found})")
    return found


def list_sessions(root: str | Path) -> list[Path]:
    """Session folders under ROOT/sessions; a ``.partial`` one (being made) is not a session yet."""
    return [p for p in DataRoot.of(root).session_dirs() if not p.name.endswith(PARTIAL_SUFFIX)]
