"""Getting one frame (counts and sidecar) back, from wherever a served session keeps it.

This module lists the copies the server can reach (stored-ZIP entries and other formats by
ranged reads through the blob store, local or S3; the MCAP source on local disk, by the chunk
holding the frame's log time) where the index says they are; ``archive.reading.copies`` orders
them by their declared cost, checks each against the manifest's hashes and reports damage.
``png16`` requests get the archived PNG bytes as they are, once their CRC-32 matches the ZIP
directory.
"""

from __future__ import annotations

import io
import json
import logging
import threading
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import imagecodecs
import numpy as np
from mcap.reader import make_reader
from mcap.records import Attachment
from mcap.stream_reader import StreamReader
from sqlalchemy import select
from sqlalchemy.engine import Engine

from thermcap.api import db
from thermcap.api.exceptions import FrameNotFound, FrameUnavailable
from thermcap.api.reading.frame_columns import FrameColumnsCache
from thermcap.api.reading.zip_index import ArchiveLocations
from thermcap.api.storage import BlobStore
from thermcap.archive.blobs import BlobFile
from thermcap.archive.codecs import get_codec
from thermcap.archive.formats import get_format
from thermcap.archive.formats.base import MCAP_SOURCE_COST, locate, read_cost
from thermcap.archive.reading.copies import (
    Copy,
    Damage,
    DamageLog,
    Part,
    in_read_order,
    read_verified,
    unoffered,
)
from thermcap.archive.reading.mcap_frames import McapFrames
from thermcap.recorder.storage.layout import EXTRAS_MCAP, DataRoot, archive_key

__all__ = ["Damage", "DamageLog", "FrameNotFound", "FrameReader", "FrameUnavailable"]

log = logging.getLogger("thermcap.api")


class FrameReader:
    """A frame's counts and sidecar, from the first copy that proves itself.

    Copies are tried in order (stored-ZIP archives, the MCAP source, the other archive formats),
    and each is checked against the manifest's digests (pixels, sidecar) before it is returned:
    a damaged copy is reported and the next one used, never served."""

    def __init__(self, engine: Engine, store: BlobStore, root: Path, cache_frames: int = 32) -> None:
        self.engine = engine
        self.store = store
        self.root = root
        self.damage = DamageLog()
        self.columns = FrameColumnsCache(engine, store)  # each session's frame times, segments and hashes
        self.locations = ArchiveLocations(engine, store)  # stored-ZIP copies, from their central directories
        self.mcap = McapFrames()  # sessions not archived yet: their segments' chunk indexes and last chunks
        # Recently decoded frames (a recorded frame never changes): the browser's temperature
        # readout and a scrubber going back and forth hit the same few frames again and again.
        self._cache: OrderedDict[tuple[str, int], np.ndarray] = OrderedDict()
        self._cache_size = cache_frames
        self._lock = threading.Lock()

    def _blobs(self, session_id: str, idx: int) -> dict[str, dict[str, Any]]:
        return self.locations.blobs(session_id, idx)

    def _key(self, session_id: str, blob: dict[str, Any]) -> str:
        return archive_key(session_id, blob["format"], blob["file"])

    def _frame_row(self, session_id: str, idx: int) -> dict[str, Any]:
        return self.columns.get(session_id).row(idx)

    def _other_formats(self, session_id: str, zipped: set[str],
                       with_unverified: bool) -> list[tuple[str, list[dict[str, Any]], bool]]:
        """(format, files, verified) of the copies not read through a ZIP directory; those not
        verified only where the frame has a digest to check them against."""
        with self.engine.connect() as conn:
            rows = conn.execute(select(db.archives.c.format, db.archives.c.files, db.archives.c.verified).where(
                db.archives.c.session_id == session_id)).all()
        return [(fmt, json.loads(files), bool(ok)) for fmt, files, ok in rows
                if fmt not in zipped and (ok or with_unverified)]

    def _open(self, session_id: str, fmt: str) -> Callable[[str], Any]:
        def open_file(rel: str) -> Any:
            key = archive_key(session_id, fmt, rel)
            head = self.store.head(key)
            if head is None:
                raise FrameNotFound(f"{key} is missing from the store")
            return io.BufferedReader(BlobFile(self.store, key, head["size"]), buffer_size=256 * 1024)

        return open_file

    def _copies(self, session_id: str, idx: int, row: dict[str, Any]) -> list[Copy]:
        """Every copy of the frame this server can reach, cheapest first. A ZIP entry is read for
        the part asked for alone: a sidecar request never decodes the image."""
        copies = []
        blobs = self._blobs(session_id, idx)
        for fmt, blob in blobs.items():
            def read_blob(part: Part, blob: dict[str, Any] = blob) -> Any:
                key = self._key(session_id, blob)
                if part == "sidecar":
                    return self.store.get_range(key, blob["sidecar_offset"],
                                                blob["sidecar_offset"] + blob["sidecar_length"])
                data = self.store.get_range(key, blob["offset"], blob["offset"] + blob["length"])
                return get_codec(blob["format"]).decode(data)
            copies.append(Copy(f"{fmt}:{blob['file']}", read_cost(fmt), read_blob))
        if row["segment"]:
            copies.append(Copy(f"mcap:{row['segment']}", MCAP_SOURCE_COST,
                               lambda part: self._from_mcap(session_id, row)[0 if part == "pixels" else 1]))
        for fmt, files, verified in self._other_formats(session_id, set(blobs), bool(row.get("pixel_digest"))):
            def read_other(part: Part, fmt: str = fmt, files: list[dict[str, Any]] = files) -> Any:
                frame = get_format(fmt).read_frame(self._open(session_id, fmt), files, idx)
                return frame.pixels if part == "pixels" else frame.sidecar
            cost = read_cost(fmt) if verified else unoffered(read_cost(fmt))
            copies.append(Copy(f"{fmt}:{locate(files, idx)[0]}", cost, read_other))
        return in_read_order(copies)

    def _verified(self, session_id: str, idx: int, part: Part) -> Any:
        """The first copy whose ``part`` matches the manifest's hash."""
        row = self._frame_row(session_id, idx)
        want = row.get("pixel_digest") if part == "pixels" else row.get("sidecar_digest")
        return read_verified(self._copies(session_id, idx, row), part, session_id=session_id, frame=idx, want=want,
                             hash_name=row["digest"], damage=self.damage)

    def encoded(self, session_id: str, idx: int, fmt: str) -> bytes | None:
        """The archived bytes of a frame in ``fmt`` (e.g. the PNG itself), if archived that way and
        intact: checked against the ZIP directory's CRC-32 (cheap) before they go out."""
        blob = self.locations.blob(session_id, fmt, idx)
        if blob is None:
            return None
        try:
            data = self.store.get_range(self._key(session_id, blob), blob["offset"], blob["offset"] + blob["length"])
        except FileNotFoundError:
            return None
        if blob.get("crc32") is not None and imagecodecs.deflate_crc32(data) != blob["crc32"]:
            self.damage.report(Damage(session_id, idx, f"{fmt}:{blob['file']}",
                                      "CRC-32 differs from the ZIP directory"))
            return None
        return data

    def pixels(self, session_id: str, idx: int) -> np.ndarray:
        key = (session_id, idx)
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        frame = np.asarray(self._verified(session_id, idx, "pixels"))
        frame.setflags(write=False)
        with self._lock:
            self._cache[key] = frame
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return frame

    def sidecar(self, session_id: str, idx: int) -> dict[str, Any]:
        return json.loads(self._verified(session_id, idx, "sidecar") or b"{}")

    def attachment(self, session_id: str, idx: int, suffix: str) -> tuple[str, bytes]:
        """The attachment recorded with frame ``idx`` whose name ends in ``/suffix`` (an importer's
        kept blob), from the MCAP source or, once that is deleted, the archive's extras.mcap."""
        row = self._frame_row(session_id, idx)
        seg = DataRoot.of(self.root).session_dir(session_id) / (row["segment"] or "")
        extras = archive_key(session_id, EXTRAS_MCAP)
        if row["segment"] and seg.is_file():
            f: Any = open(seg, "rb")  # noqa: SIM115 - one of two kinds of file, closed by the `with f` below
        elif (head := self.store.head(extras)) is not None:
            f = io.BufferedReader(BlobFile(self.store, extras, head["size"]), buffer_size=256 * 1024)
        else:
            raise FrameNotFound(f"frame {idx} of {session_id}: neither the MCAP source nor extras.mcap is there")
        with f:
            summary = make_reader(f).get_summary()
            for ai in summary.attachment_indexes if summary else []:
                if ai.log_time == row["timestamp_ns"] and ai.name.endswith("/" + suffix):
                    f.seek(ai.offset)
                    record = next(StreamReader(f, skip_magic=True).records)
                    if isinstance(record, Attachment):
                        return ai.name[: -len(suffix) - 1], record.data
        raise FrameNotFound(f"frame {idx} of {session_id} has no {suffix} (not imported from such a file)")

    def _from_mcap(self, session_id: str, row: dict[str, Any]) -> tuple[Any, bytes]:
        seg = DataRoot.of(self.root).session_dir(session_id) / (row["segment"] or "")
        if not row["segment"] or not seg.is_file():
            raise FrameNotFound(f"{seg.name or 'segment'} is not on disk")
        pixels, sidecar = self.mcap.frame(seg, row["timestamp_ns"])
        if pixels is None:
            raise FrameNotFound(f"frame {row['idx']} of {session_id} is not in {seg.name}")
        return pixels, sidecar or b""
