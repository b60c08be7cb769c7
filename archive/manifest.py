"""``sessions/<id>/archive/manifest.json``: what was archived, and the hashes that prove it.

The frame digests (of each raw frame as uint16 little-endian, row-major, and of its sidecar's
bytes) come from the MCAP source; every format is checked against them, and ``thermcap verify``
re-checks archives against them later, when the MCAP may be gone. Files are listed with their own
digest too, so a flipped byte is caught before any decoding. Each record names its hash by its
key (``blake3`` since 2026-12, ``sha256`` before and with ``--digest sha256``): see
``recorder.storage.digest``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, cast, overload

from thermcap.archive.exceptions import ManifestError
from thermcap.archive.manifest_types import Manifest
from thermcap.recorder.storage.digest import (
    DEFAULT_DIGEST,
    DIGESTS,
    FrameProof,
    bytes_digest,
    file_digest,
    file_sha256,
    frame_digest,
    frame_proof,
    frame_sha256,
    new_hasher,
    record_digest,
)
from thermcap.recorder.storage.layout import MANIFEST_JSON, SessionLayout
from thermcap.recorder.storage.manifest_file import ManifestFileError, read_manifest_file, write_manifest_file

__all__ = [
    "DEFAULT_DIGEST",
    "DIGESTS",
    "MANIFEST_NAME",
    "FrameProof",
    "bytes_digest",
    "digest_problem",
    "file_digest",
    "file_matches",
    "file_problem",
    "file_sha256",
    "frame_digest",
    "frame_proof",
    "frame_sha256",
    "iso_now",
    "load_manifest",
    "manifest_path",
    "new_hasher",
    "new_manifest",
    "record_digest",
    "save_manifest",
]

MANIFEST_NAME = MANIFEST_JSON
MANIFEST_VERSION = 1


def iso_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def archive_dir(session_dir: Path) -> Path:
    return SessionLayout.of(session_dir).archive


def manifest_path(session_dir: Path) -> Path:
    return archive_dir(session_dir) / MANIFEST_NAME


def file_problem(path: Path, rec: Mapping[str, Any]) -> str | None:
    """Why the file at ``path`` is not the one ``rec`` names ("missing", "<hash> differs from the
    manifest"); None when it is: its digest, by the hash the record names."""
    return digest_problem(path, record_digest(rec))


def digest_problem(path: Path, named: tuple[str, str] | None) -> str | None:
    """``file_problem`` for a (hash, hex) already taken from its record."""
    if named is None:
        return "the manifest names no digest for it"
    if not path.is_file():
        return "missing"
    return None if file_digest(path, named[0]) == named[1] else f"{named[0]} differs from the manifest"


def file_matches(path: Path, rec: Mapping[str, Any]) -> bool:
    return file_problem(path, rec) is None


def new_manifest(session_id: str, session_meta: dict[str, Any]) -> Manifest:
    keep = ("sensor", "radiometric_model", "source", "started", "software_version", "format_version")
    return {"manifest_version": MANIFEST_VERSION, "session_id": session_id, "created": iso_now(),
            "session": {k: session_meta[k] for k in keep if k in session_meta}, "source": {}, "frames": {},
            "formats": {}}


@overload
def load_manifest(session_dir: Path, *, required: Literal[True] = True) -> Manifest: ...
@overload
def load_manifest(session_dir: Path, *, required: bool) -> Manifest | None: ...
def load_manifest(session_dir: Path, *, required: bool = True) -> Manifest | None:
    """The manifest, from the first of its two copies whose checksum holds
    (``recorder.storage.manifest_file``)."""
    path = manifest_path(session_dir)
    try:
        data = read_manifest_file(session_dir)
    except ManifestFileError as exc:
        raise ManifestError(str(exc)) from exc
    if data is None:
        if required:
            raise ManifestError(f"{path}: no manifest; run `thermcap archive {session_dir}` first") from None
        return None
    if not isinstance(data, dict) or data.get("manifest_version") != MANIFEST_VERSION:
        raise ManifestError(f"{path}: not a thermcap manifest (version {data.get('manifest_version')!r})")
    return cast(Manifest, data)


@dataclass(frozen=True)
class ArchivedFile:
    """One verified file of the archive: its path under ``archive/``, size and digest."""

    rel: str  # "png16/0000.zip", "extras.mcap"
    bytes: int
    digest: str  #: the hash's name (``blake3``, ``sha256``)
    hex: str

    @property
    def named(self) -> tuple[str, str]:
        return self.digest, self.hex


def archived_files(manifest: Manifest) -> list[ArchivedFile]:
    """Every file of every verified format, extras.mcap and the frame summary: what is uploaded, and what the
    bucket must hold for gc and scrub. One list, so the three never disagree."""
    def named(rel: str, rec: Mapping[str, Any]) -> ArchivedFile:
        digest = record_digest(rec)
        if digest is None:
            raise ManifestError(f"archive/{rel}: the manifest names no digest for it")
        return ArchivedFile(rel, int(rec["bytes"]), *digest)

    out = [named(f"{fid}/{rec['path']}", rec)
           for fid, entry in manifest.get("formats", {}).items() if entry.get("verified")
           for rec in entry.get("files", [])]
    extras = manifest.get("extras") or {}
    if extras.get("verified"):  # attachments and vendor metadata travel with the frames
        out.append(named(extras["path"], extras))
    summary = manifest.get("summary") or {}
    if summary.get("path") and record_digest(summary):  # what region series read instead of decoding every frame
        out.append(named(summary["path"], summary))
    return out


def save_manifest(session_dir: Path, manifest: Manifest) -> None:
    manifest["updated"] = iso_now()
    write_manifest_file(session_dir, cast(dict, manifest))
