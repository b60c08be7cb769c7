"""A session read straight from the bucket ``thermcap upload`` wrote, with no server.

The bucket holds what ``upload`` sends: each verified archive file, the manifest (every frame's
time and digest, which formats hold it), ``extras.mcap`` (the sidecars, the bad-pixel map) and
the session's own small documents (``session.json``, ``events.json``, ``radiometry.json``, as of
the last upload). A frame is read from the first archive copy that has it, by ranged reads, and
checked against the manifest's digest before it is returned: a damaged object is skipped for the
next copy, never returned.
"""

from __future__ import annotations

import io
import json
from functools import cached_property
from typing import TYPE_CHECKING, Any
from urllib.parse import urlparse

import numpy as np

from thermcap.archive.formats.base import read_cost
from thermcap.archive.reading.copies import DamageLog, Part, counts_of, sidecar_of
from thermcap.recorder.radiometry.params import ModelVersion
from thermcap.recorder.settings import BucketSettings
from thermcap.recorder.storage.layout import RADIOMETRY_JSON, session_key
from thermcap.session import Session

if TYPE_CHECKING:
    from thermcap.archive.blobs import BlobStore
    from thermcap.archive.reading.frame_table import FrameTable

__all__ = ["BucketSession", "open_bucket_session"]


def open_bucket_session(url: str, *, endpoint: str | None = None, region: str | None = None) -> BucketSession:
    """``s3://BUCKET[/PREFIX]/sessions/ID``: the bucket's endpoint from ``endpoint`` or
    ``THERMCAP_S3_ENDPOINT``, credentials from ``AWS_ACCESS_KEY_ID`` / ``AWS_SECRET_ACCESS_KEY``."""
    from pathlib import Path

    from thermcap.archive.blobs import open_store
    from thermcap.recorder.storage.layout import check_session_name

    parts = urlparse(url)
    path = parts.path.strip("/").split("/")
    if parts.scheme != "s3" or not parts.netloc or len(path) < 2 or path[-2] != "sessions" or not path[-1]:
        raise ValueError(f"{url}: a session in a bucket looks like s3://BUCKET/sessions/ID "
                         f"(or s3://BUCKET/PREFIX/sessions/ID, as THERMCAP_S3_PREFIX uploaded it)")
    session_id = check_session_name(path[-1])
    where = BucketSettings.from_env()
    store = open_store(Path("."), bucket=parts.netloc, endpoint=endpoint or where.endpoint,
                       region=region or where.region,
                       prefix="/".join(path[:-2]))
    return BucketSession(store, session_id, url)


class BucketSession(Session):
    """A session in a bucket: its manifest, its documents, its frames from the archive objects."""

    def __init__(self, store: BlobStore, session_id: str, url: str = "") -> None:
        self.store, self.id, self.url = store, session_id, url or f"{store.url}/sessions/{session_id}"
        self._base = session_key(session_id)
        manifest = self._document("archive/manifest.json")
        if manifest is None:
            raise FileNotFoundError(f"{self.url}: no session here (no archive/manifest.json; `thermcap upload` "
                                    f"puts one beside the archive)")
        self.manifest: dict[str, Any] = manifest
        recorded = self._document("session.json") or {}
        self.meta = {**(manifest.get("session") or {}), **recorded, "session_id": session_id}
        source = manifest.get("source") or {}
        self.width, self.height = int(source.get("width") or 0), int(source.get("height") or 0)
        from thermcap.recorder.storage.digest import frame_proof

        self._proof = frame_proof(manifest.get("frames"))  # the per-frame digests, under the hash they name
        from thermcap.archive.reading.numbering import verified_copies

        # the copies offered whole, ordered by their declared read cost when a frame is read
        self._copies = [(f, e) for f, e in verified_copies(manifest).items() if e.get("files")]
        self.damage = DamageLog()  # damaged objects met while reading: logged and kept, bounded

    def __repr__(self) -> str:
        return f"<BucketSession {self.url!r}: {len(self)} frames, {self.width}x{self.height}>"

    # -- the bucket's documents -----------------------------------------------------------------
    def _key(self, rel: str) -> str:
        return f"{self._base}/{rel}"

    def _document(self, rel: str) -> Any:
        head = self.store.head(self._key(rel))
        if head is None:
            return None
        data = self.store.get_range(self._key(rel), 0, int(head["size"]))
        try:
            return json.loads(data)
        except ValueError as exc:
            raise ValueError(f"{self.url}/{rel}: not valid JSON ({exc})") from None

    def _object(self, rel: str) -> Any:
        """A bucket object as a seekable file, read by ranges."""
        from thermcap.archive.blobs import BlobFile

        head = self.store.head(self._key(rel))
        if head is None:
            raise FileNotFoundError(f"{self.url}/{rel} is not in the bucket")
        return io.BufferedReader(BlobFile(self.store, self._key(rel), int(head["size"])), buffer_size=256 * 1024)

    # -- what every session offers --------------------------------------------------------------
    @cached_property
    def _sidecars(self) -> list[dict[str, Any]]:
        """Every frame's sidecar from extras.mcap (one pass over it), in frame order; empty where
        the bucket has none."""
        from mcap.reader import make_reader

        from thermcap.recorder.icd.rosmsg import json_payload
        from thermcap.recorder.icd.topics import TOPIC_METADATA

        if not (self.manifest.get("extras") or {}).get("path"):
            return []
        try:
            with self._object("archive/" + self.manifest["extras"]["path"]) as f:
                return [json.loads(json_payload(ch.message_encoding, msg.data)) for _, ch, msg in
                        make_reader(f, validate_crcs=True).iter_messages(topics=[TOPIC_METADATA])]
        except FileNotFoundError:
            return []

    @cached_property
    def table(self) -> FrameTable:
        from thermcap.archive.reading.numbering import table_of

        times = [int(t) for t in (self.manifest.get("frames") or {}).get("timestamps_ns") or []]
        return table_of(self.id, times, self._sidecars if len(self._sidecars) == len(times) else [])

    def _verified(self, index: int, part: Part) -> Any:
        from thermcap.archive.formats import get_format
        from thermcap.archive.reading.copies import Copy, in_read_order, read_verified, wanted

        n = len(self._proof.pixels)
        if not 0 <= index < n:
            raise IndexError(f"frame {index}: session {self.id!r} has {n} frames")
        copies = []
        for fmt, entry in self._copies:
            def read(part: Part, fmt: str = fmt, entry: dict[str, Any] = entry) -> Any:
                frame = get_format(entry.get("config") or fmt).read_frame(
                    lambda rel: self._object(f"archive/{fmt}/{rel}"), entry["files"], index)
                return frame.pixels if part == "pixels" else frame.sidecar
            copies.append(Copy(fmt, read_cost(fmt), read))
        return read_verified(in_read_order(copies), part, session_id=self.id, frame=index,
                             want=wanted(self._proof, index, part), hash_name=self._proof.name, damage=self.damage,
                             where=self.url)

    def counts(self, index: int) -> np.ndarray:
        return counts_of(self._verified(index, "pixels"))

    def sidecar(self, index: int) -> dict[str, Any]:
        return sidecar_of(self._verified(index, "sidecar"))

    @cached_property
    def events(self) -> list[dict[str, Any]]:
        doc = self._document("events.json") or {}
        return sorted(doc.get("events") or [], key=lambda e: (e.get("start_ns") or 0))

    @cached_property
    def model_versions(self) -> list[ModelVersion]:
        from thermcap.recorder.radiometry.params import versions_from

        return versions_from(self._document(RADIOMETRY_JSON) or {})

    @cached_property
    def bad_pixel_map(self) -> np.ndarray | None:
        from thermcap.recorder.radiometry.session import bad_pixel_mask

        path = (self.manifest.get("extras") or {}).get("path")
        if not path:
            return None
        try:
            with self._object("archive/" + path) as f:
                return bad_pixel_mask(f)
        except FileNotFoundError:
            return None

    def temperatures(self, model_version: int | None = None, bad_pixels: str = "nan") -> Any:
        """The ``SessionTemperatures`` every temperature of this session is computed with (the
        model versions and the bad-pixel map as of the last upload)."""
        from thermcap.recorder.radiometry.base import model_from_dict
        from thermcap.recorder.radiometry.session import SessionTemperatures

        return SessionTemperatures(model_from_dict(self.radiometric_model), self.model_versions,
                                   self.bad_pixel_map if bad_pixels == "nan" else None,
                                   version=model_version, bad_pixels=bad_pixels)

    def temperature(self, index: int, model_version: int | None = None) -> np.ndarray:
        """Frame ``index`` in °C (float32), bad pixels NaN."""
        return self.temperatures(model_version).celsius(index, self.counts(index)).celsius

    def to_xarray(self, model_version: int | None = None, *, chunk_frames: int | None = None) -> Any:
        from thermcap.session import lazy_dataset

        return lazy_dataset(self, self.temperatures(model_version), model_version, chunk_frames)
