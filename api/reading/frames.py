"""Getting one frame (counts and sidecar) back, from wherever the session keeps it.

Order: a stored-ZIP archive (one ranged read through the blob store, local or S3, then decode;
``png16`` requests get the archived PNG bytes as they are, once their CRC-32 matches the ZIP
directory), then the MCAP source on local disk (the chunk holding the frame's log time), then
any other verified format (an HDF5 chunk or a TIFF page, by ranged reads). Every copy is checked
against the manifest's hashes before it is used; a damaged one is reported and skipped.
"""

from __future__ import annotations

import io
import json
import logging
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
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
from thermcap.api.reading.mcap_frames import McapFrames
from thermcap.api.reading.zip_index import ArchiveLocations
from thermcap.api.storage import BlobStore
from thermcap.archive.codecs import get_codec
from thermcap.archive.formats import get_format
from thermcap.archive.formats.base import locate
from thermcap.archive.manifest import bytes_digest, frame_digest

__all__ = ["BlobFile", "Damage", "DamageLog", "FrameNotFound", "FrameReader", "FrameUnavailable"]

log = logging.getLogger("thermcap.api")


class BlobFile(io.RawIOBase):
    """A stored blob as a seekable file (ranged reads), so mcap's seeking reader can fetch one
    attachment from ``extras.mcap`` on S3 without downloading the whole file."""

    def __init__(self, store: BlobStore, key: str, size: int) -> None:
        self.store, self.key, self.size, self.pos = store, key, size, 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        self.pos = {io.SEEK_SET: 0, io.SEEK_CUR: self.pos, io.SEEK_END: self.size}[whence] + offset
        return self.pos

    def tell(self) -> int:
        return self.pos

    def readinto(self, buffer: Any) -> int:
        end = min(self.size, self.pos + len(buffer))
        if end <= self.pos:
            return 0
        data = self.store.get_range(self.key, self.pos, end)
        buffer[:len(data)] = data
        self.pos += len(data)
        return len(data)




@dataclass
class Damage:
    session_id: str
    frame: int
    copy: str  # which copy: "png16:0000.zip", "mcap:0000.mcap", "hdf5:<id>.h5"
    problem: str
    at: float = field(default_factory=time.time)


class DamageLog:
    """Damaged copies met while serving: logged, counted (``thermcap_damaged_copies_total``) and
    shown on /healthz; a bounded list of the latest, so a bad disk cannot fill memory."""

    def __init__(self, keep: int = 100) -> None:
        self.recent: deque[Damage] = deque(maxlen=keep)
        self.total = 0
        self.counter: Any = None  # a prometheus Counter, set by the app
        self._lock = threading.Lock()

    def report(self, damage: Damage) -> None:
        with self._lock:
            self.total += 1
            self.recent.append(damage)
        log.warning("damaged copy of frame %d of %s in %s: %s; serving another verified copy",
                    damage.frame, damage.session_id, damage.copy, damage.problem)
        if self.counter is not None:
            self.counter.labels(damage.copy.split(":", 1)[0]).inc()

    def summary(self) -> dict[str, Any]:
        with self._lock:
            return {"damaged_copies_seen": self.total,
                    "recent": [{"session_id": d.session_id, "frame": d.frame, "copy": d.copy, "problem": d.problem}
                               for d in list(self.recent)[-10:]]}


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

    def _ordered_blobs(self, session_id: str, idx: int) -> list[dict[str, Any]]:
        # For pixels: PNG (libpng, 4-5 ms) first; HTJ2K decodes faster but only one at a time
        # (see archive.codecs.Htj2k), which serialises concurrent requests.
        by_fmt = self._blobs(session_id, idx)
        order = [f for f in ("png16", "htj2k", "jpegls", "jxl") if f in by_fmt]
        return [by_fmt[f] for f in order + sorted(set(by_fmt) - set(order))]

    def _key(self, session_id: str, blob: dict[str, Any]) -> str:
        return f"sessions/{session_id}/archive/{blob['format']}/{blob['file']}"

    def _frame_row(self, session_id: str, idx: int) -> dict[str, Any]:
        return self.columns.get(session_id).row(idx)

    def _other_formats(self, session_id: str, zipped: set[str],
                       verified: bool = True) -> list[tuple[str, list[dict[str, Any]]]]:
        with self.engine.connect() as conn:
            rows = conn.execute(select(db.archives.c.format, db.archives.c.files).where(
                db.archives.c.session_id == session_id, db.archives.c.verified.is_(verified))).all()
        return [(fmt, json.loads(files)) for fmt, files in rows if fmt not in zipped]

    def _open(self, session_id: str, fmt: str) -> Callable[[str], Any]:
        def open_file(rel: str) -> Any:
            key = f"sessions/{session_id}/archive/{fmt}/{rel}"
            head = self.store.head(key)
            if head is None:
                raise FrameNotFound(f"{key} is missing from the store")
            return io.BufferedReader(BlobFile(self.store, key, head["size"]), buffer_size=256 * 1024)

        return open_file

    def _copies(self, session_id: str, idx: int, row: dict[str, Any],
                part: str) -> Iterator[tuple[str, Callable[[], Any]]]:
        """(name, read) for every copy of the frame; read() gives its ``part`` ("pixels" or
        "sidecar" bytes). A ZIP entry is read for that part alone: a sidecar request never decodes
        the image."""
        pixels = part == "pixels"
        blobs = self._ordered_blobs(session_id, idx)
        for blob in blobs:
            def read_blob(blob: dict[str, Any] = blob) -> Any:
                key = self._key(session_id, blob)
                if not pixels:
                    return self.store.get_range(key, blob["sidecar_offset"],
                                                blob["sidecar_offset"] + blob["sidecar_length"])
                data = self.store.get_range(key, blob["offset"], blob["offset"] + blob["length"])
                return get_codec(blob["format"]).decode(data)
            yield f"{blob['format']}:{blob['file']}", read_blob
        if row["segment"]:
            yield f"mcap:{row['segment']}", lambda: self._from_mcap(session_id, row)[0 if pixels else 1]
        others = self._other_formats(session_id, {b["format"] for b in blobs})
        if row.get("pixel_digest" if pixels else "sidecar_digest"):
            # Last, the copies not offered whole (scrub marked a file of theirs damaged, or they
            # never verified): a damaged part hides only itself, and this frame is checked
            # against the manifest's hash like any other, so an intact file of theirs still serves.
            others += self._other_formats(session_id, set(), verified=False)
        for fmt, files in others:
            def read_other(fmt: str = fmt, files: list[dict[str, Any]] = files) -> Any:
                frame = get_format(fmt).read_frame(self._open(session_id, fmt), files, idx)
                return frame.pixels if pixels else frame.sidecar
            yield f"{fmt}:{locate(files, idx)[0]}", read_other

    def _verified(self, session_id: str, idx: int, part: str) -> Any:
        """The first copy whose ``part`` ("pixels" or "sidecar") matches the manifest's hash."""
        row = self._frame_row(session_id, idx)
        want = row.get("pixel_digest") if part == "pixels" else row.get("sidecar_digest")
        hash_name = row["digest"]
        missing = []
        for name, read in self._copies(session_id, idx, row, part):
            try:
                value = read()
            except (FrameNotFound, FileNotFoundError) as exc:
                missing.append(f"{name}: {exc}")
                continue
            except Exception as exc:  # a damaged file may fail anywhere inside a decoder
                self.damage.report(Damage(session_id, idx, name, f"unreadable ({type(exc).__name__}: {exc})"))
                continue
            if want:
                got = frame_digest(value, hash_name) if part == "pixels" else bytes_digest(value, hash_name)
                if got != want:
                    self.damage.report(Damage(session_id, idx, name, f"{part} {hash_name} differs from the manifest"))
                    continue
            return value
        raise FrameUnavailable(f"frame {idx} of {session_id}: no verified copy could be read"
                               + (f" ({'; '.join(missing)})" if missing else ""))

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
        seg = self.root / "sessions" / session_id / (row["segment"] or "")
        extras = f"sessions/{session_id}/archive/extras.mcap"
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
        seg = self.root / "sessions" / session_id / (row["segment"] or "")
        if not row["segment"] or not seg.is_file():
            raise FrameNotFound(f"{seg.name or 'segment'} is not on disk")
        pixels, sidecar = self.mcap.frame(seg, row["timestamp_ns"])
        if pixels is None:
            raise FrameNotFound(f"frame {row['idx']} of {session_id} is not in {seg.name}")
        return pixels, sidecar or b""
