"""``thermcap play``: a recorded or archived session over the live protocol, as if live.

Frames come from ``iter_session_frames`` (the MCAP segments, or the archive once they are
deleted), every camera merged on the session's one clock, and are released at their recorded
spacing divided by ``rate``; the recorded events go out at their times. Nothing is written.
"""

from __future__ import annotations

import heapq
import json
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.live.publisher import LivePublisher
from thermcap.recorder.radiometry import RadiometricModel, model_from_dict
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.reader import SessionFrame, iter_session_frames, read_session_meta, session_cameras

__all__ = ["ReplayResult", "replay_session"]


@dataclass
class ReplayResult:
    frames: int = 0
    events: int = 0
    loops: int = 0
    wall_s: float = 0.0
    cameras: list[str] = field(default_factory=list)
    stopped: bool = False

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _model(doc: Any) -> RadiometricModel | None:
    try:
        return model_from_dict(doc)
    except (ValueError, TypeError, KeyError):
        return None  # the picture still plays; the temperature channel says null


def _merged(session_dir: Path, cameras: list[str | None]) -> Iterator[tuple[int, str | None, SessionFrame]]:
    streams = [((f.log_time, i, cam, f) for f in iter_session_frames(session_dir, cam))
               for i, cam in enumerate(cameras)]
    for t, _, cam, f in heapq.merge(*streams, key=lambda x: (x[0], x[1])):
        yield t, cam, f


def replay_session(session_dir: str | Path, publisher: LivePublisher, *, rate: float = 1.0, loop: bool = False,
                   start_s: float = 0.0, max_fps: float = 0.0, stop: threading.Event | None = None,
                   duration_s: float | None = None, wait_for_viewer_s: float = 0.0) -> ReplayResult:
    """Publish the session until it ends (or, with ``loop``, until ``stop`` or ``duration_s``);
    first wait up to ``wait_for_viewer_s`` for a viewer to subscribe (its channels are
    advertised by then)."""
    if rate <= 0:
        raise ThermcapError(f"--rate must be positive, got {rate}")
    session_dir = Path(session_dir)
    meta = read_session_meta(session_dir)
    names = session_cameras(session_dir)
    cameras: list[str | None] = list(names) if names else [None]
    for cam in cameras:
        doc = meta["cameras"][cam].get("radiometric_model") if cam is not None else meta.get("radiometric_model")
        publisher.add_camera(cam, _model(doc))
    temps = _session_temperatures(session_dir, meta) if not names else None
    events = _events(session_dir)
    stop = stop or threading.Event()
    if wait_for_viewer_s > 0:
        publisher.subscribed.wait(wait_for_viewer_s)
    result = ReplayResult(cameras=[c or "" for c in cameras])
    t_wall0 = time.monotonic()
    period_ns = int(1e9 / max_fps) if max_fps > 0 else 0
    while not stop.is_set():
        first: int | None = None
        next_ns: dict[str | None, int] = {}
        ev = 0
        loop_start = time.monotonic()
        for t, cam, frame in _merged(session_dir, cameras):
            if first is None:
                first = t
            offset = t - first
            if offset < start_s * 1e9:
                continue
            due = loop_start + (offset - start_s * 1e9) / 1e9 / rate
            while ev < len(events) and events[ev][0] <= t:
                publisher.publish_event(events[ev][0], events[ev][1])
                result.events += 1
                ev += 1
            if period_ns and t < next_ns.get(cam, 0):
                continue
            next_ns[cam] = t + period_ns
            wait = due - time.monotonic()
            if wait > 0 and stop.wait(wait):
                break
            if duration_s is not None and time.monotonic() - t_wall0 > duration_s:
                stop.set()
                break
            publisher.publish_frame(cam, t, frame.pixels, frame.index, frame.sidecar,
                                    model=temps.model_for(frame.index) if temps is not None else None)
            result.frames += 1
        result.loops += 1
        if first is None:
            raise ThermcapError(f"{session_dir}: no frames to play")
        if not loop:
            break
    result.stopped = stop.is_set()
    result.wall_s = round(time.monotonic() - t_wall0, 3)
    return result


def _session_temperatures(session_dir: Path, meta: dict[str, Any]) -> Any:
    """The session's one temperature path (the model version in force for each frame), or None
    where its model cannot be read (the live view then gives counts alone, as before)."""
    from thermcap.recorder.radiometry.session import SessionTemperatures

    try:
        return SessionTemperatures.of(session_dir, meta, bad_pixels="keep")
    except (ValueError, TypeError, KeyError):
        return None


def _events(session_dir: Path) -> list[tuple[int, dict[str, Any]]]:
    try:
        doc = json.loads(SessionLayout.of(session_dir).events_json.read_text())
    except (OSError, ValueError):
        return []
    out = [(int(e.get("at_ns") or e.get("start_ns") or 0), e) for e in doc.get("events", []) if isinstance(e, dict)]
    return sorted(out, key=lambda x: x[0])
