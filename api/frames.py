"""Getting one frame (counts and sidecar) back, from wherever the session keeps it.

Order: a stored-ZIP archive (one ranged read through the blob store, local or S3, then decode;
``png16`` requests get the archived PNG bytes as they are, already verified bit-exact), else the
MCAP source on local disk (the chunk holding the frame's log time).
"""

from __future__ import annotations

import io
import json
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap.records import Attachment
from mcap.stream_reader import StreamReader
from sqlalchemy import select
from sqlalchemy.engine import Engine

from archive.codecs import get_codec
from recorder.messages import TOPIC_IMAGE, TOPIC_METADATA, decode_image

from . import db
from .storage import BlobStore

__all__ = ["FrameNotFound", "FrameReader"]


class FrameNotFound(LookupError):
    pass


class _BlobFile(io.RawIOBase):
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


class FrameReader:
    def __init__(self, engine: Engine, store: BlobStore, root: Path, cache_frames: int = 32) -> None:
        self.engine = engine
        self.store = store
        self.root = root
        # Recently decoded frames (a recorded frame never changes): the browser's temperature
        # readout and a scrubber going back and forth hit the same few frames again and again.
        self._cache: OrderedDict[tuple[str, int], np.ndarray] = OrderedDict()
        self._cache_size = cache_frames
        self._lock = threading.Lock()

    def _blob(self, session_id: str, idx: int, prefer: str | None = None) -> dict[str, Any] | None:
        with self.engine.connect() as conn:
            rows = conn.execute(select(db.frame_blobs).where(db.frame_blobs.c.session_id == session_id,
                                                             db.frame_blobs.c.idx == idx)).mappings().all()
        if not rows:
            return None
        by_fmt = {r["format"]: dict(r) for r in rows}
        if prefer in by_fmt:
            return by_fmt[prefer]
        # For pixels: PNG (libpng, 4-5 ms) first; HTJ2K decodes faster but only one at a time
        # (see archive.codecs.Htj2k), which serialises concurrent requests.
        return next((by_fmt[f] for f in ("png16", "htj2k", "jpegls", "jxl") if f in by_fmt), next(iter(by_fmt.values())))

    def _key(self, session_id: str, blob: dict[str, Any]) -> str:
        return f"sessions/{session_id}/archive/{blob['format']}/{blob['file']}"

    def _frame_row(self, session_id: str, idx: int) -> dict[str, Any]:
        with self.engine.connect() as conn:
            row = conn.execute(select(db.frames).where(db.frames.c.session_id == session_id,
                                                       db.frames.c.idx == idx)).mappings().first()
        if row is None:
            raise FrameNotFound(f"session {session_id} has no frame {idx}")
        return dict(row)

    def encoded(self, session_id: str, idx: int, fmt: str) -> bytes | None:
        """The archived bytes of a frame in ``fmt`` (e.g. the PNG itself), if archived that way."""
        blob = self._blob(session_id, idx, prefer=fmt)
        if blob is None or blob["format"] != fmt:
            return None
        return self.store.get_range(self._key(session_id, blob), blob["offset"], blob["offset"] + blob["length"])

    def pixels(self, session_id: str, idx: int) -> np.ndarray:
        key = (session_id, idx)
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return self._cache[key]
        frame = self._decode(session_id, idx)
        frame.setflags(write=False)
        with self._lock:
            self._cache[key] = frame
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return frame

    def _decode(self, session_id: str, idx: int) -> np.ndarray:
        row = self._frame_row(session_id, idx)
        blob = self._blob(session_id, idx)
        if blob is not None:
            data = self.store.get_range(self._key(session_id, blob), blob["offset"], blob["offset"] + blob["length"])
            return get_codec(blob["format"]).decode(data)
        return self._from_mcap(session_id, row, TOPIC_IMAGE)

    def sidecar(self, session_id: str, idx: int) -> dict[str, Any]:
        row = self._frame_row(session_id, idx)
        blob = self._blob(session_id, idx)
        if blob is not None:
            data = self.store.get_range(self._key(session_id, blob), blob["sidecar_offset"],
                                        blob["sidecar_offset"] + blob["sidecar_length"])
            return json.loads(data or b"{}")
        return self._from_mcap(session_id, row, TOPIC_METADATA)

    def attachment(self, session_id: str, idx: int, suffix: str) -> tuple[str, bytes]:
        """The attachment recorded with frame ``idx`` whose name ends in ``/suffix`` (an importer's
        kept blob), from the MCAP source or, once that is deleted, the archive's extras.mcap."""
        row = self._frame_row(session_id, idx)
        seg = self.root / "sessions" / session_id / (row["segment"] or "")
        extras = f"sessions/{session_id}/archive/extras.mcap"
        if row["segment"] and seg.is_file():
            f: Any = open(seg, "rb")
        elif (head := self.store.head(extras)) is not None:
            f = io.BufferedReader(_BlobFile(self.store, extras, head["size"]), buffer_size=256 * 1024)
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

    def _from_mcap(self, session_id: str, row: dict[str, Any], topic: str) -> Any:
        seg = self.root / "sessions" / session_id / (row["segment"] or "")
        if not row["segment"] or not seg.is_file():
            raise FrameNotFound(f"frame {row['idx']} of {session_id}: no archive and no MCAP source to read it from")
        t = row["timestamp_ns"]
        with open(seg, "rb") as f:
            for _, _, msg in make_reader(f).iter_messages(topics=[topic], start_time=t, end_time=t + 1):
                return decode_image(msg.data)[1].copy() if topic == TOPIC_IMAGE else json.loads(msg.data)
        raise FrameNotFound(f"frame {row['idx']} of {session_id} is not in {seg.name}")
