"""A tool's statistic over a session, reading as little of the archive as gives the exact answer.

Three ways, the cheapest first, each giving the numbers decoding every frame would:

1. ``summary``: the whole frame's min, max (and mean, for an affine model) from the archive's
   frame summary, with no frame decoded at all.
2. ``strips``: only the TIFF strips that hold the tool's rows. Each strip is checked against the
   summary's band CRC-32 first. A strip that fails is reported as damage, and that frame is
   read whole, through the frame reader's verified copies.
3. ``frames``: every frame through the frame reader (each copy checked against its digest), on
   a few threads. This serves sessions archived before the summary existed, or without
   tiff-lzw.

The summary is trusted only once its bytes match the digest that the manifest (and so the
index) gives for it.
"""

from __future__ import annotations

import io
import json
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.engine import Engine

from thermcap.api import db
from thermcap.api.reading.frames import FrameReader
from thermcap.api.storage import BlobStore
from thermcap.archive.blobs import BlobFile
from thermcap.archive.formats import get_format
from thermcap.archive.formats.base import RowBlock, locate, positions_in
from thermcap.archive.frame_summary import FrameSummary, load_summary
from thermcap.archive.manifest import bytes_digest, record_digest
from thermcap.archive.reading.copies import Damage
from thermcap.recorder.storage.layout import archive_key
from thermcap.recorder.thermography.measure import Box, Tool, bounds, shifted
from thermcap.recorder.thermography.series import STATS, series_point

__all__ = ["RegionReader", "SeriesResult"]

#: The format whose storage units (strips) can be read alone.
_ROW_FORMAT = "tiff-lzw"


@dataclass
class SeriesResult:
    points: list[dict[str, Any]]
    method: str  # "summary", "strips" or "frames" (the way most frames were read)
    frames_decoded: int = 0  # whole frames decoded
    strip_frames: int = 0  # frames read by their strips alone
    seconds: float = 0.0
    damaged: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"method": self.method, "frames_decoded": self.frames_decoded, "strip_frames": self.strip_frames,
                "seconds": round(self.seconds, 4), "points": self.points}


ModelAt = Callable[[int], Any]  # frame index -> radiometric model


class RegionReader:
    def __init__(self, frames: FrameReader, engine: Engine, store: BlobStore, *, threads: int = 2,
                 cache_sessions: int = 8) -> None:
        self.frames, self.engine, self.store, self.threads = frames, engine, store, threads
        self._summaries: OrderedDict[str, FrameSummary | None] = OrderedDict()
        self._cache_sessions = cache_sessions
        self._lock = threading.Lock()

    # -- the summary --------------------------------------------------------------------------

    def summary(self, session_id: str, entry_json: str | None) -> FrameSummary | None:
        """The session's frame summary once it matches its digest; None without one (or with a
        damaged one, which is reported)."""
        cache_key = f"{session_id}:{entry_json}"
        with self._lock:
            if cache_key in self._summaries:
                self._summaries.move_to_end(cache_key)
                return self._summaries[cache_key]
        got = self._load_summary(session_id, entry_json)
        with self._lock:
            self._summaries[cache_key] = got
            while len(self._summaries) > self._cache_sessions:
                self._summaries.popitem(last=False)
        return got

    def _load_summary(self, session_id: str, entry_json: str | None) -> FrameSummary | None:
        if not entry_json:
            return None
        entry = json.loads(entry_json)
        key = archive_key(session_id, entry["path"])
        try:
            data = self.store.get_range(key, 0, int(entry["bytes"]))
        except FileNotFoundError:
            return None
        named = record_digest(entry)
        if named is None or bytes_digest(data, named[0]) != named[1]:
            self.frames.damage.report(Damage(session_id, -1, f"summary:{entry['path']}",
                                             f"{named[0] if named else 'digest'} differs from the manifest"))
            return None
        try:
            return load_summary(data, name=key)
        except ValueError as exc:
            self.frames.damage.report(Damage(session_id, -1, f"summary:{entry['path']}", str(exc)))
            return None

    # -- the series ---------------------------------------------------------------------------

    def series(self, row: dict[str, Any], tool: Tool, stat: str, indices: range, model_at: ModelAt,
               times: dict[int, int]) -> SeriesResult:
        """``row``: the session's index row; ``model_at(i)``: frame i's model (re-parameterised
        versions differ by frame range). Raises ToolError for a tool outside the frame."""
        if stat not in STATS:
            raise ValueError(f"stat must be one of {', '.join(STATS)}, got {stat!r}")
        t0 = time.perf_counter()
        sid = row["id"]
        shape = (int(row["height"] or 0), int(row["width"] or 0))
        x0, y0, x1, y1 = bounds(tool, shape)  # a tool outside the frame fails here, before any read
        summary = self.summary(sid, row.get("summary"))
        if summary is not None and (summary.height, summary.width) != shape:
            summary = None
        if summary is not None and isinstance(tool, Box) and (x0, y0, x1, y1) == (0, 0, shape[1], shape[0]):
            values = self._from_summary(summary, stat, indices, model_at)
            if values is not None:
                points = [{"frame": i, "timestamp_ns": int(times.get(i, 0)), "celsius": v}
                          for i, v in zip(indices, values, strict=True)]
                return SeriesResult(points, "summary", seconds=time.perf_counter() - t0)
        result = SeriesResult([], "frames")
        local = shifted(tool, x0, y0)

        def to_celsius(i: int, counts: np.ndarray) -> np.ndarray:
            return np.asarray(model_at(i).to_celsius(counts))

        def whole(i: int) -> dict[str, Any]:
            crop = self.frames.pixels(sid, i)[y0:y1, x0:x1]
            return series_point(i, times.get(i, 0), crop, local, stat, to_celsius)

        files = self._row_files(sid) if summary is not None else None
        if files is not None and summary is not None:
            points = self._from_strips(sid, files, summary, indices, (x0, y0, x1, y1), local, stat, to_celsius,
                                       times, whole, result)
        else:
            with ThreadPoolExecutor(self.threads) as pool:
                points = list(pool.map(whole, indices))
            result.frames_decoded = len(points)
        result.points = points
        result.method = "strips" if result.strip_frames > result.frames_decoded else "frames"
        result.seconds = time.perf_counter() - t0
        return result

    @staticmethod
    def _from_summary(summary: FrameSummary, stat: str, indices: range, model_at: ModelAt) -> list[float] | None:
        idx = np.arange(indices.start, min(indices.stop, summary.frames), indices.step)
        if len(idx) != len(indices):
            return None
        out: list[float] = []
        run_start = 0
        # consecutive frames with one model version are one lookup table
        for k in range(1, len(idx) + 1):
            if k == len(idx) or model_at(int(idx[k])) is not model_at(int(idx[run_start])):
                vals = summary.celsius(stat, idx[run_start:k], model_at(int(idx[run_start])).to_celsius)
                if vals is None:
                    return None
                out += vals
                run_start = k
        return out

    def _row_files(self, session_id: str) -> list[dict[str, Any]] | None:
        with self.engine.connect() as conn:
            files = conn.execute(select(db.archives.c.files).where(
                db.archives.c.session_id == session_id, db.archives.c.format == _ROW_FORMAT,
                db.archives.c.verified.is_(True))).scalar()
        return json.loads(files) if files else None

    def _open(self, session_id: str) -> Callable[[str], Any]:
        def open_file(rel: str) -> Any:
            key = archive_key(session_id, _ROW_FORMAT, rel)
            if self.store.kind == "local":  # the store's keys are paths under the data root
                return open(self.frames.root / key, "rb")
            head = self.store.head(key)
            if head is None:
                raise FileNotFoundError(key)
            return io.BufferedReader(BlobFile(self.store, key, head["size"]), buffer_size=256 * 1024)

        return open_file

    def _from_strips(self, sid: str, files: list[dict[str, Any]], summary: FrameSummary, indices: range,
                     rect: tuple[int, int, int, int], local: Tool, stat: str,
                     to_celsius: Callable[[int, np.ndarray], np.ndarray], times: dict[int, int],
                     whole: Callable[[int], dict[str, Any]], result: SeriesResult) -> list[dict[str, Any]]:
        band = summary.band_rows
        y0, y1 = rect[1], rect[3]
        ya, yb = y0 // band * band, min(summary.height, -(-y1 // band) * band)
        fmt = get_format(_ROW_FORMAT)
        open_file = self._open(sid)
        lock = threading.Lock()

        def one_file(sub: range) -> list[dict[str, Any]]:
            out: list[dict[str, Any]] = []
            todo = sub
            while len(todo):
                nxt, read_any = todo.start, False
                try:
                    for block in fmt.read_rows(open_file, files, todo, ya, yb) or ():
                        out.append(self._block_point(sid, files, summary, block, rect, local, stat, to_celsius,
                                                     times, whole, lock, result))
                        nxt, read_any = block.index + todo.step, True
                    todo = range(0)
                except Exception as exc:
                    name = f"{_ROW_FORMAT}:{_file_of(files, nxt)}"
                    self.frames.damage.report(Damage(sid, nxt, name, f"unreadable rows ({type(exc).__name__}: "
                                                                     f"{exc})"))
                    with lock:
                        result.damaged.append(name)
                    if read_any:  # one frame's strips: that frame whole, then strips again
                        out.append(self._whole(whole, nxt, lock, result))
                        todo = range(nxt + todo.step, todo.stop, todo.step)
                    else:  # failing before any block (a missing file, not a TIFF): the rest whole
                        out += [self._whole(whole, i, lock, result) for i in range(nxt, todo.stop, todo.step)]
                        todo = range(0)
            return out

        with ThreadPoolExecutor(self.threads) as pool:
            parts = list(pool.map(one_file, _per_file(files, indices)))
        return [p for part in parts for p in part]

    def _block_point(self, sid: str, files: list[dict[str, Any]], summary: FrameSummary, block: RowBlock,
                     rect: tuple[int, int, int, int], local: Tool, stat: str,
                     to_celsius: Callable[[int, np.ndarray], np.ndarray], times: dict[int, int],
                     whole: Callable[[int], dict[str, Any]], lock: threading.Lock,
                     result: SeriesResult) -> dict[str, Any]:
        x0, y0, x1, y1 = rect
        i, rows, first = block.index, block.rows, block.first_row
        if summary.rows_intact(i, first, rows):
            with lock:
                result.strip_frames += 1
            return series_point(i, times.get(i, 0), rows[y0 - first:y1 - first, x0:x1], local, stat, to_celsius)
        if summary.checkable(first, rows.shape[0]):  # not merely strips of another height: damage
            name = f"{_ROW_FORMAT}:{_file_of(files, i)}"
            self.frames.damage.report(Damage(sid, i, name, f"rows {first}..{first + rows.shape[0]} CRC-32 differs "
                                                           f"from the frame summary"))
            with lock:
                result.damaged.append(name)
        return self._whole(whole, i, lock, result)

    @staticmethod
    def _whole(whole: Callable[[int], dict[str, Any]], i: int, lock: threading.Lock,
               result: SeriesResult) -> dict[str, Any]:
        point = whole(i)
        with lock:
            result.frames_decoded += 1
        return point


def _file_of(files: list[dict[str, Any]], index: int) -> str:
    """The file a damaged frame is in, to name in the damage log."""
    try:
        return locate(files, index)[0]
    except IndexError:
        return "?"


def _per_file(files: list[dict[str, Any]], indices: range) -> list[range]:
    """``indices`` cut at file boundaries, each part a range with the same step."""
    parts, first = [], 0
    for rec in files:
        end = first + int(rec["frames"])
        sub = indices[positions_in(indices, first, end)]
        if len(sub):
            parts.append(sub)
        first = end
    return parts
