"""Checks that an MCAP segment agrees with itself before anything is archived from it.

A flipped bit in a finished segment's Channel record can rename ``/thermal/metadata``; the
images still read, their sidecars silently do not. These checks compare the channel table
with the schemas it points to, and the summary's counts with the message indexes, so such a
segment is refused instead of being proved good.
"""

from __future__ import annotations

import io
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel

from thermcap.recorder.icd.topics import IMAGE_SCHEMA_NAME, TOPIC_IMAGE, TOPIC_METADATA
from thermcap.recorder.storage.recover import scan_records

__all__ = ["SIDECAR_SCHEMA_NAME", "channel_problems"]

SIDECAR_SCHEMA_NAME = "thermcap_msgs/msg/ThermalSidecar"
# the sidecar's schema since recordings are ROS 2 messages, and the JSON schema before
_EXPECTED = {IMAGE_SCHEMA_NAME: TOPIC_IMAGE, SIDECAR_SCHEMA_NAME: TOPIC_METADATA,
             "thermcap.ThermalSidecar": TOPIC_METADATA}


def channel_problems(path: Path) -> list[str]:
    """What is wrong with a segment's channel table and summary counts (empty when nothing)."""
    problems: list[str] = []
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception as exc:  # a damaged summary section may fail anywhere inside the reader
        return [f"unreadable summary ({type(exc).__name__}: {exc})"]
    if summary is None or summary.statistics is None:
        return ["no summary (not a finished segment)"]
    topics = {c.topic for c in summary.channels.values()}
    for ch in summary.channels.values():
        schema = summary.schemas.get(ch.schema_id)
        want = _EXPECTED.get(schema.name) if schema else None
        if schema is not None and want is not None and ch.topic != want:
            problems.append(f"channel {ch.id} has schema {schema.name} but topic {ch.topic!r} (expected {want!r})")
    if TOPIC_IMAGE in topics and TOPIC_METADATA not in topics:
        problems.append(f"has {TOPIC_IMAGE} but no {TOPIC_METADATA} channel")
    counted = summary.statistics.channel_message_counts
    unknown = sorted(set(counted) - set(summary.channels))
    if unknown:
        problems.append(f"the summary counts messages on channels {unknown} that the file does not define")
    for cid, head in _leading_channels(path).items():
        tail = summary.channels.get(cid)
        if tail is None or (tail.topic, tail.schema_id, tail.message_encoding) != \
                (head.topic, head.schema_id, head.message_encoding):
            problems.append(f"channel {cid} is {head.topic!r} at the start of the file but "
                            f"{tail.topic if tail else 'missing'!r} in its summary")
    if sum(counted.values()) != summary.statistics.message_count:
        problems.append(f"the summary's per-channel counts add up to {sum(counted.values())}, "
                        f"its total says {summary.statistics.message_count}")
    return problems


def _leading_channels(path: Path) -> dict[int, Channel]:
    """The Channel records written before the first chunk (where thermcap writes them, so a cut
    file keeps them); the summary repeats them, and the two must agree."""
    out: dict[int, Channel] = {}
    size = path.stat().st_size
    try:
        with open(path, "rb") as f:
            for _, opcode, body in scan_records(f, size, str(path)):
                if opcode in (Opcode.CHUNK, Opcode.DATA_END, Opcode.MESSAGE):
                    break
                if opcode == Opcode.CHANNEL:
                    ch = Channel.read(ReadDataStream(io.BytesIO(body)))
                    out[ch.id] = ch
    except Exception:  # a damaged head shows up as a disagreement with the summary below
        return out
    return out
