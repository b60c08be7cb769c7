"""ROS 2 messages for every topic we record besides the image, so rosbags, ros2 bag and Foxglove
all decode them, with their fields visible in Foxglove's Plot and Raw Messages panels.

Each thermcap message starts with ``string json``: the document exactly as recorded (for the
sidecar, the ICD JSON the archive keeps and hashes). The typed fields after it are a view for
plotting: floats are NaN where the document has null. Because ``json`` is the first field, any
reader takes the document back from the CDR bytes without a full decode (``json_payload``).
Recordings made before these messages (JSON channels with a JSON schema) read the same way.

Detections are also published as ``foxglove_msgs/msg/ImageAnnotations``, which Foxglove's Image
panel draws over the thermal image with no plugin.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

from thermcap.recorder.icd.cdr import library_encoder, pad, phase_layouts, write_string
from thermcap.recorder.icd.topics import sum_image_topics

__all__ = [
    "ANNOTATIONS",
    "JSON_DOCUMENT",
    "SIDECAR",
    "RosMessage",
    "TargetMark",
    "annotations_doc",
    "annotations_message",
    "json_payload",
    "message_for_topic",
    "target_marks",
]

_SEP = "=" * 80


@dataclass(frozen=True)
class RosMessage:
    """A ros2msg definition (dependencies included, as MCAP's ros2 profile embeds them) and how
    a recorded JSON document becomes its fields."""

    name: str
    text: str
    fields: Callable[[dict[str, Any]], dict[str, Any]]
    #: the same bytes laid out by hand, for a message written with every frame (the sidecar)
    layout: Callable[[dict[str, Any], bytes], bytes] | None = None

    def encode(self, doc: dict[str, Any], raw: bytes | None = None) -> bytes:
        """CDR bytes of ``doc``; ``raw`` is its JSON as recorded (kept byte for byte)."""
        data = raw if raw is not None else json.dumps(doc, separators=(",", ":")).encode()
        if self.layout is not None:
            return self.layout(doc, data)
        return library_encoder(self.name, self.text)({"json": data.decode(), **self.fields(doc)})


def _f(v: Any) -> float:
    if v.__class__ is float:  # most values, on the path of every frame
        return v
    if v is None:  # the ICD's null, the commonest non-number: no exception to raise and catch
        return math.nan
    try:
        x = float(v)
    except (TypeError, ValueError):
        return math.nan
    return x


def _s(v: Any) -> str:
    return "" if v is None else str(v)


def _b(v: Any) -> bool:
    return bool(v)


def _sidecar_fields(doc: dict[str, Any]) -> dict[str, Any]:
    cap, env = doc.get("capture") or {}, doc.get("environment") or {}
    ta, stc = doc.get("thermal_analysis") or {}, doc.get("slew_to_cue") or {}
    targets = doc.get("targets") or []
    return {
        "frame_index": int(cap.get("frame_index") or 0), "timestamp": _s(cap.get("timestamp")),
        "ambient_temp_c": _f(env.get("ambient_temp_c")), "humidity_percent": _f(env.get("humidity_percent")),
        "atmospheric_transmission": _f(env.get("atmospheric_transmission")),
        "thermal_contrast_grade": _f(ta.get("thermal_contrast_grade")),
        "max_target_temp_c": _f(ta.get("max_target_temp_c")),
        "min_background_temp_c": _f(ta.get("min_background_temp_c")), "delta_t_deg_c": _f(ta.get("delta_t_deg_c")),
        "snr_db": _f(ta.get("snr_db")), "detection_confidence": _f(ta.get("detection_confidence")),
        "analysis_source": _s(ta.get("source")), "target_count": len(targets),
        "targets": [{"target_id": _s(t.get("target_id")), "bbox": [int(v) for v in t.get("bbox") or []],
                     "centroid": [_f(v) for v in t.get("centroid") or []], "max_temp_c": _f(t.get("max_temp_c")),
                     "mean_temp_c": _f(t.get("mean_temp_c")), "classification": _s(t.get("classification")),
                     "confidence": _f(t.get("confidence"))} for t in targets],
        "slew_to_cue_active": _b(stc.get("slew_to_cue_active")),
        "radar_cue_received": _b(stc.get("radar_cue_received")),
        "slew_state": _s(stc.get("state")), "radar_azimuth_deg": _f(stc.get("radar_azimuth_deg")),
        "radar_elevation_deg": _f(stc.get("radar_elevation_deg")), "radar_range_m": _f(stc.get("radar_range_m")),
        "turret_pan_deg": _f(stc.get("turret_pan_deg")), "turret_tilt_deg": _f(stc.get("turret_tilt_deg")),
    }


_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_F9 = struct.Struct("<9d")
_F5 = struct.Struct("<5d")
_F2 = struct.Struct("<2d")
_F1 = struct.Struct("<d")
_TWO_U32 = struct.Struct("<2I")
_TWO_BOOLS = struct.Struct("<2B")
#: a Target's bbox (length, 4 int32), centroid (length, 2 float64), max_temp_c and mean_temp_c
_BOX_TARGET = phase_layouts(["I", "i", "i", "i", "i", "I", "d", "d", "d", "d"])


def _sidecar_layout(doc: dict[str, Any], raw: bytes) -> bytes:
    """``ThermalSidecar`` laid out by hand: mcap_ros2's bytes for ``_sidecar_fields(doc)``,
    whose values it packs, tested on every shape of document.

    Why by hand: the recorder writes one with every frame, on its writer thread; a generic
    encoder's machinery (a lookup and a coercion per field) is what ``thermcap bench cdr``
    weighs this against. A target with the usual four-number box and two-number centroid is one
    pack."""
    raw.decode("utf-8")  # the library takes text: bytes that are not UTF-8 fail here as they would there
    f = _sidecar_fields(doc)
    out = bytearray(b"\x00\x01\x00\x00")  # CDR_LE; alignment counts from after these four bytes
    out += _U32.pack(len(raw) + 1)  # json: at offset 0, aligned
    out += raw
    out += b"\0"
    pad(out, 8)
    out += _U64.pack(f["frame_index"])
    write_string(out, f["timestamp"])
    pad(out, 8)
    out += _F9.pack(f["ambient_temp_c"], f["humidity_percent"], f["atmospheric_transmission"],
                    f["thermal_contrast_grade"], f["max_target_temp_c"], f["min_background_temp_c"],
                    f["delta_t_deg_c"], f["snr_db"], f["detection_confidence"])
    write_string(out, f["analysis_source"])
    pad(out, 4)
    out += _TWO_U32.pack(f["target_count"], len(f["targets"]))  # then the sequence's length
    for t in f["targets"]:
        write_string(out, t["target_id"])
        bbox, centroid = t["bbox"], t["centroid"]
        pad(out, 4)
        if len(bbox) == 4 and len(centroid) == 2:  # every detector's target: one pack
            out += _BOX_TARGET[(len(out) - 4) % 8].pack(4, *bbox, 2, *centroid, t["max_temp_c"], t["mean_temp_c"])
        else:
            out += struct.pack(f"<I{len(bbox)}i", len(bbox), *bbox)
            out += _U32.pack(len(centroid))
            pad(out, 8)  # the centroid's doubles, or else max_temp_c's
            out += struct.pack(f"<{len(centroid)}d", *centroid)
            out += _F2.pack(t["max_temp_c"], t["mean_temp_c"])
        write_string(out, t["classification"])
        pad(out, 8)
        out += _F1.pack(t["confidence"])
    out += _TWO_BOOLS.pack(f["slew_to_cue_active"], f["radar_cue_received"])
    write_string(out, f["slew_state"])
    pad(out, 8)
    out += _F5.pack(f["radar_azimuth_deg"], f["radar_elevation_deg"], f["radar_range_m"], f["turret_pan_deg"],
                    f["turret_tilt_deg"])
    return bytes(out)


SIDECAR = RosMessage("thermcap_msgs/msg/ThermalSidecar", f"""\
# The ICD sidecar of one frame. json: exactly as recorded (the archive keeps and hashes it);
# the other fields are its numbers for plotting, NaN where the ICD has null.
string json
uint64 frame_index
string timestamp
float64 ambient_temp_c
float64 humidity_percent
float64 atmospheric_transmission
float64 thermal_contrast_grade
float64 max_target_temp_c
float64 min_background_temp_c
float64 delta_t_deg_c
float64 snr_db
float64 detection_confidence
string analysis_source
uint32 target_count
thermcap_msgs/Target[] targets
bool slew_to_cue_active
bool radar_cue_received
string slew_state
float64 radar_azimuth_deg
float64 radar_elevation_deg
float64 radar_range_m
float64 turret_pan_deg
float64 turret_tilt_deg
{_SEP}
MSG: thermcap_msgs/Target
string target_id
int32[] bbox
float64[] centroid
float64 max_temp_c
float64 mean_temp_c
string classification
float64 confidence
""", _sidecar_fields, _sidecar_layout)


def _stats_fields(d: dict[str, Any]) -> dict[str, Any]:
    lat = ((d.get("write_latency_ms") or {}).get("interval") or {})
    timing = d.get("timing") or {}
    dropped = d.get("dropped") or {}
    return {"frames_captured": int(d.get("frames_captured") or 0), "frames_written": int(d.get("frames_written") or 0),
            "frames_dropped": sum_image_topics(dropped),
            "frames_paused": int(d.get("frames_paused") or 0), "queue_depth": int(d.get("queue_depth") or 0),
            "queue_capacity": int(d.get("queue_capacity") or 0), "write_latency_p50_ms": _f(lat.get("p50")),
            "write_latency_p99_ms": _f(lat.get("p99")), "analysis_skipped": int(d.get("analysis_skipped") or 0),
            "achieved_fps": _f(timing.get("achieved_fps")), "segment": int(d.get("segment") or 0)}


STATS = RosMessage("thermcap_msgs/msg/RecorderStats", """\
# Recorder health about once a second (counts cumulative for the session); json has it all.
string json
uint64 frames_captured
uint64 frames_written
uint64 frames_dropped
uint64 frames_paused
uint32 queue_depth
uint32 queue_capacity
float64 write_latency_p50_ms
float64 write_latency_p99_ms
uint64 analysis_skipped
float64 achieved_fps
uint32 segment
""", _stats_fields)


def _event_fields(d: dict[str, Any]) -> dict[str, Any]:
    def ns(v: Any) -> int:
        return int(v) if isinstance(v, int) else -1

    return {"kind": _s(d.get("kind")), "reason": _s(d.get("reason")), "note": _s(d.get("note")),
            "camera": _s(d.get("camera")), "at_ns": ns(d.get("at_ns")),
            "protect_start_ns": ns(d.get("protect_start_ns")),
            "protect_end_ns": ns(d.get("protect_end_ns"))}


EVENT = RosMessage("thermcap_msgs/msg/RecorderEvent", """\
# A mark, trigger, pause, resume or split; times in ns since the Unix epoch, -1 where none.
string json
string kind
string reason
string note
string camera
int64 at_ns
int64 protect_start_ns
int64 protect_end_ns
""", _event_fields)


def _cue_fields(d: dict[str, Any]) -> dict[str, Any]:
    return {"timestamp": _s(d.get("timestamp")), "target_id": _s(d.get("target_id")),
            **{k: _f(d.get(k)) for k in ("latitude", "longitude", "altitude_m", "azimuth_deg", "elevation_deg",
                                          "range_m", "uncertainty_m")}}


RADAR_CUE = RosMessage("thermcap_msgs/msg/RadarCue", """\
# A radar cue (ICD section 8.1); NaN where the cue has no value.
string json
string timestamp
string target_id
float64 latitude
float64 longitude
float64 altitude_m
float64 azimuth_deg
float64 elevation_deg
float64 range_m
float64 uncertainty_m
""", _cue_fields)

JSON_DOCUMENT = RosMessage("thermcap_msgs/msg/JsonDocument", """\
# Any other recorded JSON document, exactly as recorded.
string json
""", lambda d: {})

_BY_TOPIC = {"/thermal/metadata": SIDECAR, "/recorder/stats": STATS, "/recorder/events": EVENT,
             "/radar/cue": RADAR_CUE}


def message_for_topic(topic: str) -> RosMessage:
    """The message of a recorded topic (a named camera's ``/thermal/<name>/...`` as the plain one)."""
    parts = topic.split("/")
    if len(parts) > 3 and parts[1] == "thermal" and parts[2] not in ("image", "metadata"):
        topic = "/" + "/".join(["thermal", *parts[3:]]) if parts[3] in ("image", "metadata") else \
            "/" + "/".join(parts[3:])
    return _BY_TOPIC.get(topic, JSON_DOCUMENT)


def json_payload(message_encoding: str, data: bytes | memoryview) -> bytes:
    """A recorded document's JSON bytes from its message: the first string of a thermcap CDR
    message, or the message itself on a JSON channel (older recordings)."""
    if message_encoding != "cdr":
        return bytes(data)
    mv = memoryview(data)
    if len(mv) < 8:
        raise ValueError("a CDR message shorter than its header")
    little = mv[1] == 1
    (n,) = struct.unpack_from("<I" if little else ">I", mv, 4)
    if n == 0 or 8 + n > len(mv):
        raise ValueError("a CDR message whose first string runs past its end")
    return bytes(mv[8:8 + n - 1])  # without the terminating NUL


ANNOTATIONS = RosMessage("foxglove_msgs/msg/ImageAnnotations", f"""\
foxglove_msgs/CircleAnnotation[] circles
foxglove_msgs/PointsAnnotation[] points
foxglove_msgs/TextAnnotation[] texts
{_SEP}
MSG: foxglove_msgs/CircleAnnotation
builtin_interfaces/Time timestamp
foxglove_msgs/Point2 position
float64 diameter
float64 thickness
foxglove_msgs/Color fill_color
foxglove_msgs/Color outline_color
{_SEP}
MSG: foxglove_msgs/PointsAnnotation
builtin_interfaces/Time timestamp
uint8 UNKNOWN=0
uint8 POINTS=1
uint8 LINE_LOOP=2
uint8 LINE_STRIP=3
uint8 LINE_LIST=4
uint8 type
foxglove_msgs/Point2[] points
foxglove_msgs/Color outline_color
foxglove_msgs/Color[] outline_colors
foxglove_msgs/Color fill_color
float64 thickness
{_SEP}
MSG: foxglove_msgs/TextAnnotation
builtin_interfaces/Time timestamp
foxglove_msgs/Point2 position
string text
float64 font_size
foxglove_msgs/Color text_color
foxglove_msgs/Color background_color
{_SEP}
MSG: foxglove_msgs/Point2
float64 x
float64 y
{_SEP}
MSG: foxglove_msgs/Color
float64 r
float64 g
float64 b
float64 a
{_SEP}
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
""", lambda d: d)


#: how a detection is drawn (RGBA): box outline, label text, label background
BOX_RGBA, LABEL_RGBA, LABEL_BACKGROUND_RGBA = (1.0, 0.2, 0.1, 1.0), (1.0, 1.0, 1.0, 1.0), (0.0, 0.0, 0.0, 0.6)


class TargetMark(NamedTuple):
    """One detected target as it is drawn: its box's corners and its label, in image pixels.
    (A named tuple: made for every target of every frame, at a fifth of a frozen dataclass's cost.)"""

    corners: tuple[tuple[float, float], ...]  # TL, TR, BR, BL
    label: str
    label_at: tuple[float, float]


def target_marks(targets: list[dict[str, Any]], scale: float = 1.0) -> list[TargetMark]:
    """A box and a "#id max °C" label per target with a box, in an image ``scale`` times the
    frame's size (a subsampled live picture)."""
    out = []
    for tg in targets:
        bbox = tg.get("bbox") or []
        if len(bbox) != 4:
            continue
        b0, b1, b2, b3 = bbox
        x0, y0 = float(b0) * scale, float(b1) * scale
        # inclusive pixel boxes: to the far edge of the last pixel
        x1, y1 = float(b2) * scale + scale, float(b3) * scale + scale
        out.append(TargetMark(((x0, y0), (x1, y0), (x1, y1), (x0, y1)),
                              f"#{tg.get('target_id')} {tg.get('max_temp_c')} °C", (x0, max(0.0, y0 - 2))))
    return out


#: One PointsAnnotation as ``annotations_message`` writes it (a LINE_LOOP of four corners, no
#: per-point colours): it starts 8-aligned and is 160 bytes long, so every one has this layout.
_BOX = struct.Struct("<iIB3xI8d4dI4x4dd")
#: a TextAnnotation's timestamp and position, and its font size and two colours
_TEXT_AT = phase_layouts(["i", "I", "d", "d"])
_TEXT_STYLE = phase_layouts(["d"] * 9)
_NO_COLOUR = (0.0, 0.0, 0.0, 0.0)
_LINE_LOOP, _THICKNESS, _FONT_SIZE = 2, 2.0, 12.0


def annotations_message(stamp_ns: int, targets: list[dict[str, Any]]) -> bytes:
    """The targets' marks as CDR ``foxglove_msgs/msg/ImageAnnotations``, for Foxglove's Image panel.

    Laid out by hand, not by the library's encoder the low-rate messages use: it is written with
    every frame and its shape is fixed but for the labels (``thermcap bench cdr`` weighs it
    against mcap_ros2 and rosbags). The bytes are mcap_ros2's for ``annotations_doc``: tested on
    random targets and labels of every length.
    """
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    marks = target_marks(targets)
    out = bytearray(b"\x00\x01\x00\x00")  # CDR_LE; alignment counts from after these four bytes
    out += _U32.pack(0)  # circles
    out += _U32.pack(len(marks))
    for m in marks:
        (x0, y0), (x1, y1), (x2, y2), (x3, y3) = m.corners
        out += _BOX.pack(sec, nsec, _LINE_LOOP, 4, x0, y0, x1, y1, x2, y2, x3, y3, *BOX_RGBA, 0, *_NO_COLOUR,
                          _THICKNESS)
    out += _U32.pack(len(marks))
    for m in marks:
        out += _TEXT_AT[(len(out) - 4) % 8].pack(sec, nsec, *m.label_at)
        write_string(out, m.label)
        out += _TEXT_STYLE[(len(out) - 4) % 8].pack(_FONT_SIZE, *LABEL_RGBA, *LABEL_BACKGROUND_RGBA)
    return bytes(out)


def annotations_doc(stamp_ns: int, targets: list[dict[str, Any]]) -> dict[str, Any]:
    """The fields of ``annotations_message``."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    t = {"sec": sec, "nanosec": nsec}

    def rgba(c: tuple[float, ...]) -> dict[str, float]:
        return dict(zip("rgba", c, strict=True))

    none = rgba(_NO_COLOUR)
    marks = target_marks(targets)
    points = [{"timestamp": t, "type": _LINE_LOOP, "points": [{"x": x, "y": y} for x, y in m.corners],
               "outline_color": rgba(BOX_RGBA), "outline_colors": [], "fill_color": none, "thickness": _THICKNESS}
              for m in marks]
    texts = [{"timestamp": t, "position": {"x": m.label_at[0], "y": m.label_at[1]}, "text": m.label,
              "font_size": _FONT_SIZE, "text_color": rgba(LABEL_RGBA), "background_color": rgba(LABEL_BACKGROUND_RGBA)}
             for m in marks]
    return {"circles": [], "points": points, "texts": texts}
