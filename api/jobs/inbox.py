"""``thermcap watch``: a folder where files are dropped and each is taken in exactly once.

As the TERRA-REF converter ran "whenever a file is added to a dataset": each camera file
dropped in the inbox (DJI, FLIR, TERRA-REF, ICD) is imported into the data root (one session
per file), archived and verified, and its derived products are written beside it in
``<name>.derived/``: a heatmap PNG with its colour bar, a °C GeoTIFF, and per-frame
``surface_temperature`` statistics. The API's index takes the sessions in on its next pass.

- Exactly once: the journal (``.thermcap/inbox.jsonl``) keys each file by its content's
  sha256, so a file seen before (under any name) is never processed again, and a restart
  resumes where it stopped. Its sessions are named by that content (``inbox-<sha256[:16]>``),
  so a crash between importing and journaling finds them instead of importing again, and a
  session a crash left half-made is imported again from the file.
- Never half-way: a file is taken only when its size and mtime have not changed for
  ``settle_s``, and names of files being written (``.part``, ``.tmp``, dot files) are skipped.
- A bad file goes to ``quarantine/`` with a ``.reason.txt`` beside it; the queue goes on.
- One pass at a time per inbox (a lock), so two watchers never take the same file. A second
  watcher is a standby: it takes its turn between the other's passes, and all of them once the
  other is gone (the lock dies with its process).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.storage.digest import file_sha256
from thermcap.recorder.storage.layout import DataRoot
from thermcap.recorder.storage.lock import lock_session
from thermcap.recorder.storage.reader import read_session_meta

__all__ = ["InboxBusy", "InboxPass", "process_inbox", "take_file"]

STATE = ".thermcap"
QUARANTINE = "quarantine"
_SKIP_SUFFIXES = (".part", ".tmp", ".crdownload", ".partial", ".reason.txt")


class InboxBusy(ThermcapError):
    """Another watcher is on this inbox now: a standby watcher tries again on its next pass."""


@dataclass
class InboxPass:
    processed: list[dict[str, Any]] = field(default_factory=list)
    duplicates: list[str] = field(default_factory=list)  # content seen before
    waiting: list[str] = field(default_factory=list)  # still changing (being copied)
    quarantined: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _journal(inbox: Path) -> dict[str, dict[str, Any]]:
    path = inbox / STATE / "inbox.jsonl"
    out: dict[str, dict[str, Any]] = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                rec = json.loads(line)
            except ValueError:
                continue  # a line cut by a crash: that file is simply taken again
            out[rec["sha256"]] = rec
    return out


def _record(inbox: Path, rec: dict[str, Any]) -> None:
    path = inbox / STATE / "inbox.jsonl"
    with open(path, "a") as f:
        f.write(json.dumps(rec) + "\n")
        f.flush()
        os.fsync(f.fileno())


def _candidates(inbox: Path) -> list[Path]:
    out = []
    for p in sorted(inbox.rglob("*")):
        rel = p.relative_to(inbox).parts
        if not p.is_file() or rel[0] in (STATE, QUARANTINE) or any(x.endswith(".derived") for x in rel[:-1]):
            continue
        if p.name.startswith(".") or p.name.endswith(_SKIP_SUFFIXES):
            continue
        if p.suffix.lower() == ".json" and any(p.with_suffix(s).exists() for s in (".tif", ".tiff", ".bin", ".raw")):
            continue  # the sidecar of an ICD pair or the metadata of a TERRA-REF image: taken with it
        if p.name.endswith("_metadata.json") and list(p.parent.glob(p.name.replace("_metadata.json", "_ir.bin"))):
            continue
        out.append(p)
    return out


def _settled(path: Path, settle_s: float, now: float) -> bool:
    st = path.stat()
    return now - st.st_mtime >= settle_s


def _quarantine(inbox: Path, path: Path, reason: str) -> None:
    q = inbox / QUARANTINE
    q.mkdir(exist_ok=True)
    dest = q / path.name
    k = 1
    while dest.exists():
        dest = q / f"{path.stem}.{k}{path.suffix}"
        k += 1
    shutil.move(str(path), dest)
    dest.with_name(dest.name + ".reason.txt").write_text(reason + "\n")


def _earlier_sessions(root: Path, name: str) -> list[Path]:
    """The sessions an earlier run imported from the same content, if it finished importing;
    a session it left half-made (it died mid-import) is removed, for the file is still here to
    import again, and the others of that file with it, so it is imported whole, once."""
    base = DataRoot.of(root).sessions
    found = sorted(p for p in base.glob(f"{name}*") if p.is_dir() and (p.name == name or
                                                                        p.name.startswith(name + "-")))
    if not found:
        return []
    if all(read_session_meta(p).get("status") == "complete" for p in found):
        return found
    for p in found:
        shutil.rmtree(p)
    return []


def _derive(session_dir: Path, out: Path) -> list[str]:
    from thermcap.recorder.exports.files import export_session

    out.mkdir(exist_ok=True)
    made = []
    for kind, summary in (("heatmap-png", None), ("celsius-tiff", "json")):
        try:
            res = export_session(session_dir, kind, out, summary=summary)
        except ThermcapError as exc:
            made.append(f"{kind}: not made ({exc})")
            continue
        made.append(f"{kind}: {res['files']} files" + ("" if not res["refused"] else f" ({res['refused'][0]})"))
    return made


def take_file(inbox: Path, root: Path, rel: str, digest: str, archive_formats: list[str] | None) -> dict[str, Any]:
    """One settled new file taken in: imported (or found imported, by its content-named session),
    archived, its derived products written beside it; or quarantined with the reason. Returns
    its journal record. The same call in-process or as a Dask task on a worker that sees both
    folders."""
    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.importers.run import import_paths

    path = inbox / rel
    name = f"inbox-{digest[:16]}"  # a file's sessions are named by its content: a rerun finds them
    done = _earlier_sessions(root, name)
    if done:
        report = None  # imported before a crash that came ahead of the journal: not imported again
        session_dirs = done
    else:
        report = import_paths([str(path)], root, session=name)
        session_dirs = [s.session_dir for s in report.sessions]
    problem = "" if report is None else "; ".join(f["error"] for f in report.failed + report.truncated)
    if problem or not session_dirs:
        reason = problem or "not a camera file thermcap reads"
        _quarantine(inbox, path, reason)
        return {"sha256": digest, "path": rel, "status": "quarantined", "reason": reason}
    archived = []
    for d in session_dirs:
        if archive_formats:
            archive_session(d, archive_formats)  # resumes a half-done archive, skips a done one
            archived.append(d.name)
    derived = _derive(session_dirs[0], path.with_name(path.name + ".derived"))
    return {"sha256": digest, "path": rel, "status": "processed", "sessions": [str(d) for d in session_dirs],
            "archived": archived, "derived": derived, "at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def process_inbox(inbox: str | Path, root: str | Path, *, settle_s: float = 2.0,
                  archive_formats: list[str] | None = None, log: Callable[[str], None] = lambda m: None,
                  client: Any = None) -> InboxPass:
    """One pass: take every settled new file once. ``client`` (a Dask client) takes the files as
    tasks, in parallel on its workers; each is journaled here as it finishes."""
    inbox, root = Path(inbox), Path(root)
    if not inbox.is_dir():
        raise ThermcapError(f"{inbox}: no such inbox folder")
    (inbox / STATE).mkdir(exist_ok=True)
    lock = lock_session(inbox / STATE, "watch", wait_s=0.0)
    if lock is None:
        raise InboxBusy(f"{inbox}: another `thermcap watch` holds this inbox")
    result = InboxPass()
    try:
        seen = _journal(inbox)
        now = time.time()
        todo: dict[str, str] = {}  # digest -> rel
        for path in _candidates(inbox):
            rel = str(path.relative_to(inbox))
            if not _settled(path, settle_s, now):
                result.waiting.append(rel)
                continue
            digest = file_sha256(path)
            if digest in seen or digest in todo:
                if (seen.get(digest) or {}).get("path", todo.get(digest)) != rel:
                    result.duplicates.append(rel)
                continue
            todo[digest] = rel
        if client is not None:
            from distributed import as_completed

            futures = [client.submit(take_file, inbox, root, rel, digest, archive_formats,
                                     key=f"thermcap-inbox-{digest[:32]}") for digest, rel in todo.items()]
            records = (f.result() for f in as_completed(futures))
        else:
            records = (take_file(inbox, root, rel, digest, archive_formats) for digest, rel in todo.items())
        for rec in records:
            if rec["status"] == "quarantined":
                result.quarantined[rec["path"]] = rec["reason"]
                log(f"quarantined {rec['path']}: {rec['reason']}")
            else:
                result.processed.append(rec)
                log(f"took {rec['path']} -> {', '.join(Path(x).name for x in rec['sessions'])}")
            _record(inbox, rec)
            seen[rec["sha256"]] = rec
    finally:
        lock.release()
    return result
