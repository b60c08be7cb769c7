"""``thermcap watch s3://BUCKET/PREFIX``: a bucket prefix as the inbox, for field teams that
upload rather than copy to a share.

Each pass lists the prefix, stages every new object in a local folder
(``ROOT/.thermcap/bucket-inbox/<bucket>/<prefix>``) and runs the folder inbox there
(``api.jobs.inbox``: once by content, content-named sessions, archive, derived products,
quarantine). Then the results go back to the bucket. A file's derived products are uploaded
as ``<key>.derived/...``. A bad file moves to ``quarantine/<key>``, with its
``.reason.txt``, and its original is deleted. Each file's journal record goes to
``.thermcap/inbox/<sha256>.json``, so a watcher on another host (or a fresh disk) skips what
was taken already.

An S3 object appears whole when its upload completes, so nothing is picked up half-written.
Keys that name a file being written (``.part``, ``.tmp``) are skipped anyway. The staged copy of a
processed file is deleted once its results are in the bucket, so local disk stays bounded.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

from thermcap.api.jobs.inbox import QUARANTINE, STATE, InboxPass, process_inbox
from thermcap.archive.blobs import BlobStore
from thermcap.recorder.exceptions import ThermcapError

__all__ = ["BUCKET_JOURNAL", "parse_bucket_url", "process_bucket_inbox"]

BUCKET_JOURNAL = ".thermcap/inbox"
_SKIP = (".part", ".tmp", ".crdownload", ".partial", ".reason.txt")


def parse_bucket_url(url: str) -> tuple[str, str]:
    m = re.fullmatch(r"s3://([^/]+)/?(.*)", url)
    if not m:
        raise ThermcapError(f"{url}: a bucket inbox is s3://BUCKET/PREFIX")
    return m.group(1), m.group(2).strip("/")


def _taken(store: BlobStore) -> set[str]:
    """sha256 of every file some watcher took, from the bucket's own journal."""
    return {Path(key).stem for key, _ in store.list(BUCKET_JOURNAL + "/") if key.endswith(".json")}


def process_bucket_inbox(store: BlobStore, prefix: str, root: str | Path, *, bucket: str,
                         archive_formats: list[str] | None = None, log: Any = lambda m: None) -> InboxPass:
    root = Path(root)
    stage = root / STATE / "bucket-inbox" / bucket / (prefix or "_")
    stage.mkdir(parents=True, exist_ok=True)
    known = _stage_index(stage)
    base = f"{prefix}/" if prefix else ""
    for key, size in store.list(base):
        rel = key[len(base):]
        parts = rel.split("/")
        if not rel or parts[0] in (STATE, QUARANTINE) or any(p.endswith(".derived") for p in parts[:-1]) \
                or parts[-1].startswith(".") or parts[-1].endswith(_SKIP) or key.startswith(BUCKET_JOURNAL + "/"):
            continue
        if known.get(rel) == size:
            continue  # staged (and taken, or waiting in the stage) already
        local = stage / rel
        local.parent.mkdir(parents=True, exist_ok=True)
        tmp = local.with_name(local.name + ".part")
        with open(tmp, "wb") as f:
            for block in store.iter_bytes(key):
                f.write(block)
        os.replace(tmp, local)
        os.utime(local, (0, 0))  # whole as uploaded: settled from the start
        known[rel] = size
    _save_stage_index(stage, known)
    # the folder inbox does the work; files other watchers took are journaled as seen first
    taken = _taken(store)
    _seed_journal(stage, taken)
    res = process_inbox(stage, root, settle_s=0.0, archive_formats=archive_formats, log=log)
    for rec in res.processed:
        rel = rec["path"]
        derived = stage / (rel + ".derived")
        for p in sorted(derived.rglob("*")) if derived.is_dir() else []:
            if p.is_file():
                store.put_file(f"{base}{rel}.derived/{p.relative_to(derived).as_posix()}", p)
        _journal_to_bucket(store, rec)
        (stage / rel).unlink(missing_ok=True)  # its results are in the bucket
    for rel, reason in res.quarantined.items():
        moved = stage / QUARANTINE / Path(rel).name
        candidates = sorted((stage / QUARANTINE).glob(Path(rel).stem + "*" + Path(rel).suffix))
        src = moved if moved.is_file() else (candidates[-1] if candidates else None)
        if src is not None:
            store.put_file(f"{base}{QUARANTINE}/{rel}", src)
        store.put_bytes(f"{base}{QUARANTINE}/{rel}.reason.txt", (reason + "\n").encode())
        store.delete(f"{base}{rel}")
        _journal_to_bucket(store, {"path": rel, "status": "quarantined", "reason": reason,
                                   "sha256": _sha_of(stage, rel)})
    return res


def _journal_to_bucket(store: BlobStore, rec: dict[str, Any]) -> None:
    if rec.get("sha256"):
        store.put_bytes(f"{BUCKET_JOURNAL}/{rec['sha256']}.json", json.dumps(rec).encode())


def _sha_of(stage: Path, rel: str) -> str | None:
    from thermcap.api.jobs.inbox import _journal

    return next((sha for sha, r in _journal(stage).items() if r.get("path") == rel), None)


def _seed_journal(stage: Path, taken: set[str]) -> None:
    """Files another watcher took (the bucket's journal) count as seen in this stage's journal."""
    from thermcap.api.jobs.inbox import _journal, _record

    (stage / STATE).mkdir(exist_ok=True)
    mine = _journal(stage)
    for sha in sorted(taken - set(mine)):
        _record(stage, {"sha256": sha, "path": "", "status": "taken elsewhere"})


def _stage_index(stage: Path) -> dict[str, int]:
    try:
        return {k: int(v) for k, v in json.loads((stage / STATE / "staged.json").read_text()).items()}
    except (OSError, ValueError):
        return {}


def _save_stage_index(stage: Path, known: dict[str, int]) -> None:
    (stage / STATE).mkdir(exist_ok=True)
    tmp = stage / STATE / "staged.json.tmp"
    tmp.write_text(json.dumps(known))
    os.replace(tmp, stage / STATE / "staged.json")
