"""``sessions/<id>/archive/manifest.json``: what was archived, and the hashes that prove it.

The frame hashes (sha256 of each raw frame as uint16 little-endian, row-major) come from the
MCAP source; every format is checked against them, and ``thermcap verify`` re-checks archives
against them later, when the MCAP may be gone. Files are listed with their own sha256 too, so a
flipped byte is caught before any decoding.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, cast, overload

from thermcap.archive.exceptions import ManifestError
from thermcap.archive.manifest_types import Manifest
from thermcap.recorder.storage.atomic import write_json_atomic
from thermcap.recorder.storage.digest import file_sha256, frame_sha256
from thermcap.recorder.storage.layout import MANIFEST_JSON, SessionLayout

__all__ = [
    "MANIFEST_NAME",
    "file_sha256",
    "frame_sha256",
    "iso_now",
    "load_manifest",
    "manifest_path",
    "new_manifest",
    "save_manifest",
    "sidecar_sha256",
]

MANIFEST_NAME = MANIFEST_JSON
MANIFEST_VERSION = 1


def iso_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def archive_dir(session_dir: Path) -> Path:
    return SessionLayout.of(session_dir).archive


def manifest_path(session_dir: Path) -> Path:
    return archive_dir(session_dir) / MANIFEST_NAME


def sidecar_sha256(sidecar: bytes) -> str:
    """The sidecar's hash: sha256 of its JSON bytes exactly as recorded."""
    return hashlib.sha256(sidecar).hexdigest()




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
    path = manifest_path(session_dir)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        if required:
            raise ManifestError(f"{path}: no manifest; run `thermcap archive {session_dir}` first") from None
        return None
    except (OSError, ValueError) as exc:
        raise ManifestError(f"{path}: unreadable manifest ({exc})") from exc
    if not isinstance(data, dict) or data.get("manifest_version") != MANIFEST_VERSION:
        raise ManifestError(f"{path}: not a thermcap manifest (version {data.get('manifest_version')!r})")
    return cast(Manifest, data)


@dataclass(frozen=True)
class ArchivedFile:
    """One verified file of the archive: its path under ``archive/``, size and sha256."""

    rel: str  # "png16/0000.zip", "extras.mcap"
    bytes: int
    sha256: str


def archived_files(manifest: Manifest) -> list[ArchivedFile]:
    """Every file of every verified format, extras.mcap and the frame summary: what is uploaded, and what the
    bucket must hold for gc and scrub. One list, so the three never disagree."""
    out = [ArchivedFile(f"{fid}/{rec['path']}", rec["bytes"], rec["sha256"])
           for fid, entry in manifest.get("formats", {}).items() if entry.get("verified")
           for rec in entry.get("files", [])]
    extras = manifest.get("extras") or {}
    if extras.get("verified"):  # attachments and vendor metadata travel with the frames
        out.append(ArchivedFile(extras["path"], extras["bytes"], extras["sha256"]))
    summary = manifest.get("summary") or {}
    if summary.get("sha256"):  # what region series read instead of decoding every frame
        out.append(ArchivedFile(summary["path"], summary["bytes"], summary["sha256"]))
    return out


def save_manifest(session_dir: Path, manifest: Manifest) -> None:
    manifest["updated"] = iso_now()
    write_json_atomic(manifest_path(session_dir), manifest)
