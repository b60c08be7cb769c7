"""The cloud's side of ``thermcap sync``: re-read every segment a vehicle shipped, re-hash every
frame, and write a receipt the vehicle checks before it frees anything.

A receipt (``receipts/<key>.json``) names the bytes the store holds (size and sha256, hashed
here from what was read back, not taken from the vehicle's word) and says whether the segment
is a whole MCAP whose summary counts the frames its data holds. The vehicle confirms a segment
only when the receipt's size and sha256 are its own; a receipt for other bytes makes it send the
segment again. A segment already receipted is not read again.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from thermcap.archive.blobs import BlobStore
from thermcap.archive.manifest import file_sha256, frame_sha256, iso_now
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage.layout import SESSIONS_PREFIX
from thermcap.recorder.storage.reader import iter_segment_frames, segment_span
from thermcap.recorder.sync.targets import RECEIPTS_PREFIX, receipt_key

__all__ = ["ConfirmReport", "check_segment", "confirm_synced"]


@dataclass
class ConfirmReport:
    receipted: list[str] = field(default_factory=list)
    damaged: dict[str, str] = field(default_factory=dict)
    already: int = 0


def check_segment(path: Path) -> dict[str, Any]:
    """What a receipt says of one MCAP segment file."""
    out: dict[str, Any] = {"bytes": path.stat().st_size, "sha256": file_sha256(path)}
    frames = hashlib.sha256()
    n = 0
    try:
        _, _, counted = segment_span(path)
        for fr in iter_segment_frames(path):
            frames.update((frame_sha256(fr.pixels) + hashlib.sha256(fr.sidecar).hexdigest()).encode()
                          + fr.log_time.to_bytes(8, "little"))
            n += 1
    except McapFileError as exc:
        return {**out, "ok": False, "problem": str(exc).replace(str(path), path.name)}
    if n != counted:
        return {**out, "ok": False, "frames": n, "problem": f"its summary counts {counted} frames, its data holds {n}"}
    return {**out, "ok": True, "frames": n, "frames_sha256": frames.hexdigest()}


def _still_holds(store: BlobStore, rkey: str, head: dict[str, Any]) -> bool:
    """Whether an existing receipt still speaks for the object as it is now: it said the bytes
    were good, and the object has the size and ETag it had then. A receipt for damaged bytes is
    never final: the vehicle sends the segment again, and the new bytes are checked anew."""
    try:
        receipt = json.loads(b"".join(store.iter_bytes(rkey)))
    except FileNotFoundError:
        return False
    except ValueError:
        return False  # an unreadable receipt is written again
    if not receipt.get("ok") or receipt.get("bytes") != head.get("size"):
        return False
    etag = receipt.get("etag")
    return not etag or etag == str(head.get("e_tag") or "")


def confirm_synced(store: BlobStore, prefix: str = SESSIONS_PREFIX) -> ConfirmReport:
    report = ConfirmReport()
    for key in sorted(k for k, _ in store.list(prefix)):
        if not key.endswith(".mcap") or "/archive/" in key or key.startswith(RECEIPTS_PREFIX + "/"):
            continue
        rkey = receipt_key(key)
        head = store.head(key)
        if head is None:
            continue  # removed while we listed
        if _still_holds(store, rkey, head):
            report.already += 1
            continue
        with tempfile.TemporaryDirectory() as tmp:
            local = Path(tmp) / Path(key).name
            with open(local, "wb") as f:
                for block in store.iter_bytes(key):
                    f.write(block)
            receipt = {"key": key, **check_segment(local), "etag": str(head.get("e_tag") or ""),
                       "checked_at": iso_now(), "by": "thermcap sync-confirm"}
        store.put_bytes(rkey, json.dumps(receipt, indent=1).encode())
        if receipt["ok"]:
            report.receipted.append(key)
        else:
            report.damaged[key] = receipt["problem"]
    return report
