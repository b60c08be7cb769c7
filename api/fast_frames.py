"""The lean path for a frame's bytes: ``GET /api/v1/sessions/{id}/frames/{n}`` as png16 or raw.

Why: a frame through the framework cost 4.1x nginx serving the same PNG. The profile put about
40% in the middleware stack and routing, 18% in sending through those layers, 21% in the
object store's ranged read, and 10% in a database query per request. This path answers the
two plain requests, ``format=png16`` (or none) and ``format=raw``, in front of all that:

- It keeps a session's frame hashes in memory, loaded by one query when first asked for and
  looked at again only when the session's index row changes (at most every ``CHECK_S``). A
  frame's place in the png16 ZIP comes from that ZIP's central directory, read once per file
  (``api.reading.zip_index``).
- Bytes come by ``os.pread`` on the archive file, through a cache of open descriptors.
- A PNG is checked against the ZIP directory's CRC-32 before it goes out, as on the full path.
- Raw counts are undone from the PNG's own deflate stream where thermcap wrote it (every row
  filtered Up: libdeflate, then a blocked prefix sum, 1.1 ms for 640x512 against 2.6 ms for
  libpng and 2.4 ms for the tiff-lzw strips on two threads). A PNG another writer made falls
  to the tiff-lzw strips, then to libpng. Whichever gives them, the counts are checked
  against the archive's frame summary (a CRC-32 for each 64-row band, taken from the source
  and bound to the manifest by its digest), or against the frame's digest where the archive
  has no summary. Their ETag is the body's BLAKE3 either way (``body_etag``): where the manifest
  took BLAKE3, that is the frame's own digest, hashed once. A TIFF file's strip offsets are read
  from its IFDs once, the first time it is asked for.

Raw counts of a session not archived yet (no png16 copy) come from its MCAP segment through the
application's own ``McapFrames`` (one index and chunk cache for both paths), checked against the
frame's digest where the index has one. A frame whose chunk is kept is read in the event loop (a
header walk); one that needs a chunk read and decompressed goes to a thread, so the loop never
waits on zstd.

It gives the same bytes, status, ETag, 304 and headers as the route. Anything else goes to the
full application: another format or parameter, an Origin header (CORS), a token that does not
pass, a session or copy it does not know, damage. So there is one behaviour, and the fast
path only skips layers.
"""

from __future__ import annotations

import asyncio
import functools
import json
import os
import re
import threading
import time
from collections import Counter, OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl

import imagecodecs
import numpy as np
import tifffile
from sqlalchemy import select
from sqlalchemy.engine import Engine

from thermcap.api import db
from thermcap.api.cache_policy import Kind, cache_control
from thermcap.api.http_conventions import body_etag, etag_matches
from thermcap.api.reading.frame_columns import FrameColumns, FrameColumnsCache
from thermcap.api.reading.zip_index import ArchiveLocations
from thermcap.api.security import given_token, scopes_for_token
from thermcap.archive.codecs import decode_up_png, get_codec
from thermcap.archive.formats.base import locate
from thermcap.archive.formats.tiff_lzw import decode_strip
from thermcap.archive.frame_summary import FrameSummary
from thermcap.archive.reading.mcap_frames import McapFrames
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.digest import new_hasher
from thermcap.recorder.storage.layout import DataRoot, archive_key

__all__ = ["FrameFastPath"]

# a frame, or the same counts as a chunk of the session's Zarr store (api.routes.zarr): one frame
# a chunk, numbered as the index numbers frames
_PATH = re.compile(r"/api/v1/sessions/([A-Za-z0-9][A-Za-z0-9_.-]{0,127})/"
                   r"(?:frames/([0-9]{1,9})|zarr/counts/([0-9]{1,9})\.0\.0)")
CHECK_S = 2.0  # how stale a session's cached locations may be before its index row is looked at again
_PNG16 = get_codec("png16")


def _raw_headers(pixels: np.ndarray) -> list[tuple[bytes, bytes]]:
    """The route's headers for a frame's raw counts."""
    h, w = pixels.shape
    return [(b"content-type", b"application/octet-stream"), (b"x-width", str(w).encode()),
            (b"x-height", str(h).encode()), (b"x-dtype", b"uint16le")]


class _Route:
    path = "/api/v1/sessions/{session_id}/frames/{n}"


_ROUTE = _Route()


@dataclass
class _Session:
    indexed_at: int
    frames: int
    columns: FrameColumns  # each frame's log time, MCAP segment and pixel hash
    checked: float
    tiff: list[dict[str, Any]]  # tiff-lzw files ({path: key, frames}), in session order
    summary: str | None  # the index's entry for archive/summary.npz (JSON), if the archive has one


@dataclass
class _Pages:
    """A multi-page LZW TIFF's strips, from its IFDs: what a page's rows need, without tifffile."""

    offsets: list[tuple[int, ...]]
    counts: list[tuple[int, ...]]
    rows_per_strip: list[int]
    shape: list[tuple[int, int]]
    predictor: list[int]


class FrameFastPath:
    def __init__(self, app: Any, *, engine: Engine, root: Path, store_kind: str, tokens: dict[str, frozenset[str]],
                 locations: ArchiveLocations, state: Any = None, keep_sessions: int = 16, keep_files: int = 64) -> None:
        self.app, self.engine, self.root, self.tokens = app, engine, Path(root), tokens
        self._cache_control = cache_control(Kind.FIXED, guarded=bool(tokens)).encode()  # counts only, here
        self.locations = locations  # the frame reader's: one cache of central directories
        self._state = state  # the application's, for its frame summaries (state.regions)
        if state is not None:
            state.fast_frames = self  # for /metrics-style counts and the tests
        self.local = store_kind == "local"
        self._sessions: OrderedDict[str, _Session] = OrderedDict()
        self._fds: OrderedDict[str, int] = OrderedDict()
        self._keep_sessions, self._keep_files = keep_sessions, keep_files
        self._lock = threading.Lock()
        self._pages: OrderedDict[str, _Pages | None] = OrderedDict()
        self._pool = ThreadPoolExecutor(2, thread_name_prefix="thermcap-strips")
        self._segment_pool = ThreadPoolExecutor(4, thread_name_prefix="thermcap-segments")
        frames = getattr(state, "frames", None)
        self._mcap: McapFrames | None = getattr(frames, "mcap", None)  # the application's, where there is one
        self._columns: FrameColumnsCache | None = getattr(frames, "columns", None)
        self.served = 0  # requests answered here (the rest went to the application)
        #: raw answers by where the counts came from: the PNG's own IDAT undone here (``png-up``,
        #: the fast one), the tiff-lzw strips, or libpng (a PNG another writer made)
        self.raw_from: Counter[str] = Counter()
        #: how raw answers were proved: ``crc32`` against the frame summary's band checksums,
        #: or ``blake3``/``sha256`` against the frame's digest (no summary, or one for another shape)
        self.raw_checked: Counter[str] = Counter()

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        request = self._plain_frame_request(scope) if self.local else None
        if request is None:
            await self.app(scope, receive, send)
            return
        sid, n, fmt, inm = request
        scope["route"] = _ROUTE  # the metrics count it under the route's own template
        # In the event loop, raw too: a PNG is a pread and a CRC, raw 1.5 ms more of mostly
        # GIL-free work, and a thread hand-off cost raw 1 ms at p50 and 11% of its throughput
        # with four clients (bench api)
        answer = self._answer(sid, n, fmt)
        if callable(answer):  # the frame's chunk must be read and decompressed first: off the event loop
            answer = await asyncio.get_running_loop().run_in_executor(self._segment_pool, answer)
        if answer is None:
            await self.app(scope, receive, send)
            return
        body, etag, headers = answer
        self.served += 1
        headers = [*headers, (b"etag", etag), (b"cache-control", self._cache_control)]
        if etag_matches(inm, etag):
            await send({"type": "http.response.start", "status": 304, "headers": headers})
            await send({"type": "http.response.body", "body": b""})
            return
        headers.append((b"content-length", str(len(body)).encode()))
        await send({"type": "http.response.start", "status": 200, "headers": headers})
        await send({"type": "http.response.body", "body": b"" if scope["method"] == "HEAD" else body})

    def _plain_frame_request(self, scope: dict) -> tuple[str, int, str, bytes | None] | None:
        if scope["type"] != "http" or scope["method"] not in ("GET", "HEAD"):
            return None
        m = _PATH.fullmatch(scope["path"])
        if m is None:
            return None
        query = dict(parse_qsl(scope.get("query_string", b"").decode("latin-1"), keep_blank_values=True))
        fmt = "raw" if m.group(3) else query.pop("format", "png16")
        if query or fmt not in ("png16", "raw"):
            return None
        headers = dict(scope.get("headers", []))
        if b"origin" in headers:  # CORS answers belong to the application's middleware
            return None
        if self.tokens:
            given = given_token(headers.get(b"authorization", b"").decode("latin-1"),
                                 headers.get(b"cookie", b"").decode("latin-1"))
            scopes = scopes_for_token(self.tokens, given)
            if scopes is None or "read" not in scopes:
                return None  # the application says 401 or 403, as always
        return m.group(1), int(m.group(2) or m.group(3)), fmt, headers.get(b"if-none-match")

    def _answer(self, sid: str, n: int, fmt: str) -> Any:
        """(body, ETag, headers); None for the full application; or, for a frame whose chunk is
        not kept, the call that answers it, to be run on a thread."""
        s = self._session(sid)
        if s is None or not 0 <= n < s.frames:
            return None
        blob = self.locations.blob(sid, "png16", n)
        if blob is None:
            if fmt != "raw":  # a PNG made on request costs more than the layers skipped
                return None
            mcap, segment = self._mcap, s.columns.segment(n)
            if mcap is None or not segment:
                return None
            path, log_time = DataRoot.of(self.root).session_dir(sid) / segment, int(s.columns.timestamp_ns[n])
            if not path.is_file():  # e.g. deleted once archived
                return None
            read = functools.partial(self._from_segment, mcap, path, log_time, s.columns.digest,
                                     s.columns.pixel_digest_raw(n))
            return read() if mcap.is_kept(path, log_time) else read
        data = self._read(archive_key(sid, "png16", blob["file"]), blob["offset"], blob["length"])
        if data is None or imagecodecs.deflate_crc32(data) != blob["crc32"]:
            return None  # missing or damaged: the full path reports it and serves another copy
        if fmt == "png16":
            return data, body_etag(data).encode(), [(b"content-type", b"image/png")]
        want, name = s.columns.pixel_digest_raw(n), s.columns.digest
        if want is None:
            return None
        summary = self._summary(sid, s, n)
        for source, decode in (("png-up", lambda: decode_up_png(data)), ("strips", lambda: self._tiff_pixels(s, n)),
                               ("libpng", lambda: _PNG16.decode(data))):
            got = decode()
            if got is None:
                continue
            pixels = np.ascontiguousarray(got, dtype="<u2")
            if summary is not None and pixels.shape == (summary.height, summary.width):
                ok, proof = summary.rows_intact(n, 0, pixels), "crc32"
            else:
                h = new_hasher(name)
                h.update(pixels.data.cast("B"))
                ok, proof = h.digest() == want, name
            if ok:
                self.raw_from[source] += 1
                self.raw_checked[proof] += 1
                break
        else:
            return None  # no copy here proves itself: the full path reports and tries the others
        body = pixels.tobytes()  # proved equal to the frame ``want`` names (by its hash, or the band CRCs)
        return body, body_etag(body, (name, want.hex())).encode(), _raw_headers(pixels)

    def _from_segment(self, mcap: McapFrames, path: Path, log_time: int, name: str,
                      want: bytes | None) -> tuple[bytes, bytes, list[tuple[bytes, bytes]]] | None:
        """A frame's raw counts from its MCAP segment, as the route answers them. Damage, a
        segment gone, a frame not there or counts that differ from the index's digest (``want``,
        by hash ``name``): None, and the full application says what happened or serves another
        copy."""
        try:
            pixels, _ = mcap.frame(path, log_time)
        except (McapFileError, OSError):
            return None
        if pixels is None:
            return None
        body = np.ascontiguousarray(pixels, dtype="<u2").tobytes()
        h = new_hasher(name)
        h.update(body)
        if want is not None and h.digest() != want:
            return None
        with self._lock:  # this may run on a thread of the segment pool
            self.raw_from["mcap"] += 1
        return body, body_etag(body, (name, h.hexdigest())).encode(), _raw_headers(pixels)

    def _summary(self, sid: str, s: _Session, n: int) -> FrameSummary | None:
        """The archive's frame summary where it covers frame ``n``: its band CRC-32s were taken
        from the source on the archive's one read, and it is itself checked against the
        manifest's digest before it is trusted (``RegionReader``), so decoded counts that match
        it are the source's. 8 CRC-32s of a 640x512 frame cost 0.16 ms where its sha256 costs
        0.38 ms."""
        regions = getattr(self._state, "regions", None)
        summary = regions.summary(sid, s.summary) if regions is not None and s.summary else None
        return summary if summary is not None and 0 <= n < summary.frames else None

    def _tiff_pixels(self, s: _Session, n: int) -> np.ndarray | None:
        try:
            key, k = locate(s.tiff, n)
        except IndexError:
            return None
        pages = self._tiff_pages(key)
        if pages is None or k >= len(pages.offsets):
            return None
        try:
            return self._strips(key, pages, k)
        except Exception:  # a damaged strip: the PNG, then the digest, decide
            return None

    def _strips(self, key: str, pages: _Pages, k: int) -> np.ndarray | None:
        h, w = pages.shape[k]
        rps, predictor = pages.rows_per_strip[k], pages.predictor[k]
        out = np.empty((h, w), np.uint16)

        def strip(i: int) -> None:
            data = self._read(key, pages.offsets[k][i], pages.counts[k][i])
            if data is None:
                raise OSError(f"{key}: strip {i} of page {k} is short")
            rows = min(rps, h - i * rps)
            out[i * rps:i * rps + rows] = decode_strip(data, rows, w, predictor, f"{key}: page {k}, strip {i}")

        list(self._pool.map(strip, range(len(pages.offsets[k]))))
        return out

    def _tiff_pages(self, key: str) -> _Pages | None:
        with self._lock:
            if key in self._pages:
                self._pages.move_to_end(key)
                return self._pages[key]
        got: _Pages | None = _Pages([], [], [], [], [])
        try:
            with tifffile.TiffFile(self.root / key) as tif:
                for page in tif.pages:
                    if not isinstance(page, tifffile.TiffPage) or page.compression != 5 \
                            or page.dtype != np.uint16 or page.samplesperpixel != 1:
                        got = None
                        break
                    assert got is not None
                    got.offsets.append(tuple(page.dataoffsets))
                    got.counts.append(tuple(page.databytecounts))
                    got.rows_per_strip.append(int(page.rowsperstrip))
                    got.shape.append((int(page.shape[0]), int(page.shape[1])))
                    got.predictor.append(int(page.predictor))
        except (OSError, ValueError, tifffile.TiffFileError):
            got = None
        with self._lock:
            self._pages[key] = got
            while len(self._pages) > self._keep_files:
                self._pages.popitem(last=False)
        return got

    def _read(self, key: str, offset: int, length: int) -> bytes | None:
        with self._lock:
            fd = self._fds.get(key)
            if fd is not None:
                self._fds.move_to_end(key)
        if fd is None:
            try:
                fd = os.open(self.root / key, os.O_RDONLY)
            except OSError:
                return None
            with self._lock:
                self._fds[key] = fd
                while len(self._fds) > self._keep_files:
                    os.close(self._fds.popitem(last=False)[1])
        try:
            data = os.pread(fd, length, offset)
        except OSError:
            return None
        return data if len(data) == length else None

    def _session(self, sid: str) -> _Session | None:
        now = time.monotonic()
        with self._lock:
            s = self._sessions.get(sid)
            if s is not None and now - s.checked < CHECK_S:
                self._sessions.move_to_end(sid)
                return s
        with self.engine.connect() as conn:
            row = conn.execute(select(db.sessions.c.indexed_at, db.sessions.c.frames, db.sessions.c.summary)
                               .where(db.sessions.c.id == sid)).first()
            if row is None:
                return None
            if s is not None and s.indexed_at == row[0]:
                s.checked = now
                return s
            tiff_files = conn.execute(select(db.archives.c.files).where(
                db.archives.c.session_id == sid, db.archives.c.format == "tiff-lzw",
                db.archives.c.verified.is_(True))).scalar()
        if self._columns is None:
            return None
        try:
            cols = self._columns.get(sid)
        except LookupError:  # no frame table yet: the application answers (and says why)
            return None
        frames = min(int(row[1]), len(cols))
        tiff = [{"path": archive_key(sid, "tiff-lzw", r["path"]), "frames": int(r["frames"])}
                for r in json.loads(tiff_files)] if tiff_files else []
        s = _Session(int(row[0]), frames, cols, now, tiff, row[2])
        with self._lock:
            self._sessions[sid] = s
            while len(self._sessions) > self._keep_sessions:
                self._sessions.popitem(last=False)
        return s
