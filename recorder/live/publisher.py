"""Frames, sidecars, annotations and events as Foxglove messages on a WebSocket server.

The server is the ``foxglove-sdk`` one (Rust, its own threads): each client has a bounded
outgoing buffer whose oldest message is dropped when a viewer is slow, so a viewer can never
push back on us. Images go out as ``foxglove.RawImage`` ``mono16``: the counts themselves,
subsampled when a lower resolution is asked for, never rescaled, so a value read off the
live picture is a real count of that pixel.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
from foxglove.websocket import ServerListener

from thermcap.recorder.radiometry import RadiometricModel

__all__ = ["CameraTopics", "LiveOptions", "LivePublisher", "check_live_host", "subsample"]


def check_live_host(host: str, port: int, flag: str) -> None:
    """The Foxglove WebSocket view (``record --live``, ``play``) has no token of its own, so it
    is served on this machine only; raises ValueError saying how to reach it from elsewhere."""
    from thermcap.recorder.loopback import is_loopback

    if not is_loopback(host):
        raise ValueError(f"{flag} {host}: the live view has no token of its own, so it is served on this machine "
                         f"only (127.0.0.1); reach it from elsewhere through an SSH tunnel "
                         f"(ssh -L {port}:127.0.0.1:{port} ...) or a proxy that checks a token")


@dataclass(frozen=True)
class LiveOptions:
    """What a viewer gets: at most ``max_fps`` frames per second per camera, subsampled so the
    picture is at most ``max_width`` pixels wide (0: full resolution)."""

    host: str = "127.0.0.1"
    port: int = 8765
    max_fps: float = 10.0
    max_width: int = 0
    name: str = "thermcap"
    #: messages buffered per viewer before its oldest is dropped (the SDK's backlog)
    backlog: int = 64


@dataclass(frozen=True)
class CameraTopics:
    """A camera's live topics: ``/thermal/...`` for a single camera, ``/thermal/<name>/...``
    when several share a session (the recorded layout)."""

    image: str
    metadata: str
    annotations: str
    temperature: str

    @classmethod
    def of(cls, camera: str | None) -> CameraTopics:
        base = "/thermal" if not camera else f"/thermal/{camera}"
        return cls(f"{base}/image", f"{base}/metadata", f"{base}/annotations", f"{base}/temperature")


def subsample(pixels: np.ndarray, max_width: int) -> tuple[np.ndarray, int]:
    """Every k-th pixel of every k-th row so the width is at most ``max_width``; (image, k)."""
    if not max_width or pixels.shape[1] <= max_width:
        return pixels, 1
    k = -(-pixels.shape[1] // max_width)
    return pixels[::k, ::k], k


_TEMPERATURE_SCHEMA = {
    "type": "object", "title": "thermcap.LiveTemperature",
    "properties": {"min_c": {"type": ["number", "null"]}, "max_c": {"type": ["number", "null"]},
                   "mean_c": {"type": ["number", "null"]}, "center_c": {"type": ["number", "null"]},
                   "hottest_xy": {"type": "array", "items": {"type": "integer"}},
                   "subsample": {"type": "integer"}, "frame_index": {"type": "integer"}},
}


class _Camera:
    def __init__(self, topics: CameraTopics, model: RadiometricModel | None, context: Any) -> None:
        from foxglove import Channel
        from foxglove.channels import ImageAnnotationsChannel, RawImageChannel

        self.topics = topics
        self.model = model
        self.image = RawImageChannel(topics.image, context=context)
        self.metadata = Channel(topics.metadata, message_encoding="json", context=context)
        self.annotations = ImageAnnotationsChannel(topics.annotations, context=context)
        self.temperature = Channel(topics.temperature, schema=_TEMPERATURE_SCHEMA, context=context)


class LivePublisher:
    """One Foxglove WebSocket server and the channels of each camera on it."""

    def __init__(self, options: LiveOptions | None = None) -> None:
        import foxglove

        self.options = options or LiveOptions()
        self.subscribed = threading.Event()  # set once a viewer subscribes to anything
        self._viewers: dict[int, int] = {}  # client id -> subscriptions
        self._context = foxglove.Context()  # our own, so two publishers in one process never mix
        self._server = foxglove.start_server(name=self.options.name, host=self.options.host,
                                             port=self.options.port, context=self._context,
                                             message_backlog_size=self.options.backlog,
                                             server_listener=_Listener(self))
        self._cameras: dict[str | None, _Camera] = {}
        self._events = foxglove.Channel("/recorder/events", message_encoding="json", context=self._context)
        self._lock = threading.Lock()
        self.messages_sent = 0

    @property
    def viewers(self) -> int:
        """Clients subscribed to at least one channel."""
        return sum(1 for n in self._viewers.values() if n > 0)

    @property
    def port(self) -> int:
        return int(self._server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.options.host}:{self.port}"

    def add_camera(self, camera: str | None, model: RadiometricModel | None) -> CameraTopics:
        with self._lock:
            if camera not in self._cameras:
                self._cameras[camera] = _Camera(CameraTopics.of(camera), model, self._context)
            return self._cameras[camera].topics

    def publish_frame(self, camera: str | None, timestamp_ns: int, pixels: np.ndarray, frame_index: int,
                      sidecar: dict[str, Any] | bytes | None = None,
                      model: tuple[RadiometricModel, int] | None = None) -> None:
        """One frame: its image (subsampled to the configured width), its sidecar as recorded,
        boxes and labels for its targets, and its scene temperatures from the camera's model, or
        from ``model`` (the model and its version a replay takes from the session's temperature
        path for this frame)."""
        from foxglove.messages import RawImage, Timestamp

        cam = self._cameras.get(camera)
        if cam is None:
            self.add_camera(camera, None)
            cam = self._cameras[camera]
        img, k = subsample(pixels, self.options.max_width)
        img = np.ascontiguousarray(img, dtype="<u2")
        stamp = Timestamp(sec=timestamp_ns // 1_000_000_000, nsec=timestamp_ns % 1_000_000_000)
        cam.image.log(RawImage(timestamp=stamp, frame_id=cam.topics.image.rsplit("/", 1)[0].lstrip("/") or "thermal",
                               width=img.shape[1], height=img.shape[0], encoding="mono16",
                               step=img.shape[1] * 2, data=img.tobytes()), log_time=timestamp_ns)
        sent = 1
        blocks: dict[str, Any] | None = None
        if sidecar is not None:
            raw = sidecar if isinstance(sidecar, bytes) else json.dumps(sidecar, separators=(",", ":")).encode()
            cam.metadata.log(raw, log_time=timestamp_ns)
            sent += 1
            blocks = sidecar if isinstance(sidecar, dict) else _loads(raw)
        if blocks is not None:
            cam.annotations.log(_annotations(blocks.get("targets") or [], stamp, k), log_time=timestamp_ns)
            sent += 1
        if model is not None:
            temps = {**_temperatures(model[0], img, k, frame_index), "model_version": model[1]}
            cam.temperature.log(temps, log_time=timestamp_ns)
            sent += 1
        elif cam.model is not None:  # capture: the model recorded is the only one (version 0)
            cam.temperature.log({**_temperatures(cam.model, img, k, frame_index), "model_version": 0},
                                log_time=timestamp_ns)
            sent += 1
        self.messages_sent += sent

    def publish_event(self, timestamp_ns: int, event: dict[str, Any]) -> None:
        self._events.log(event, log_time=timestamp_ns)
        self.messages_sent += 1

    def close(self) -> None:
        self._server.stop()


class _Listener(ServerListener):
    """The SDK's callbacks (on its own threads): who is watching."""

    def __init__(self, owner: LivePublisher) -> None:
        self.owner = owner

    def on_subscribe(self, client: Any, channel: Any) -> None:
        v = self.owner._viewers
        v[client.id] = v.get(client.id, 0) + 1
        self.owner.subscribed.set()

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        v = self.owner._viewers
        v[client.id] = max(0, v.get(client.id, 0) - 1)


def _loads(raw: bytes) -> dict[str, Any] | None:
    try:
        doc = json.loads(raw)
    except ValueError:
        return None
    return doc if isinstance(doc, dict) else None


def _temperatures(model: RadiometricModel, img: np.ndarray, k: int, frame_index: int) -> dict[str, Any]:
    try:
        c = np.asarray(model.to_celsius(img), dtype=np.float64)
    except Exception:  # a model that cannot give temperatures (missing constants): say so, not fail
        return {"min_c": None, "max_c": None, "mean_c": None, "center_c": None, "hottest_xy": [],
                "subsample": k, "frame_index": frame_index}
    hy, hx = np.unravel_index(int(np.argmax(c)), c.shape)
    cy, cx = c.shape[0] // 2, c.shape[1] // 2
    return {"min_c": round(float(c.min()), 3), "max_c": round(float(c.max()), 3),
            "mean_c": round(float(c.mean()), 3), "center_c": round(float(c[cy, cx]), 3),
            "hottest_xy": [int(hx) * k, int(hy) * k], "subsample": k, "frame_index": frame_index}


def _annotations(targets: list[dict[str, Any]], stamp: Any, k: int) -> Any:
    from foxglove.messages import (
        Color,
        ImageAnnotations,
        Point2,
        PointsAnnotation,
        PointsAnnotationType,
        TextAnnotation,
    )

    from thermcap.recorder.icd.rosmsg import BOX_RGBA, LABEL_BACKGROUND_RGBA, LABEL_RGBA, target_marks

    def color(c: tuple[float, ...]) -> Any:
        return Color(r=c[0], g=c[1], b=c[2], a=c[3])

    marks = target_marks(targets, 1.0 / k)  # the same marks as recorded, on the subsampled picture
    boxes = [PointsAnnotation(timestamp=stamp, type=PointsAnnotationType.LineLoop,
                              points=[Point2(x=x, y=y) for x, y in m.corners], outline_color=color(BOX_RGBA),
                              thickness=2.0) for m in marks]
    labels = [TextAnnotation(timestamp=stamp, position=Point2(x=m.label_at[0], y=m.label_at[1]), text=m.label,
                             font_size=12.0, text_color=color(LABEL_RGBA),
                             background_color=color(LABEL_BACKGROUND_RGBA)) for m in marks]
    return ImageAnnotations(timestamp=stamp, points=boxes, texts=labels)
