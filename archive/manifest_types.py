"""The shape of ``archive/manifest.json``, for the type checker: what each block holds.

The manifest stays plain JSON on disk (readable by any tool, and by archives written before any
of these keys existed, hence ``total=False``); these TypedDicts let mypy check every access.
"""

from __future__ import annotations

from typing import Any, TypedDict

__all__ = ["Damage", "ExtrasEntry", "FileEntry", "FormatEntry", "FramesBlock", "Manifest", "SourceBlock",
           "SummaryEntry", "UploadBlock"]


class FileEntry(TypedDict, total=False):
    path: str
    frames: int
    bytes: int
    blake3: str  # the file's digest, under its hash's name (recorder.storage.digest)
    sha256: str


class Damage(TypedDict, total=False):
    at: str
    problems: list[str]


class FormatEntry(TypedDict, total=False):
    config: dict[str, Any]
    description: str
    files: list[FileEntry]
    frames_per_file: list[int]
    objects: int
    bytes: int
    compression_ratio: float | None
    bits_per_pixel: float | None
    encode_fps: float | None
    decode_fps: float | None
    library_versions: dict[str, str]
    verified: bool
    verified_at: str
    verification: str | list[str]
    damaged: Damage


class FramesBlock(TypedDict, total=False):
    # the per-frame digests under their hash's name: blake3 since 2026-12, sha256 before (frame_proof)
    blake3: list[str]
    sidecar_blake3: list[str]
    sha256: list[str]
    sidecar_sha256: list[str]
    timestamps_ns: list[int]
    segments: list[str]


class SourceBlock(TypedDict, total=False):
    segments: list[dict[str, Any]]
    frames: int
    width: int
    height: int
    raw_bytes: int
    deleted: bool
    deleted_at: str
    deleted_by: str
    kept_because: str  # why --delete-source left it (protected event windows)


class ExtrasEntry(TypedDict, total=False):
    path: str
    bytes: int
    blake3: str
    sha256: str
    verified: bool
    verification: str
    topics: dict[str, Any]
    attachments: list[dict[str, Any]]
    damaged: Damage


class SummaryEntry(TypedDict, total=False):
    path: str
    bytes: int
    blake3: str
    sha256: str
    band_rows: int
    frames: int


class UploadBlock(TypedDict, total=False):
    complete: bool
    keys: list[str]
    etags: dict[str, str]  # each object's ETag when it was read back and hashed at upload
    at: str
    store: str
    damaged: dict[str, str]
    references: dict[str, Any]  # h5 key -> its kerchunk reference file beside it (archive.hdf5_refs), or why not
    documents: list[str]  # session.json, events.json, radiometry.json sent beside the archive (overwritten)


class Manifest(TypedDict, total=False):
    manifest_version: int
    session_id: str
    created: str
    updated: str
    scrubbed_at: str
    session: dict[str, Any]
    requested_formats: list[str]
    source: SourceBlock
    frames: FramesBlock
    formats: dict[str, FormatEntry]
    extras: ExtrasEntry
    summary: SummaryEntry
    upload: UploadBlock
