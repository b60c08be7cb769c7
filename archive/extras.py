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
from typing import Any, cast

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from thermcap.archive.manifest_types import ExtrasEntry
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.icd.topics import TOPIC_IMAGE
from thermcap.recorder.storage.digest import DEFAULT_DIGEST, bytes_digest
from thermcap.recorder.storage.layout import EXTRAS_MCAP, PARTIAL_SUFFIX
from thermcap.recorder.storage.reader import session_segments

__all__ = ["EXTRAS_NAME", "ExtrasWriter", "extras_from", "summarize_mcap", "write_extras"]

EXTRAS_NAME = EXTRAS_MCAP


def _extra_records(path: Path, messages: bool = True) -> Iterator[tuple[str, Any]]:
    """Everything of one MCAP but its image messages: ("message", (schema, channel, msg)),
    ("attachment", attachment), ("metadata", record); one place for what "extras" means.
    ``messages=False``: only the attachments and metadata records, which the summary indexes
    (no chunk is decompressed)."""
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        try:
            if messages:
                for schema, channel, msg in reader.iter_messages():
                    if channel.topic != TOPIC_IMAGE:
                        yield "message", (schema, channel, msg)
            for att in reader.iter_attachments():
                yield "attachment", att
            for rec in reader.iter_metadata():
                yield "metadata", rec
        except McapError as exc:  # a damaged record the extras would have to carry: not carried as good
            raise McapFileError(f"{path}: a record the archive keeps beside the frames (an attachment, metadata "
                                f"or another topic's message) is damaged ({type(exc).__name__}: {exc or 'cut short'}); "
                                f"the archive stops rather than leave it behind unsaid, and nothing was archived or "
                                f"deleted (the frames themselves: `thermcap info`)") from None


class _Summary:
    """Message counts and a digest per topic, attachments by sha256, metadata records: what the
    extras must carry over, and what their check compares."""

    def __init__(self) -> None:
        self.topics: dict[str, Any] = {}
        self.attachments: list[dict[str, Any]] = []
        self.metadata: list[dict[str, Any]] = []

    def add(self, kind: str, rec: Any) -> None:
        if kind == "message":
            _, channel, msg = rec
            t = self.topics.setdefault(channel.topic, {"messages": 0, "digest": hashlib.sha256()})
            t["messages"] += 1
            t["digest"].update(msg.log_time.to_bytes(8, "little") + msg.data)
        elif kind == "attachment":
            self.attachments.append({"name": rec.name, "bytes": len(rec.data),
                                     "sha256": hashlib.sha256(rec.data).hexdigest()})
        else:
            self.metadata.append({"name": rec.name, "metadata": dict(rec.metadata)})

    def to_dict(self) -> dict[str, Any]:
        return {"topics": {k: {"messages": v["messages"], "sha256": v["digest"].hexdigest()}
                           for k, v in self.topics.items()},
                "attachments": self.attachments, "metadata": self.metadata}


def summarize_mcap(paths: list[Path]) -> dict[str, Any]:
    """What ``extras.mcap`` must carry over from ``paths`` and what its check compares."""
    summary = _Summary()
    for path in paths:
        for kind, rec in _extra_records(path):
            summary.add(kind, rec)
    return summary.to_dict()


class ExtrasWriter:
    """``extras.mcap`` written as the source is read: the archiver hands it every message but the
    images from its one read of the segments (``add_message``), and ``finish`` adds the
    attachments and metadata records (from the summaries), re-reads the file and compares it
    with what it was given before it takes its name (``.partial`` until then)."""

    def __init__(self, archive_folder: Path, digest: str = DEFAULT_DIGEST) -> None:
        self.digest = digest  # the file's, as the manifest records it (recorder.storage.digest)
        self.final = archive_folder / EXTRAS_NAME
        self.partial = archive_folder / (EXTRAS_NAME + PARTIAL_SUFFIX)
        self.expected = _Summary()
        self._out = open(self.partial, "wb")  # noqa: SIM115 - closed in finish() or abort()
        self._writer = Writer(self._out, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="thermcap-archive")
        self._channels: dict[tuple, int] = {}
        self._schemas: dict[tuple, int] = {}
        self._seen_meta: set[tuple] = set()

    def add_message(self, schema: Any, channel: Any, msg: Any) -> None:
        if channel.topic == TOPIC_IMAGE:
            return
        self.expected.add("message", (schema, channel, msg))
        writer = self._writer
        skey = (schema.name, schema.encoding, schema.data) if schema else None
        if skey is not None and skey not in self._schemas:
            self._schemas[skey] = writer.register_schema(schema.name, schema.encoding, schema.data)
        ckey = (channel.topic, channel.message_encoding, skey)
        if ckey not in self._channels:
            self._channels[ckey] = writer.register_channel(channel.topic, channel.message_encoding,
                                                           self._schemas[skey] if skey is not None else 0,
                                                           dict(channel.metadata))
        writer.add_message(self._channels[ckey], msg.log_time, msg.data, msg.publish_time, msg.sequence)

    def _add_record(self, kind: str, rec: Any) -> None:
        self.expected.add(kind, rec)
        if kind == "attachment":
            self._writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
        elif (key := (rec.name, tuple(sorted(rec.metadata.items())))) not in self._seen_meta:
            self._seen_meta.add(key)  # identical records (if a writer repeats one) are kept once
            self._writer.add_metadata(rec.name, dict(rec.metadata))

    def abort(self) -> None:
        self._out.close()
        self.partial.unlink(missing_ok=True)

    def finish(self, segments: list[Path]) -> ExtrasEntry:
        try:
            for seg in segments:
                for kind, rec in _extra_records(seg, messages=False):
                    self._add_record(kind, rec)
            self._writer.finish()
            self._out.flush()
            os.fsync(self._out.fileno())
        except BaseException:
            self.abort()
            raise
        self._out.close()
        expected = self.expected.to_dict()
        got = summarize_mcap([self.partial])
        want_meta = {(m["name"], tuple(sorted(m["metadata"].items()))) for m in expected["metadata"]}
        got_meta = {(m["name"], tuple(sorted(m["metadata"].items()))) for m in got["metadata"]}
        verified = got["topics"] == expected["topics"] and got["attachments"] == expected["attachments"] \
            and got_meta == want_meta
        if not verified:
            self.partial.unlink()
            return {"path": EXTRAS_NAME, "verified": False,
                    "verification": "extras.mcap did not re-read identical to the source; the source was kept"}
        os.replace(self.partial, self.final)
        data = self.final.read_bytes()
        return cast(ExtrasEntry, {
            "path": EXTRAS_NAME, "bytes": len(data), self.digest: bytes_digest(data, self.digest), "verified": True,
            "topics": got["topics"], "attachments": got["attachments"],
            "verification": "every non-image message, attachment and metadata record re-read identical to the source"})


def write_extras(session_dir: Path, archive_folder: Path, digest: str = DEFAULT_DIGEST) -> ExtrasEntry:
    """``extras.mcap`` from a read of its own (``scrub --repair``, recorded by the hash of the
    entry it replaces; the archiver feeds an ``ExtrasWriter`` from the read that feeds the formats)."""
    segments = session_segments(session_dir)
    return extras_from(archive_folder, segments, segments, digest)


def extras_from(archive_folder: Path, message_files: list[Path], segments: list[Path],
                digest: str = DEFAULT_DIGEST) -> ExtrasEntry:
    """``extras.mcap`` with the non-image messages of ``message_files`` (the segments, or the
    per-segment extras a cluster's tasks made from them) and the attachments and metadata of
    ``segments``, compared with both before it takes its name."""
    extras = ExtrasWriter(archive_folder, digest)
    try:
        for path in message_files:
            for kind, rec in _extra_records(path):
                if kind == "message":
                    extras.add_message(*rec)
    except BaseException:
        extras.abort()
        raise
    return extras.finish(segments)
