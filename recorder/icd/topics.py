"""Message schemas and encoders for the recorded topics.

``/thermal/image`` is a standard ROS 2 ``sensor_msgs/msg/Image`` (ros2msg schema, CDR), so
Foxglove, ros2 bag and every MCAP tool open it without thermcap. We encode the CDR by hand
because the generic encoder builds a Python list of 327,680 pixels per frame: here the pixel
buffer travels as one piece, behind a 60-odd-byte prefix.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "EVENT_SCHEMA",
    "GROUND_TRUTH_SCHEMA",
    "IMAGE_SCHEMA_NAME",
    "IMAGE_SCHEMA_TEXT",
    "RADAR_CUE_SCHEMA",
    "STATS_SCHEMA",
    "TOPIC_ANNOTATIONS",
    "TOPIC_EVENTS",
    "TOPIC_GROUND_TRUTH",
    "TOPIC_IMAGE",
    "TOPIC_METADATA",
    "TOPIC_RADAR_CUE",
    "TOPIC_STATS",
    "CameraTopics",
    "camera_topics",
    "check_camera_name",
    "decode_image",
    "encode_image_prefix",
    "image_message_parts",
    "is_image_topic",
    "sum_image_topics",
]

TOPIC_IMAGE = "/thermal/image"
TOPIC_METADATA = "/thermal/metadata"
TOPIC_ANNOTATIONS = "/thermal/annotations"  # detections as foxglove_msgs/msg/ImageAnnotations
TOPIC_RADAR_CUE = "/radar/cue"
TOPIC_STATS = "/recorder/stats"
TOPIC_EVENTS = "/recorder/events"  # marks, triggers, pauses and splits while recording
TOPIC_GROUND_TRUTH = "/sim/ground_truth"

_CAMERA_NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,31}")


@dataclass(frozen=True)
class CameraTopics:
    """Where one camera's messages go. A single-camera session keeps the plain ``/thermal/image``
    and ``/thermal/metadata``; in a session of several cameras everything a camera's source
    emits lives under ``/thermal/<name>/`` (its radar cues too), so no two cameras share a topic."""

    name: str | None
    image: str
    metadata: str
    annotations: str

    def extra(self, topic: str) -> str:
        return topic if self.name is None else f"/thermal/{self.name}{topic}"


def check_camera_name(name: str) -> str:
    if not _CAMERA_NAME.fullmatch(name):
        raise ValueError(f"camera name {name!r}: use 1-32 lower-case letters, digits, '-' or '_'")
    return name


def camera_topics(name: str | None = None) -> CameraTopics:
    if name is None:
        return CameraTopics(None, TOPIC_IMAGE, TOPIC_METADATA, TOPIC_ANNOTATIONS)
    check_camera_name(name)
    return CameraTopics(name, f"/thermal/{name}/image", f"/thermal/{name}/metadata", f"/thermal/{name}/annotations")


def is_image_topic(topic: str) -> bool:
    """``/thermal/image`` or a named camera's ``/thermal/<name>/image``."""
    if topic == TOPIC_IMAGE:
        return True
    parts = topic.split("/")
    return len(parts) == 4 and parts[1] == "thermal" and parts[3] == "image" and bool(_CAMERA_NAME.fullmatch(parts[2]))


def sum_image_topics(counts: dict[str, int]) -> int:
    """The per-topic counts (messages, drops) of every camera's image topic, added: frames."""
    return sum(n for t, n in counts.items() if is_image_topic(t))


IMAGE_SCHEMA_NAME = "sensor_msgs/msg/Image"
IMAGE_SCHEMA_TEXT = """\
std_msgs/Header header
uint32 height
uint32 width
string encoding
uint8 is_bigendian
uint32 step
uint8[] data
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""

_CDR_LE = b"\x00\x01\x00\x00"


def _cdr_string(s: str, offset: int) -> tuple[bytes, int]:
    """A CDR string at ``offset`` (already 4-aligned): length, bytes, NUL; no trailing padding."""
    raw = s.encode() + b"\x00"
    out = struct.pack("<I", len(raw)) + raw
    return out, offset + len(out)


def _pad(offset: int) -> bytes:
    return b"\x00" * ((-offset) % 4)


def encode_image_prefix(stamp_ns: int, frame_id: str, height: int, width: int,
                        encoding: str = "mono16", bytes_per_pixel: int = 2) -> bytes:
    """Everything of a CDR sensor_msgs/Image up to (and including) the pixel-array length."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    body = struct.pack("<iI", sec, nsec)
    off = 8
    s, off = _cdr_string(frame_id, off)
    body += s + _pad(off)
    off += (-off) % 4
    body += struct.pack("<II", height, width)
    off += 8
    s, off = _cdr_string(encoding, off)
    body += s
    # is_bigendian (uint8) needs no alignment; step (uint32) and the uint8[] length do.
    body += b"\x00"
    off += 1
    step = width * bytes_per_pixel
    body += _pad(off) + struct.pack("<II", step, step * height)
    return _CDR_LE + body


def image_message_parts(frame: np.ndarray, stamp_ns: int, frame_id: str = "thermal") -> list[Any]:
    """The CDR message as [prefix, pixel buffer]: joined once, inside the chunk, never copied as a list."""
    if frame.dtype != np.uint16 or frame.ndim != 2:
        raise ValueError(f"a Gray16 frame must be a 2-D uint16 array, got {frame.dtype} {frame.shape}")
    if not frame.flags.c_contiguous:
        frame = np.ascontiguousarray(frame)
    le = frame if frame.dtype.byteorder in "<=|" else frame.astype("<u2")
    h, w = frame.shape
    return [encode_image_prefix(stamp_ns, frame_id, h, w), le.data.cast("B")]


def decode_image(data: bytes | memoryview) -> tuple[int, np.ndarray]:
    """(stamp_ns, frame) from a CDR mono16 sensor_msgs/Image, without copying the pixels."""
    mv = memoryview(data)
    if bytes(mv[:2]) != b"\x00\x01":
        raise ValueError("not a little-endian CDR message")
    off = 4
    sec, nsec = struct.unpack_from("<iI", mv, off)
    off += 8
    (n,) = struct.unpack_from("<I", mv, off)
    off += 4 + n
    off += (-(off - 4)) % 4
    height, width = struct.unpack_from("<II", mv, off)
    off += 8
    (n,) = struct.unpack_from("<I", mv, off)
    encoding = bytes(mv[off + 4: off + 4 + n - 1]).decode()
    off += 4 + n
    is_bigendian = mv[off]
    off += 1
    off += (-(off - 4)) % 4
    step, size = struct.unpack_from("<II", mv, off)
    off += 8
    if encoding not in ("mono16", "16UC1"):
        raise ValueError(f"expected a mono16 image, got encoding {encoding!r}")
    if size != height * step or step != width * 2:
        raise ValueError(f"image size {size} does not match {width}x{height} mono16 (step {step})")
    dtype = ">u2" if is_bigendian else "<u2"
    frame = np.frombuffer(mv[off: off + size], dtype=dtype).reshape(height, width)
    return sec * 1_000_000_000 + nsec, frame


RADAR_CUE_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "thermcap.RadarCue",
    "description": "Radar cue message (Thermal Data ICD section 8.1)",
    "type": "object",
    "properties": {
        "timestamp": {"type": "string"},
        "target_id": {"type": "string"},
        "latitude": {"type": "number"},
        "longitude": {"type": "number"},
        "altitude_m": {"type": "number"},
        "azimuth_deg": {"type": "number"},
        "elevation_deg": {"type": "number"},
        "range_m": {"type": "number"},
        "uncertainty_m": {"type": "number"},
    },
    "required": ["timestamp", "target_id", "azimuth_deg", "elevation_deg", "range_m"],
}

EVENT_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "thermcap.RecorderEvent",
    "description": "Something that happened while recording: a mark, a trigger (and the window it protects), "
                   "a pause or resume, a split",
    "type": "object",
    "properties": {
        "kind": {"type": "string", "enum": ["mark", "trigger", "pause", "resume", "split"]},
        "reason": {"type": "string"},
        "note": {"type": "string"},
        "at_ns": {"type": "integer"},
        "protect_start_ns": {"type": ["integer", "null"]},
        "protect_end_ns": {"type": ["integer", "null"]},
        "frames_paused": {"type": ["integer", "null"]},
    },
    "required": ["kind", "at_ns"],
}

STATS_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "thermcap.RecorderStats",
    "description": "Recorder health, about once a second: counts are cumulative for the session",
    "type": "object",
    "properties": {
        "frames_captured": {"type": "integer"},
        "frames_written": {"type": "integer"},
        "dropped": {"type": "object", "additionalProperties": {"type": "integer"}},
        "queue_depth": {"type": "integer"},
        "queue_capacity": {"type": "integer"},
        "write_latency_ms": {"type": "object"},
        "analysis_skipped": {"type": "integer"},
        "timing": {
            "type": "object",
            "description": "time_basis: 'capture' (the clock when each frame was taken) or 'stream' (its "
                           "position in the input at the declared rate); achieved_fps and frames_late say "
                           "whether the source kept its declared rate",
            "properties": {"time_basis": {"type": "string"}, "declared_fps": {"type": "number"},
                           "achieved_fps": {"type": ["number", "null"]}, "frames_late": {"type": "integer"}},
        },
        "segment": {"type": "integer"},
    },
    "required": ["frames_captured", "frames_written", "dropped", "queue_depth", "write_latency_ms"],
}

GROUND_TRUTH_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "thermcap.SimGroundTruth",
    "description": "The simulator's true targets for a frame, kept apart from what any detector says",
    "type": "object",
    "properties": {
        "frame_index": {"type": "integer"},
        "targets": {"type": "array"},
        "crossover_factor": {"type": "number"},
        "slew_state": {"type": "string"},
    },
    "required": ["frame_index", "targets"],
}
