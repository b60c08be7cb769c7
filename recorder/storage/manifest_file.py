"""The archive manifest as a file: kept twice, each copy carrying its own checksum.

The manifest proves every archived frame (its digests) and says which copies hold it; with the
source deleted, one flipped bit in it made three intact copies unreachable. So it is written
twice (``archive/manifest.json`` and ``archive/manifest.copy.json``), each with a ``checksum``
(sha256 of its canonical JSON without that field), and read from the first copy whose checksum
holds. A manifest written before checksums has none and is read as it is. Every reader of the
manifest file (the archive, the index, ``info``, ``ls``, the ledger) reads it here.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.atomic import write_json_atomic
from thermcap.recorder.storage.layout import SessionLayout

__all__ = ["ManifestFileError", "manifest_checksum", "read_manifest_file", "write_manifest_file"]

CHECKSUM = "checksum"


class ManifestFileError(McapFileError):
    """Neither copy of the manifest reads and holds its checksum."""


def manifest_checksum(doc: dict[str, Any]) -> str:
    body = {k: v for k, v in doc.items() if k != CHECKSUM}
    return "sha256:" + hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _read_one(path: Path) -> tuple[dict[str, Any] | None, str | None]:
    """(the document, or None with why not)."""
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        return None, "missing"
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        return None, f"unreadable ({exc})"
    if not isinstance(doc, dict):
        return None, "not a JSON object"
    said = doc.get(CHECKSUM)
    if said is not None and said != manifest_checksum(doc):
        return None, "its checksum does not hold (changed since it was written)"
    doc.pop(CHECKSUM, None)
    return doc, None


def read_manifest_file(session_dir: str | Path) -> dict[str, Any] | None:
    """The session's manifest from the first copy that holds; None where the session has none.
    Raises ``ManifestFileError`` naming each copy's problem where one exists and none holds."""
    layout = SessionLayout.of(Path(session_dir))
    problems = []
    for path in (layout.manifest, layout.manifest_copy):
        doc, why = _read_one(path)
        if doc is not None:
            return doc
        problems.append(f"{path.name}: {why}")
    if all(p.endswith("missing") for p in problems):
        return None
    raise ManifestFileError(f"{layout.manifest}: unreadable manifest ({'; '.join(problems)})")


def write_manifest_file(session_dir: str | Path, doc: dict[str, Any]) -> None:
    """Both copies, each atomically, each with the checksum of what it holds."""
    layout = SessionLayout.of(Path(session_dir))
    body = {k: v for k, v in doc.items() if k != CHECKSUM}
    stamped = {**body, CHECKSUM: manifest_checksum(body)}
    write_json_atomic(layout.manifest, stamped)
    write_json_atomic(layout.manifest_copy, stamped)
