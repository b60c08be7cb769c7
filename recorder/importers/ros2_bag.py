"""ROS 2 bags (rosbag2's MCAP storage): a thermal camera's ``sensor_msgs/msg/Image`` topic as
frames, with the bag's own times.

Most vehicle stacks already run a camera driver and record with ``ros2 bag record``. A bag's
MCAP file holds CDR messages; ``mono16`` (and ``16UC1``) images are the counts, little- or
big-endian as ``is_bigendian`` says, rows ``step`` bytes apart: they are taken exactly, padding
dropped. Each frame keeps its header stamp as its capture time (the camera driver's clock) and,
in its vendor metadata, the bag's log and publish times, the header's ``frame_id``, the image's
encoding, and the ``sensor_msgs/msg/CameraInfo`` published beside it (``.../camera_info``,
the last one before the frame). The bag's ``metadata.yaml``, when it lies beside the file, is
kept bit-exact as an attachment of the first frame.

A bag carries no radiometric model: the frames get the ICD's linear model, and the vendor
metadata says it was assumed (``thermcap radiometry`` sets the camera's own). A bag with more
than one 16-bit image topic is refused, naming them: importing them into one session would mix
cameras.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.importers.base import ImportedFrame, ImportFileError
from thermcap.recorder.radiometry import DEFAULT_MODEL

__all__ = ["MCAP_MAGIC", "SQLITE_MAGIC", "is_ros2_bag", "is_ros2_bag_folder", "is_ros2_db3", "iter_ros2_bag",
           "iter_ros2_db3"]

MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
_IMAGE = "sensor_msgs/msg/Image"
_INFO = "sensor_msgs/msg/CameraInfo"
_SIXTEEN = ("mono16", "16UC1")


def is_ros2_bag(path: str) -> bool:
    """An MCAP file whose image topics are ROS 2 ``sensor_msgs/msg/Image`` (a thermcap session's
    segment is one too, but is imported as a session already: ``thermcap import`` of a segment
    is for bags)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:
        return False
    if summary is None:
        return False
    return any(s.name == _IMAGE for s in summary.schemas.values())


def iter_ros2_bag(path: str) -> Iterator[ImportedFrame]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    try:
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
            summary = reader.get_summary()
            if summary is None:
                raise ImportFileError(f"{path}: an MCAP file without a summary (unfinished; `thermcap recover` "
                                      "finishes a segment, `ros2 bag reindex` a bag)")
            images = {c.topic for c in summary.channels.values()
                      if (sc := summary.schemas.get(c.schema_id)) is not None and sc.name == _IMAGE}
            if not images:
                raise ImportFileError(f"{path}: a bag with no {_IMAGE} topic")
            messages = ((channel.topic, int(message.log_time), int(message.publish_time), decoded)
                        for _schema, channel, message, decoded in reader.iter_decoded_messages(
                            topics=[*images, *{_info_topic(t) for t in images}], log_time_order=True))
            yield from _frames(path, images, messages)
    except ImportFileError:
        raise
    except OSError as exc:
        raise ImportFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except Exception as exc:  # a damaged bag may trip mcap or the CDR decoder anywhere: named, never a traceback
        raise ImportFileError(f"{path}: corrupt ROS 2 bag ({type(exc).__name__}: {exc})") from None


def _frames(path: str, images: set[str],
            messages: Iterator[tuple[str, int, int | None, Any]]) -> Iterator[ImportedFrame]:
    """Frames from a bag's decoded (topic, log time, publish time, message), in log-time order,
    whichever storage they came from."""
    blobs = _bag_metadata(path)
    chosen: str | None = None
    info: dict[str, Any] | None = None
    index = 0
    for topic, log_time, publish_time, decoded in messages:
        if topic not in images:
            info = _camera_info(decoded)
            continue
        encoding = str(decoded.encoding)
        if encoding not in _SIXTEEN:
            continue  # a colour or 8-bit view of the scene: not counts
        if chosen is None:
            chosen = topic
        elif topic != chosen:
            raise ImportFileError(f"{path}: 16-bit images on more than one topic ({chosen}, {topic}); "
                                  "one camera a session: split the bag (`ros2 bag convert`) first")
        pixels = _pixels(path, decoded, index)
        stamp = int(decoded.header.stamp.sec) * 1_000_000_000 + int(decoded.header.stamp.nanosec)
        yield ImportedFrame(
            path=path, format="ros2-bag", layout=encoding, pixels=pixels, model=DEFAULT_MODEL,
            timestamp_ns=stamp or log_time, sensor_model=f"ROS 2 {topic}", sensor_id=_sensor_id(topic),
            vendor_metadata={"topic": topic, "log_time_ns": log_time,
                             **({"publish_time_ns": publish_time} if publish_time is not None else {}),
                             "header": {"frame_id": str(decoded.header.frame_id), "stamp_ns": stamp},
                             "encoding": encoding, "is_bigendian": bool(decoded.is_bigendian),
                             "camera_info": info,
                             "radiometric_model": "assumed (the ICD's linear model): a bag carries none; "
                                                  "`thermcap radiometry` sets the camera's own"},
            blobs=blobs if index == 0 else {}, frame_index=index, model_assumed=True)
        index += 1
    if chosen is None:
        raise ImportFileError(f"{path}: no 16-bit image (mono16 or 16UC1) on {', '.join(sorted(images))}")


def is_ros2_bag_folder(folder: Path) -> bool:
    """rosbag2's own folder: ``metadata.yaml`` naming the bag, beside its .mcap or .db3 files."""
    try:
        head = (folder / "metadata.yaml").read_text(errors="replace")[:200]
    except OSError:
        return False
    return "rosbag2_bagfile_information" in head


def is_ros2_db3(path: str) -> bool:
    """A rosbag2 sqlite3 storage file (``*.db3``): SQLite with rosbag2's ``messages`` table."""
    try:
        with open(path, "rb") as f:
            if f.read(16) != SQLITE_MAGIC:
                return False
    except OSError:
        return False
    return Path(path).suffix.lower() == ".db3"


def iter_ros2_db3(path: str) -> Iterator[ImportedFrame]:
    """A rosbag2 bag in sqlite3 storage (the default before Iron), read by rosbags, which knows
    the standard message definitions: its folder (with ``metadata.yaml``) is the bag, read
    whole from its first file; a split bag's later files are read with the first."""
    try:
        from rosbags.rosbag2 import Reader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        from thermcap.recorder.install_hint import install_command

        raise ImportFileError(f"{path}: a ROS 2 bag in sqlite3 storage is read with rosbags: "
                              f"{install_command('ros2')}") from None
    bag = Path(path).parent
    if not (bag / "metadata.yaml").is_file():
        raise ImportFileError(f"{path}: a .db3 without the bag's metadata.yaml beside it (`ros2 bag reindex "
                              f"{bag}` writes it)")
    try:
        typestore = get_typestore(Stores.ROS2_HUMBLE)
        first = sorted(p.name for p in bag.glob("*.db3"))[0]
        if Path(path).name != first:
            return  # a split bag's later file: read with the first, as one bag
        with Reader(bag) as reader:
            images = {c.topic for c in reader.connections if c.msgtype == _IMAGE}
            if not images:
                raise ImportFileError(f"{path}: a bag with no {_IMAGE} topic")
            wanted = [c for c in reader.connections
                      if c.topic in images or (c.msgtype == _INFO and c.topic in {_info_topic(t) for t in images})]
            messages = ((conn.topic, int(log_time), None, typestore.deserialize_cdr(raw, conn.msgtype))
                        for conn, log_time, raw in reader.messages(connections=wanted))
            yield from _frames(path, images, messages)
    except ImportFileError:
        raise
    except Exception as exc:  # a damaged bag may trip sqlite, rosbags or the CDR decoder: named
        raise ImportFileError(f"{path}: corrupt ROS 2 bag ({type(exc).__name__}: {exc})") from None


def _pixels(path: str, msg: Any, index: int) -> np.ndarray:
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = bytes(msg.data)
    if h <= 0 or w <= 0 or step < 2 * w or len(data) < step * h:
        raise ImportFileError(f"{path}: image {index} is {w}x{h} with rows of {step} bytes, but holds "
                              f"{len(data)} bytes")
    rows = np.frombuffer(data, np.uint8, step * h).reshape(h, step)[:, :2 * w]
    return np.ascontiguousarray(rows).view(">u2" if msg.is_bigendian else "<u2").astype(np.uint16)


def _info_topic(image_topic: str) -> str:
    return image_topic.rsplit("/", 1)[0] + "/camera_info"


def _camera_info(msg: Any) -> dict[str, Any]:
    return {"width": int(msg.width), "height": int(msg.height), "distortion_model": str(msg.distortion_model),
            "d": [float(v) for v in msg.d], "k": [float(v) for v in msg.k], "r": [float(v) for v in msg.r],
            "p": [float(v) for v in msg.p], "frame_id": str(msg.header.frame_id)}


def _sensor_id(topic: str) -> str:
    name = "".join(c if c.isalnum() else "_" for c in topic.strip("/").split("/")[0]).upper()
    return (name or "ROS2")[:32]


def _bag_metadata(path: str) -> dict[str, bytes]:
    meta = Path(path).with_name("metadata.yaml")
    try:
        return {"metadata.yaml": meta.read_bytes()} if meta.is_file() else {}
    except OSError:
        return {}
