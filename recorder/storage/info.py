"""``thermcap info``: what a segment or a session holds, read from MCAP summaries (no full scan).

Per-topic byte counts come from the ``thermcap.segment`` metadata record our writer leaves in
each segment; for MCAP files written by other tools they are counted by reading the messages.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from mcap.reader import make_reader

from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.icd.names import iso_utc
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.icd.topics import TOPIC_METADATA, TOPIC_STATS, camera_topics, sum_image_topics
from thermcap.recorder.storage.chunks import log_times_in
from thermcap.recorder.storage.coverage import coverage
from thermcap.recorder.storage.coverage import gaps as coverage_gaps
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.ledger import deletions, lost_segments
from thermcap.recorder.storage.lock import session_status
from thermcap.recorder.storage.reader import archived_frame_count
from thermcap.recorder.storage.segments import ACTIVE_SUFFIX, SEGMENT_STATS_METADATA, SESSION_METADATA

__all__ = ["SegmentInfo", "SessionInfo", "TopicUsage", "info", "segment_info", "session_info"]


@dataclass(frozen=True)
class TopicUsage:
    messages: int
    bytes: int | None  # uncompressed message bytes; None when a segment did not say and was not counted


@dataclass(frozen=True)
class SegmentInfo:
    """One finished segment, as its summary section and our ``thermcap.segment`` record tell it."""

    path: str
    frames: int
    messages: int
    start: str | None
    end: str | None
    start_ns: int
    end_ns: int
    duration_s: float
    effective_fps: float | None
    chunks: int
    chunk_compression: list[str]
    bytes: int
    compressed_bytes: int
    uncompressed_bytes: int
    compression_ratio: float | None
    topics: dict[str, TopicUsage]
    attachments: list[str]
    dropped: dict[str, int] = field(default_factory=dict)  # from the segment's last stats message
    write_latency_ms: dict[str, Any] | None = None
    session_id: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class CameraUsage:
    """One camera of a session of several: its frames in the segments and what the recorder said."""

    sensor: str | None
    frames: int
    frames_captured: int | None
    frames_dropped: int
    effective_fps: float | None
    error: str | None


@dataclass(frozen=True)
class SessionInfo:
    """A session folder: its segments summed, its status from the lock, its timing from session.json."""

    path: str
    session_id: str
    status: str
    hint: str | None
    time_basis: str | None
    declared_fps: float | None
    achieved_fps: float | None
    frames_late: int | None
    sensor: str | None
    radiometric_model: Any
    frames: int
    frames_captured: int | None
    frames_dropped: int
    dropped: dict[str, int]
    start: str | None
    end: str | None
    duration_s: float
    effective_fps: float | None
    segments: list[SegmentInfo]
    active_segments: list[str]
    bytes: int
    compression_ratio: float | None
    chunk_compression: list[str]
    topics: dict[str, TopicUsage]
    write_latency_ms: Any
    error: str | None
    frames_from: str  # "segments", or "archive" once the source was deleted after archiving
    pauses: list[list[int | None]] = field(default_factory=list)  # [start_ns, end_ns] of `ctl pause` gaps
    frames_paused: int = 0
    ring: dict[str, Any] | None = None  # the --ring budget the session was recorded under
    evicted_segments: int = 0
    cameras: dict[str, CameraUsage] = field(default_factory=dict)  # a session of several cameras
    # segments session.json lists that are gone with no record of why (recorder.storage.ledger)
    lost_segments: list[dict[str, Any]] = field(default_factory=list)
    frames_lost: int = 0
    source: dict[str, Any] = field(default_factory=dict)  # what the source was (describe())
    # what it went through: gaps without frames, incomplete buffers, frames the camera sent that
    # never came, restarts or reconnections (empty for a source with nothing to tell)
    source_health: dict[str, Any] = field(default_factory=dict)
    # times without frames, as the API and the workbench define them (recorder.storage.coverage)
    gaps: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def segment_info(path: str | Path) -> SegmentInfo:
    return _segment_info(Path(path))[0]


def _segment_info(path: Path) -> tuple[SegmentInfo, list[int] | None]:
    """A segment's info and its frames' log times (from its message indexes; None where it has
    none), from one opening and one read of its summary."""
    frame_times: list[int] | None = None
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                raise McapFileError(f"{path}: no summary section (an unfinished segment? try `thermcap recover`)")
            stats = summary.statistics
            topics = {c.id: c.topic for c in summary.channels.values()}
            meta: dict[str, dict[str, str]] = {}
            for rec in reader.iter_metadata():
                meta[rec.name] = rec.metadata
            last_stats = None
            for _, channel, msg in reader.iter_messages(topics=[TOPIC_STATS]):
                last_stats = json_payload(channel.message_encoding, msg.data)
            topic_bytes: dict[str, int] = {}
            if SEGMENT_STATS_METADATA in meta:
                topic_bytes = {t: 0 for t in topics.values()}
                topic_bytes.update(json.loads(meta[SEGMENT_STATS_METADATA].get("topic_bytes", "{}")))
            else:
                for _, channel, msg in reader.iter_messages():
                    topic_bytes[channel.topic] = topic_bytes.get(channel.topic, 0) + len(msg.data)
            frame_times = log_times_in(f, summary, {TOPIC_METADATA})
    except McapFileError:
        raise
    except Exception as exc:
        raise McapFileError(f"{path}: not a readable MCAP file ({type(exc).__name__}: {exc})") from exc
    chunks = summary.chunk_indexes
    compressions = sorted({c.compression or "none" for c in chunks})
    comp = sum(c.compressed_size for c in chunks)
    uncomp = sum(c.uncompressed_size for c in chunks)
    counts = {topics[cid]: n for cid, n in stats.channel_message_counts.items() if cid in topics}
    frames = sum_image_topics(counts)
    span_s = (stats.message_end_time - stats.message_start_time) / 1e9 if stats.message_count else 0.0
    last = json.loads(last_stats) if last_stats is not None else {}
    return SegmentInfo(
        path=str(path),
        frames=frames,
        messages=stats.message_count,
        start=iso_utc(stats.message_start_time) if stats.message_count else None,
        end=iso_utc(stats.message_end_time) if stats.message_count else None,
        start_ns=stats.message_start_time,
        end_ns=stats.message_end_time,
        duration_s=round(span_s, 6),
        effective_fps=round((frames - 1) / span_s, 3) if frames > 1 and span_s > 0 else None,
        chunks=len(chunks),
        chunk_compression=compressions,
        bytes=path.stat().st_size,
        compressed_bytes=comp,
        uncompressed_bytes=uncomp,
        compression_ratio=round(uncomp / comp, 3) if comp else None,
        topics={t: TopicUsage(counts.get(t, 0), topic_bytes.get(t)) for t in sorted(set(counts) | set(topic_bytes))},
        attachments=[a.name for a in summary.attachment_indexes],
        dropped=last.get("dropped", {}),
        write_latency_ms=last.get("write_latency_ms", {}).get("session"),
        session_id=meta[SESSION_METADATA].get("session_id") if SESSION_METADATA in meta else None,
    ), frame_times


def session_info(path: str | Path) -> SessionInfo:
    path = Path(path)
    segments = sorted(p for p in path.glob("[0-9][0-9][0-9][0-9].mcap"))
    active = sorted(p.name for p in path.glob(f"*.mcap{ACTIVE_SUFFIX}"))
    meta: dict[str, Any] = {}
    if SessionLayout.of(path).session_json.is_file():
        try:
            meta = json.loads(SessionLayout.of(path).session_json.read_text())
        except ValueError as exc:
            raise McapFileError(f"{path / 'session.json'}: not valid JSON ({exc})") from exc
    if not segments and not meta:
        raise McapFileError(f"{path}: not a thermcap session (no NNNN.mcap segments, no session.json)")
    read = [_segment_info(p) for p in segments]
    segs = [info for info, _ in read]
    frames = sum(s.frames for s in segs)
    archived = archived_frame_count(path) if not segments else None
    if archived is not None:  # the source was deleted after archiving: the archive holds the frames
        frames = archived
    start = min((s.start_ns for s in segs if s.messages), default=None)
    end = max((s.end_ns for s in segs if s.messages), default=None)
    # the frames' own times, as the index takes them; none unless every segment can say
    times = [] if any(t is None for _, t in read) else sorted(t for _, ts in read for t in ts or [])
    if times:  # the frames' own times, as the index takes them: start, span and gaps agree with the API
        start, end = times[0], times[-1]
    fps = (meta.get("sensor") or {}).get("frame_rate_hz")
    period = 1e9 / fps if fps else 0.0
    found_gaps = [{"start": iso_utc(a), "end": iso_utc(b), "start_ns": a, "end_ns": b, "seconds": round(sec, 6)}
                  for a, b, sec in coverage_gaps(coverage(times), period)] if times else []
    span = (end - start) / 1e9 if start is not None and end is not None else 0.0
    topics: dict[str, TopicUsage] = {}
    for s in segs:
        for t, v in s.topics.items():
            agg = topics.get(t, TopicUsage(0, 0))
            nbytes = None if v.bytes is None or agg.bytes is None else agg.bytes + v.bytes
            topics[t] = TopicUsage(agg.messages + v.messages, nbytes)
    comp = sum(s.compressed_bytes for s in segs)
    uncomp = sum(s.uncompressed_bytes for s in segs)
    status, hint = session_status(path, meta.get("status"))
    lost = lost_segments(path, meta) if meta else []
    if lost:
        said = ", ".join(f"{s.name} ({s.frames} frames)" for s in lost)
        hint = (f"{sum(s.frames for s in lost)} frames the recorder wrote are missing: {said} gone from the "
                f"folder with no eviction, sync or archive on record" + (f"; {hint}" if hint else ""))
    timing = meta.get("timing") or {}
    return SessionInfo(
        path=str(path),
        session_id=meta.get("session_id", path.name),
        status=status,
        hint=hint,
        time_basis=timing.get("time_basis") or (meta.get("source") or {}).get("time_basis"),
        declared_fps=timing.get("declared_fps"),
        achieved_fps=timing.get("achieved_fps"),
        frames_late=timing.get("frames_late"),
        sensor=meta.get("sensor", {}).get("model") or (f"{len(meta['cameras'])} cameras" if meta.get("cameras")
                                                        else None),
        radiometric_model=meta.get("radiometric_model"),
        frames=frames,
        frames_captured=meta.get("frames_captured"),
        frames_dropped=meta.get("frames_dropped", 0),
        dropped=meta.get("dropped", {}),
        start=iso_utc(start) if start is not None else None,
        end=iso_utc(end) if end is not None else None,
        duration_s=round(span, 6),
        effective_fps=round((frames - 1) / span, 3) if frames > 1 and span > 0 else None,
        segments=segs,
        active_segments=active,
        bytes=sum(s.bytes for s in segs),
        compression_ratio=round(uncomp / comp, 3) if comp else None,
        chunk_compression=sorted({c for s in segs for c in s.chunk_compression}),
        topics=topics,
        write_latency_ms=meta.get("write_latency_ms"),
        error=meta.get("error"),
        frames_from="archive" if archived is not None else "segments",
        pauses=meta.get("pauses") or [],
        frames_paused=meta.get("frames_paused") or 0,
        ring=meta.get("ring"),
        evicted_segments=_evicted(Path(path), meta),
        cameras=_cameras(meta, topics, span),
        lost_segments=[{"name": s.name, "frames": s.frames} for s in lost], frames_lost=sum(s.frames for s in lost),
        source=meta.get("source") or {}, source_health=meta.get("source_health") or {}, gaps=found_gaps,
    )


def _evicted(session_dir: Path, meta: dict[str, Any]) -> int:
    """Segments the ring deleted from this session (not those sync freed once the cloud had them)."""
    n = sum("freed_by" not in entry for entry in deletions(session_dir))
    return max(n, int(meta.get("evicted_segments") or 0))


def _cameras(meta: dict[str, Any], topics: dict[str, TopicUsage], span: float) -> dict[str, CameraUsage]:
    out = {}
    for name, cam in sorted((meta.get("cameras") or {}).items()):
        n = topics.get(camera_topics(name).image, TopicUsage(0, 0)).messages
        out[name] = CameraUsage(sensor=(cam.get("sensor") or {}).get("model"), frames=n,
                                frames_captured=cam.get("frames_captured"),
                                frames_dropped=cam.get("frames_dropped") or 0,
                                effective_fps=round((n - 1) / span, 3) if n > 1 and span > 0 else None,
                                error=cam.get("error"))
    return out


def info(path: str | Path) -> SegmentInfo | SessionInfo:
    p = Path(path)
    if p.is_dir():
        return session_info(p)
    if p.is_file():
        if p.name.endswith(ACTIVE_SUFFIX):
            raise McapFileError(f"{p}: an unfinished segment; run `thermcap recover {p}` first")
        return segment_info(p)
    raise McapFileError(f"{p}: no such file or folder")
