"""Synced sessions landed in the cloud's data root, where the workers archive them.

Why: a vehicle ships its sessions to a bucket, but archiving reads a session folder on a disk the
workers see. ``land_synced`` brings a session down once all of it has arrived and been
receipted:

- its ``session.json`` says it ended (complete, recovered or failed);
- every segment it lists has a good receipt (``thermcap sync-confirm``) for the bytes the bucket
  holds, bar as many as its ring says it evicted before they could ship.

Each file is downloaded into ``sessions/<id>.partial/``, which no reader takes for a session.
Every segment is hashed on the way and compared with its receipt. Only when all of it is there
does the folder take its name. A session that is still arriving waits, and says why.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from thermcap.archive.blobs import BlobStore
from thermcap.recorder.exceptions import SessionBusyError
from thermcap.recorder.storage.atomic import fsync_dir
from thermcap.recorder.storage.layout import PARTIAL_SUFFIX, SESSION_JSON, SESSIONS_PREFIX, DataRoot
from thermcap.recorder.storage.lock import holder, lock_session
from thermcap.recorder.sync.targets import receipt_key

__all__ = ["LandReport", "land_synced"]

_FINISHED = ("complete", "recovered", "failed")


@dataclass
class LandReport:
    landed: list[str] = field(default_factory=list)
    waiting: dict[str, str] = field(default_factory=dict)  # session -> why not yet
    damaged: dict[str, str] = field(default_factory=dict)  # session -> what differs from its receipts
    already: int = 0


def _read_json(store: BlobStore, key: str) -> dict | None:
    head = store.head(key)
    if head is None:
        return None
    try:
        return json.loads(store.get_range(key, 0, head["size"]))
    except ValueError:
        return None


def land_synced(store: BlobStore, root: Path, prefix: str = SESSIONS_PREFIX) -> LandReport:
    """Land every whole, receipted session in ``root/sessions``, one landing at a time: two at
    once would download the same session into the same ``.partial`` folder, and one could give
    the other's half-written folder the session's name. Raises SessionBusyError naming the
    holder while another landing holds the root's lock."""
    root.mkdir(parents=True, exist_ok=True)
    lock = lock_session(root, "landing", wait_s=0.0)
    if lock is None:
        raise SessionBusyError(f"{root}: {holder(root) or 'another process'} is landing sessions here; "
                               "try again when it is done")
    try:
        return _land(store, root, prefix)
    finally:
        lock.release()


def _land(store: BlobStore, root: Path, prefix: str) -> LandReport:
    report = LandReport()
    by_session: dict[str, dict[str, int]] = {}
    for key, size in store.list(prefix):
        parts = key[len(prefix):].split("/")
        if len(parts) == 2 and parts[1]:  # sessions/<id>/<file>: not the archive, not the receipts
            by_session.setdefault(parts[0], {})[parts[1]] = size
    for sid, files in sorted(by_session.items()):
        final = DataRoot.of(root).session_dir(sid)
        if final.exists():
            report.already += 1
            continue
        why = _not_ready(store, prefix, sid, files)
        if why:
            report.waiting[sid] = why
            continue
        try:
            _download(store, prefix, sid, files, final)
        except ValueError as exc:  # the bucket's copy changed since its receipt: not landed, said
            report.damaged[sid] = str(exc)
            continue
        report.landed.append(sid)
    return report


def _not_ready(store: BlobStore, prefix: str, sid: str, files: dict[str, int]) -> str | None:
    meta = _read_json(store, f"{prefix}{sid}/{SESSION_JSON}")
    if meta is None:
        return "no session.json yet"
    if meta.get("status") not in _FINISHED:
        return f"still {meta.get('status') or 'recording'} on the vehicle"
    evicted = int(meta.get("evicted_segments") or 0)  # the ring freed them before they could ship
    missing = []
    for seg in meta.get("segments") or []:
        name = seg.get("name")
        if not name:
            continue
        if name not in files:
            missing.append(name)
            continue
        receipt = _read_json(store, receipt_key(f"{prefix}{sid}/{name}"))
        if receipt is None:
            return f"{name} has no receipt yet (thermcap sync-confirm)"
        if not receipt.get("ok") or receipt.get("bytes") != files[name]:
            return f"{name}: its receipt is not for the bytes the bucket holds ({receipt.get('problem') or 'size'})"
    if len(missing) > evicted:
        return f"{', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''} not arrived yet"
    return None


def _download(store: BlobStore, prefix: str, sid: str, files: dict[str, int], final: Path) -> None:
    partial = final.with_name(final.name + PARTIAL_SUFFIX)
    if partial.exists():  # a landing that stopped half-way: never taken for a session
        shutil.rmtree(partial)
    partial.mkdir(parents=True)
    try:
        for name in sorted(files):
            key = f"{prefix}{sid}/{name}"
            h = hashlib.sha256()
            with open(partial / name, "wb") as f:
                for block in store.iter_bytes(key):
                    f.write(block)
                    h.update(block)
                f.flush()
                os.fsync(f.fileno())
            if name.endswith(".mcap"):
                receipt = _read_json(store, receipt_key(key)) or {}
                if receipt.get("sha256") != h.hexdigest():
                    raise ValueError(f"{key}: the bytes read now differ from the receipt's sha256")
        fsync_dir(partial)
        os.replace(partial, final)
        fsync_dir(final.parent)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
