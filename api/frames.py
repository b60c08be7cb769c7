"""Getting one frame (counts and sidecar) back, from wherever the session keeps it.

Order: a stored-ZIP archive (one ranged read through the blob store, local or S3, then decode;
``png16`` requests get the archived PNG bytes as they are, already verified bit-exact), else the
MCAP source on local disk (the chunk holding the frame's log time).
"""

from __future__ import annotations

import json
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from sqlalchemy import select
from sqlalchemy.engine import Engine

from archive.codecs import get_codec
from recorder.messages import TOPIC_IMAGE, TOPIC_METADATA, decode_image

from . import db
from .storage import BlobStore

__all__ = ["FrameNotFound", "FrameReader"]


class FrameNotFound(LookupError):
    pass


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

    def _from_mcap(self, session_id: str, row: dict[str, Any], topic: str) -> Any:
        seg = self.root / "sessions" / session_id / (row["segment"] or "")
        if not row["segment"] or not seg.is_file():
            raise FrameNotFound(f"frame {row['idx']} of {session_id}: no archive and no MCAP source to read it from")
        t = row["timestamp_ns"]
        with open(seg, "rb") as f:
            for _, _, msg in make_reader(f).iter_messages(topics=[topic], start_time=t, end_time=t + 1):
                return decode_image(msg.data)[1].copy() if topic == TOPIC_IMAGE else json.loads(msg.data)
        raise FrameNotFound(f"frame {row['idx']} of {session_id} is not in {seg.name}")
