"""``thermcap gc``: retention that never deletes the last good copy.

What may go, per session, oldest first, by age and/or total size:

- the MCAP segments, once every requested archive format and ``extras.mcap`` verified and their
  files still hash to the manifest (the archive covers the source);
- the whole local folder (archives included), only once the upload to the object store is
  complete and every uploaded object is there at its archived size (the bucket covers it).

A session with protected event windows (``protected.json``: marks and triggers) is kept whole
unless ``include_protected``. Each session is handled under its lock, so a session being
recorded, recovered, archived or analysed is never touched. A dry run lists every deletion with what it relies on.
"""

from __future__ import annotations

import contextlib
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from thermcap.api.storage import BlobStore
from thermcap.archive.archiver import DEFAULT_FORMATS
from thermcap.archive.blobs import stored_digest
from thermcap.archive.evidence import local_cover
from thermcap.archive.manifest import archived_files, iso_now, load_manifest, save_manifest
from thermcap.archive.manifest_types import Manifest
from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.lock import holder, lock_session
from thermcap.recorder.storage.reader import list_sessions, read_session_meta
from thermcap.recorder.storage.ring import load_windows
from thermcap.recorder.storage.rosbag2 import write_bag_metadata

__all__ = ["GcDecision", "GcResult", "gc_sessions"]


@dataclass
class GcDecision:
    session: str
    started_ns: int
    bytes: int
    action: str  # "delete-source", "delete-local", "keep"
    frees: int = 0
    relies_on: list[str] = field(default_factory=list)
    why_kept: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class GcResult:
    dry_run: bool
    decisions: list[GcDecision]
    bytes_remaining: int

    @property
    def deleted(self) -> list[GcDecision]:
        return [d for d in self.decisions if d.action != "keep" and d.frees]

    def to_dict(self) -> dict[str, Any]:
        return {"dry_run": self.dry_run, "deleted": [d.session for d in self.deleted],
                "bytes_freed": sum(d.frees for d in self.deleted), "bytes_remaining": self.bytes_remaining,
                "decisions": [d.to_dict() for d in self.decisions],
                "kept_unverified": [d.session for d in self.decisions if d.action == "keep"]}


def _documents_uploaded(session_dir: Path, store: BlobStore, root: Path) -> str | None:
    """Why the session's own documents in the store are not the folder's (None: they are). A
    model version added after the upload lives in ``radiometry.json`` alone: deleting the folder
    on the archive objects' word would lose it."""
    from thermcap.archive.blobs import session_documents

    for path, key in session_documents(root, session_dir):
        head = store.head(key)
        local = path.read_bytes()
        if head is None or int(head["size"]) != len(local) or store.get_range(key, 0, len(local)) != local:
            return (f"{path.name} changed since the upload (or was never sent): `thermcap upload` again before "
                    f"the folder goes")
    return None


def _bucket_cover(m: Manifest, store: BlobStore | None, session_dir: Path | None = None,
                  root: Path | None = None) -> tuple[list[str], str | None]:
    """(what deleting the local folder relies on, or why it cannot go). The upload hashed each
    object as the store gave it back and kept its ETag; now every object must still be there at
    its size and with that ETag (the same object, not rewritten since), every archive file must
    hash, read back now, to the digest it was verified with (a store can rot a byte under an
    unchanged HEAD), and scrub must not have found any of them damaged. A manifest's word alone,
    with no store to ask, is not enough."""
    up = m.get("upload") or {}
    if not up.get("complete"):
        return [], "not uploaded to the object store"
    if store is None:
        return [], "an upload is recorded, but no store is configured to recheck it (THERMCAP_S3_BUCKET)"
    if up.get("damaged"):
        return [], f"scrub found {len(up['damaged'])} damaged objects in the store"
    files = {f.rel: f for f in archived_files(m)}
    sizes = {rel: f.bytes for rel, f in files.items()}
    etags = up.get("etags") or {}
    keys = up.get("keys", [])
    read_back = 0
    for key in keys:
        rel = key.split("/archive/", 1)[-1]
        head = store.head(key)
        if head is None or (rel in sizes and head["size"] != sizes[rel]):
            return [], f"object {key} is missing from the store or has another size"
        if key in etags and str(head.get("e_tag")) != etags[key]:
            return [], f"object {key} was rewritten since it was uploaded and hashed (ETag differs)"
        if rel in files:  # the archive's own files: their bytes, read back now, must hash as verified
            f = files[rel]
            try:
                got = stored_digest(store, key, f.digest)
            except Exception as exc:  # the store's own check failed, or the link: no evidence either way
                return [], f"object {key} cannot be read back now ({type(exc).__name__}: {str(exc)[:200]})"
            if got != f.hex:
                return [], (f"object {key}'s bytes no longer hash as when they were verified (the store's copy "
                            "is damaged)")
            read_back += 1
    missing = [rel for rel in sizes if not any(k.endswith("/archive/" + rel) for k in keys)]
    if missing:
        return [], f"{len(missing)} archived files were never uploaded ({missing[0]}, ...)"
    if session_dir is not None and root is not None and store.kind == "s3":
        why = _documents_uploaded(session_dir, store, root)
        if why is not None:
            return [], why
    return [f"{len(keys)} objects in the {store.kind} store, sizes and ETags rechecked, the {read_back} archive files "
            f"read back and hashed, the session's documents compared"], None


def gc_sessions(root: Path, *, keep_days: float | None, max_bytes: int | None, require_upload: bool,
                dry_run: bool, store: BlobStore | None = None, include_protected: bool = False) -> GcResult:
    sessions = []
    for d in list_sessions(root):
        meta = read_session_meta(d)
        size = sum(p.stat().st_size for p in d.rglob("*") if p.is_file())
        sessions.append((int(meta.get("started_ns") or 0), d, size))
    sessions.sort(key=lambda r: r[0])
    total = sum(s for _, _, s in sessions)
    now = time.time_ns()
    decisions = []
    for started, d, size in sessions:
        too_old = keep_days is not None and started < now - keep_days * 86400e9
        if not too_old and not (max_bytes is not None and total > max_bytes):
            continue
        decision = _decide_and_act(d, started, size, require_upload, dry_run, store, include_protected)
        decisions.append(decision)
        total -= decision.frees
    return GcResult(dry_run, decisions, total)


def _decide_and_act(d: Path, started: int, size: int, require_upload: bool, dry_run: bool,
                    store: BlobStore | None, include_protected: bool) -> GcDecision:
    decision = GcDecision(str(d), started, size, "keep")
    lock = lock_session(d, "gc", wait_s=0.0)
    if lock is None:
        decision.why_kept = f"{holder(d) or 'another process'} is working on it"
        return decision
    try:
        layout = SessionLayout.of(d)
        if layout.active_segments():
            decision.why_kept = "unfinished segments (*.active): run `thermcap recover`"
            return decision
        windows = load_windows(d)
        if windows and not include_protected:
            decision.why_kept = (f"{len(windows)} event windows are protected (protected.json); "
                                 f"--include-protected lets them go")
            return decision
        try:
            m = load_manifest(d, required=False)
        except ThermcapError as exc:
            decision.why_kept = str(exc)
            return decision
        if m is None:
            decision.why_kept = "not archived"
            return decision
        relies, why = _bucket_cover(m, store, d, d.parent.parent)
        if why is None:
            decision.action, decision.relies_on, decision.frees = "delete-local", relies, size
            if not dry_run:
                shutil.rmtree(d)
            return decision
        if require_upload:
            decision.why_kept = why
            return decision
        segments = layout.segments()
        if not segments:
            decision.why_kept = "only the archive is left (the last copy); upload it to free more"
            return decision
        cover = local_cover(layout, m, m.get("requested_formats") or list(DEFAULT_FORMATS))
        if not cover.ok:
            decision.why_kept = "; ".join(cover.problems[:3])
            return decision
        decision.action, decision.relies_on = "delete-source", cover.relies_on
        decision.frees = sum(p.stat().st_size for p in segments)
        if not dry_run:
            for seg in segments:
                seg.unlink()
            with contextlib.suppress(OSError):  # derived data: a failure must not undo the work above
                write_bag_metadata(d)
            m["source"]["deleted"] = True
            m["source"]["deleted_at"] = iso_now()
            m["source"]["deleted_by"] = "gc"
            save_manifest(d, m)
        return decision
    finally:
        lock.release()
