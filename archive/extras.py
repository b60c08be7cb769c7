"""Everything in a session besides its pixels, kept with the archive: ``extras.mcap``.

The archive formats hold the frames (and their sidecars); a session holds more that must outlive
``--delete-source``: the importers' ``/import/source`` messages (vendor metadata, positions), the
radar cues and recorder stats, the MCAP metadata records, and the attachments, among them the DJI
and FLIR calibration blobs that vendor software needs to compute temperatures years later. All of
it goes into one small MCAP (every channel but ``/thermal/image``), re-read and compared with the
source before it counts.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from archive.manifest_types import ExtrasEntry
from recorder.icd.topics import TOPIC_IMAGE
from recorder.storage.layout import EXTRAS_MCAP, PARTIAL_SUFFIX
from recorder.storage.reader import session_segments

__all__ = ["EXTRAS_NAME", "summarize_mcap", "write_extras"]

EXTRAS_NAME = EXTRAS_MCAP


def _extra_records(path: Path) -> Iterator[tuple[str, Any]]:
    """Everything of one MCAP but its image messages: ("message", (schema, channel, msg)),
    ("attachment", attachment), ("metadata", record); one place for what "extras" means."""
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, msg in reader.iter_messages():
            if channel.topic != TOPIC_IMAGE:
                yield "message", (schema, channel, msg)
        for att in reader.iter_attachments():
            yield "attachment", att
        for rec in reader.iter_metadata():
            yield "metadata", rec


def summarize_mcap(paths: list[Path]) -> dict[str, Any]:
    """Message counts and a digest per topic, attachments by sha256, metadata records: what
    ``write_extras`` must carry over and what its check compares."""
    topics: dict[str, Any] = {}
    attachments, metadata = [], []
    for path in paths:
        for kind, rec in _extra_records(path):
            if kind == "message":
                _, channel, msg = rec
                t = topics.setdefault(channel.topic, {"messages": 0, "digest": hashlib.sha256()})
                t["messages"] += 1
                t["digest"].update(msg.log_time.to_bytes(8, "little") + msg.data)
            elif kind == "attachment":
                digest = hashlib.sha256(rec.data).hexdigest()
                attachments.append({"name": rec.name, "bytes": len(rec.data), "sha256": digest})
            else:
                metadata.append({"name": rec.name, "metadata": dict(rec.metadata)})
    return {"topics": {k: {"messages": v["messages"], "sha256": v["digest"].hexdigest()} for k, v in topics.items()},
            "attachments": attachments, "metadata": metadata}


def write_extras(session_dir: Path, archive_folder: Path) -> ExtrasEntry:
    """Write ``extras.mcap`` beside the formats (``.partial`` first, renamed once it re-reads
    identical to the source); returns its manifest entry."""
    segments = session_segments(session_dir)
    final = archive_folder / EXTRAS_NAME
    partial = archive_folder / (EXTRAS_NAME + PARTIAL_SUFFIX)
    expected = summarize_mcap(segments)
    channels: dict[tuple, int] = {}
    schemas: dict[tuple, int] = {}
    seen_meta: set[tuple] = set()
    with open(partial, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        writer.start(profile="", library="thermcap-archive")
        for seg in segments:
            for kind, rec in _extra_records(seg):
                if kind == "message":
                    schema, channel, msg = rec
                    skey = (schema.name, schema.encoding, schema.data) if schema else None
                    if skey is not None and skey not in schemas:
                        schemas[skey] = writer.register_schema(schema.name, schema.encoding, schema.data)
                    ckey = (channel.topic, channel.message_encoding, skey)
                    if ckey not in channels:
                        channels[ckey] = writer.register_channel(channel.topic, channel.message_encoding,
                                                                 schemas[skey] if skey is not None else 0,
                                                                 dict(channel.metadata))
                    writer.add_message(channels[ckey], msg.log_time, msg.data, msg.publish_time, msg.sequence)
                elif kind == "attachment":
                    writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
                elif (key := (rec.name, tuple(sorted(rec.metadata.items())))) not in seen_meta:
                    seen_meta.add(key)  # identical records (if a writer repeats one) are kept once
                    writer.add_metadata(rec.name, dict(rec.metadata))
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
    got = summarize_mcap([partial])
    want_meta = {(m["name"], tuple(sorted(m["metadata"].items()))) for m in expected["metadata"]}
    got_meta = {(m["name"], tuple(sorted(m["metadata"].items()))) for m in got["metadata"]}
    verified = got["topics"] == expected["topics"] and got["attachments"] == expected["attachments"] \
        and got_meta == want_meta
    if not verified:
        partial.unlink()
        return {"path": EXTRAS_NAME, "verified": False,
                "verification": "extras.mcap did not re-read identical to the source; the source was kept"}
    os.replace(partial, final)
    data = final.read_bytes()
    return {"path": EXTRAS_NAME, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest(), "verified": True,
            "topics": got["topics"], "attachments": got["attachments"],
            "verification": "every non-image message, attachment and metadata record re-read identical to the source"}
