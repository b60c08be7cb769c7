"""A session's per-frame facts as one columnar file, beside the archives in the blob store.

A row per frame in the database cost 157 bytes (34 MB a camera-hour at 60 fps, 9.9 TB a year
for 100 cameras at 8 hours a day), most of it two 32-byte digests and the row and index
overhead that a database pays for every row. None of it is searched across sessions: a frame's
hashes, time and segment are read for the one session being served. So the indexer writes them
as a Parquet file (``index/frames/<session>/<state>.parquet``, in the same store as the
archives, local or S3), and the database keeps the session's row, its per-second target
summaries (``frame_search``) and the file's key. The file is read whole, once per indexed state
of the session, and kept in a bounded cache; anyone can read it with pyarrow, DuckDB or pandas.
Its two digest columns are named by the manifest's hash: ``blake3`` and ``sidecar_blake3``, or
``sha256`` and ``sidecar_sha256`` for a session archived before BLAKE3 (or with ``--digest sha256``).
"""

from __future__ import annotations

import hashlib
import io
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.engine import Engine

from thermcap.api import db
from thermcap.api.exceptions import FrameNotFound, FrameUnavailable
from thermcap.archive.blobs import BlobStore
from thermcap.archive.reading.frame_table import FRAME_FIELDS, FrameTable
from thermcap.recorder.storage.digest import DEFAULT_DIGEST, DIGESTS
from thermcap.recorder.storage.layout import frames_index_key

__all__ = ["FrameColumns", "FrameColumnsCache", "frames_key"]

#: Bumped when the file's columns change; a file of another version is rebuilt by the next scan.
FRAMES_FILE_VERSION = "1"


def frames_key(session_id: str, fingerprint: str) -> str:
    """Where a session's frames file lives for one indexed state: a new state is a new key, so a
    reader never sees a file half replaced."""
    state = hashlib.sha256(fingerprint.encode()).hexdigest()[:16]
    return frames_index_key(session_id, state)


def _digests(values: list[str | None], n: int) -> tuple[np.ndarray, np.ndarray]:
    raw = np.zeros((n, 32), np.uint8)
    have = np.zeros(n, bool)
    for i, v in enumerate(values[:n]):
        if v:
            raw[i] = np.frombuffer(bytes.fromhex(v), np.uint8)
            have[i] = True
    return raw, have


@dataclass(frozen=True)
class FrameColumns:
    """Every frame of a session, as arrays: frame ``i`` is row ``i``."""

    session_id: str
    timestamp_ns: np.ndarray  # int64
    segment_code: np.ndarray  # int16: index into ``segment_names``, -1 for none
    segment_names: tuple[str, ...]
    digest: str  # the hash of the two digest columns (recorder.storage.digest)
    pixel_digest: np.ndarray  # uint8 [frames, 32]; a frame without one has ``has_pixel_digest`` False
    has_pixel_digest: np.ndarray
    sidecar_digest: np.ndarray
    has_sidecar_digest: np.ndarray
    grade: np.ndarray  # float64, NaN: not graded
    target_count: np.ndarray  # int32
    max_target_temp_c: np.ndarray  # float64, NaN: no target
    slew_to_cue: np.ndarray  # bool

    def __len__(self) -> int:
        return len(self.timestamp_ns)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.timestamp_ns, self.segment_code, self.pixel_digest, self.has_pixel_digest,
                                      self.sidecar_digest, self.has_sidecar_digest, self.grade, self.target_count,
                                      self.max_target_temp_c, self.slew_to_cue))

    @classmethod
    def from_rows(cls, session_id: str, rows: list[dict[str, Any]], digest: str = DEFAULT_DIGEST) -> FrameColumns:
        """From the indexer's per-frame dicts (frame ``i`` at position ``i``; the digests, by
        ``digest``'s hash, under ``pixel_digest`` and ``sidecar_digest``)."""
        n = len(rows)
        names: dict[str, int] = {}
        codes = np.array([-1 if not r.get("segment") else names.setdefault(r["segment"], len(names))
                          for r in rows], np.int16)
        sha, has_sha = _digests([r.get("pixel_digest") for r in rows], n)
        side, has_side = _digests([r.get("sidecar_digest") for r in rows], n)

        def floats(key: str) -> np.ndarray:
            return np.array([np.nan if r.get(key) is None else r[key] for r in rows], np.float64)
        return cls(session_id, np.array([int(r.get("timestamp_ns") or 0) for r in rows], np.int64), codes,
                   tuple(names), digest, sha, has_sha, side, has_side, floats("grade"),
                   np.array([int(r.get("target_count") or 0) for r in rows], np.int32), floats("max_target_temp_c"),
                   np.array([bool(r.get("slew_to_cue")) for r in rows], bool))

    def segment(self, i: int) -> str | None:
        code = int(self.segment_code[i])
        return self.segment_names[code] if code >= 0 else None

    def pixel_digest_raw(self, i: int) -> bytes | None:
        return self.pixel_digest[i].tobytes() if self.has_pixel_digest[i] else None

    def row(self, i: int) -> dict[str, Any]:
        """Frame ``i`` as the frame reader asks for it (digests in hex, as the manifests have
        them, and the hash that took them under ``digest``)."""
        if not 0 <= i < len(self):
            raise FrameNotFound(f"session {self.session_id} has no frame {i}")
        return {"idx": i, "timestamp_ns": int(self.timestamp_ns[i]), "segment": self.segment(i), "digest": self.digest,
                "pixel_digest": self.pixel_digest[i].tobytes().hex() if self.has_pixel_digest[i] else None,
                "sidecar_digest": self.sidecar_digest[i].tobytes().hex() if self.has_sidecar_digest[i] else None,
                "grade": None if np.isnan(self.grade[i]) else float(self.grade[i]),
                "target_count": int(self.target_count[i]),
                "max_target_temp_c": None if np.isnan(self.max_target_temp_c[i]) else float(self.max_target_temp_c[i]),
                "slew_to_cue": bool(self.slew_to_cue[i])}

    def table(self) -> FrameTable:
        """The sidecar summaries as the Python API's and the Zarr store's coordinates."""
        by_column = {"grade": self.grade, "target_count": self.target_count,
                     "max_target_temp_c": self.max_target_temp_c, "slew_to_cue": self.slew_to_cue}
        fields = {name: by_column[col].astype(np.dtype(dtype)) for name, (col, dtype, _) in FRAME_FIELDS.items()}
        return FrameTable(self.session_id, np.arange(len(self), dtype=np.int64), self.timestamp_ns, fields)

    def to_parquet(self) -> bytes:
        import pyarrow as pa
        import pyarrow.parquet as pq

        def digests(raw: np.ndarray, have: np.ndarray) -> Any:
            return pa.FixedSizeBinaryArray.from_buffers(pa.binary(32), len(raw),
                                                        [pa.py_buffer(np.packbits(have, bitorder="little")),
                                                         pa.py_buffer(np.ascontiguousarray(raw))])

        def nullable(values: np.ndarray) -> Any:
            return pa.array(values, mask=np.isnan(values))

        segment = pa.DictionaryArray.from_arrays(pa.array(self.segment_code, pa.int16(), mask=self.segment_code < 0),
                                                 pa.array(list(self.segment_names), pa.string()))
        table = pa.table({"timestamp_ns": self.timestamp_ns, "segment": segment,
                          self.digest: digests(self.pixel_digest, self.has_pixel_digest),
                          f"sidecar_{self.digest}": digests(self.sidecar_digest, self.has_sidecar_digest),
                          "grade": nullable(self.grade), "target_count": self.target_count,
                          "max_target_temp_c": nullable(self.max_target_temp_c), "slew_to_cue": self.slew_to_cue},
                         metadata={"thermcap.session_id": self.session_id,
                                   "thermcap.frames_file": FRAMES_FILE_VERSION})
        out = io.BytesIO()
        # Timestamps step by a frame period: delta coding takes them to about a byte a frame.
        pq.write_table(table, out, compression="zstd", use_dictionary=["segment"],
                       column_encoding={"timestamp_ns": "DELTA_BINARY_PACKED"})
        return out.getvalue()

    @classmethod
    def from_parquet(cls, session_id: str, data: bytes) -> FrameColumns:
        import pyarrow as pa
        import pyarrow.parquet as pq

        # One thread, no pre-buffering: the frames file is small, and a read through Arrow's
        # thread pools left a worker alive into the interpreter's teardown, where it aborted the
        # process after its work was done (apache/arrow#34314: a plain read and exit aborted 10
        # times in 150 here, `thermcap cut` once in 40). This read starts no thread.
        table = pq.ParquetFile(pa.BufferReader(data), pre_buffer=False).read(use_threads=False)

        def column(name: str) -> Any:
            return table.column(name).combine_chunks()

        def digests(name: str) -> tuple[np.ndarray, np.ndarray]:
            arr = column(name)
            raw = np.frombuffer(arr.buffers()[1], np.uint8)[arr.offset * 32:(arr.offset + len(arr)) * 32]
            return raw.reshape(-1, 32).copy(), arr.is_valid().to_numpy(zero_copy_only=False)

        def floats(name: str) -> np.ndarray:
            return column(name).to_numpy(zero_copy_only=False).astype(np.float64)  # nulls become NaN

        seg = column("segment")
        if isinstance(seg, pa.DictionaryArray):
            codes = seg.indices.fill_null(-1).to_numpy(zero_copy_only=False).astype(np.int16)
            names = tuple(seg.dictionary.to_pylist())
        else:  # a reader that wrote the segments as plain strings
            values = seg.to_pylist()
            lookup: dict[str, int] = {}
            codes = np.array([-1 if v is None else lookup.setdefault(v, len(lookup)) for v in values], np.int16)
            names = tuple(lookup)
        name = next((d for d in DIGESTS if d in table.column_names), DEFAULT_DIGEST)
        sha, has_sha = digests(name)
        side, has_side = digests(f"sidecar_{name}")
        return cls(session_id, column("timestamp_ns").to_numpy().astype(np.int64), codes, names, name, sha, has_sha,
                   side, has_side, floats("grade"), column("target_count").to_numpy().astype(np.int32),
                   floats("max_target_temp_c"), column("slew_to_cue").to_numpy(zero_copy_only=False).astype(bool))


class FrameColumnsCache:
    """Sessions' frame columns, read from the store once per indexed state and kept within a
    byte budget (a camera-hour is about 20 MB in memory), least recently used first out."""

    def __init__(self, engine: Engine, store: BlobStore, max_bytes: int = 512 << 20) -> None:
        self.engine, self.store, self.max_bytes = engine, store, max_bytes
        self._kept: OrderedDict[str, FrameColumns] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def _key(self, session_id: str) -> str | None:
        with self.engine.connect() as conn:
            row = conn.execute(select(db.sessions.c.frames_key).where(db.sessions.c.id == session_id)).first()
        if row is None:
            raise FrameNotFound(f"no session {session_id}")
        return row[0]

    def get(self, session_id: str) -> FrameColumns:
        key = self._key(session_id)
        for _ in range(2):
            if key is None:  # indexed before the frames files: the next scan writes one
                raise FrameUnavailable(f"session {session_id} has no frame table yet; `thermcap index` writes it")
            with self._lock:
                cols = self._kept.get(key)
                if cols is not None:
                    self._kept.move_to_end(key)
                    return cols
            head = self.store.head(key)
            if head is None:  # re-indexed between the lookup and the read: take the new state
                newer = self._key(session_id)
                if newer == key:
                    raise FrameUnavailable(f"session {session_id}: its frame table {key} is missing from the "
                                           f"store; `thermcap index --force` rebuilds it")
                key = newer
                continue
            cols = FrameColumns.from_parquet(session_id, self.store.get_range(key, 0, int(head["size"])))
            with self._lock:
                if key not in self._kept:
                    self._kept[key] = cols
                    self._bytes += cols.nbytes
                while self._bytes > self.max_bytes and len(self._kept) > 1:
                    _, old = self._kept.popitem(last=False)
                    self._bytes -= old.nbytes
            return cols
        raise FrameUnavailable(f"session {session_id} was re-indexed while it was read; ask again")
