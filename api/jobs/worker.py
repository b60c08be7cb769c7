"""``thermcap worker``: archive, verify, upload and index finished sessions as they appear.

A session is finished when it has a summary and no ``.active`` segment and nobody holds its
recording lock. Workers coordinate through leases in the index (SQLite or PostgreSQL): a worker
archives a session only while it holds the lease, so several workers on one root or one bucket
never archive the same session twice; a lease expires, so a dead worker's session is picked up
again, and a live worker renews its lease every third of its lifetime for as long as the work
takes (an hour-long session archives for longer than any fixed lifetime). Uploads use
create-only writes: an object that is already there with the same content is left alone, one
with different content is an error, never an overwrite.
"""

from __future__ import annotations

import os
import socket
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sqlalchemy import delete, insert, update
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError

from api import db
from api.indexing import index_session
from api.jobs.records import archive_job_id, finish_job, start_job, submit_job
from api.storage import BlobStore, upload_archive
from archive.archiver import archive_session
from archive.manifest import load_manifest
from archive.scrub import ScrubReport, scrub_session
from recorder.exceptions import ThermcapError
from recorder.storage.layout import SessionLayout
from recorder.storage.lock import is_locked
from recorder.storage.reader import list_sessions, read_session_meta, session_segments
from recorder.storage.split import split_cameras

__all__ = ["Worker", "acquire_lease", "finished_sessions", "release_lease"]


def acquire_lease(engine: Engine, session_id: str, owner: str, ttl_s: float) -> bool:
    now = time.time_ns()
    expires = now + int(ttl_s * 1e9)
    with engine.begin() as conn:
        try:
            conn.execute(insert(db.leases).values(session_id=session_id, owner=owner, expires_ns=expires))
            return True
        except IntegrityError:
            pass
    with engine.begin() as conn:
        res = conn.execute(update(db.leases).where(db.leases.c.session_id == session_id,
                                                   (db.leases.c.expires_ns < now) | (db.leases.c.owner == owner))
                           .values(owner=owner, expires_ns=expires))
        return res.rowcount == 1


class _Renewal:
    """Keeps a lease alive on a thread while its holder works; says if it was lost (a pause
    longer than the lease, and another worker took it)."""

    def __init__(self, engine: Engine, session_id: str, owner: str, ttl_s: float) -> None:
        self.engine, self.session_id, self.owner, self.ttl_s = engine, session_id, owner, ttl_s
        self.lost = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"lease-{session_id}", daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.ttl_s / 3):
            try:
                renewed = acquire_lease(self.engine, self.session_id, self.owner, self.ttl_s)
            except Exception:  # the index is unreachable for a moment: try again next time
                renewed = True
            if not renewed:
                self.lost = True
                return

    def __enter__(self) -> _Renewal:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def release_lease(engine: Engine, session_id: str, owner: str) -> None:
    with engine.begin() as conn:
        conn.execute(delete(db.leases).where(db.leases.c.session_id == session_id, db.leases.c.owner == owner))


def finished_sessions(root: Path) -> list[Path]:
    out = []
    for d in list_sessions(root):
        meta = read_session_meta(d)
        if meta.get("status") not in ("complete", "recovered", "failed") or list(d.glob("*.active")):
            continue
        if is_locked(d):
            continue  # still being recorded (or archived on this host)
        out.append(d)
    return out


def _needs_work(d: Path, formats: list[str], store: BlobStore | None) -> bool:
    if isinstance(read_session_meta(d).get("cameras"), dict):
        return False  # archived through its per-camera sessions
    try:
        m = load_manifest(d, required=False)
    except ThermcapError:
        return True
    if m is None or any(not m["formats"].get(f, {}).get("verified") for f in formats):
        return True
    return store is not None and not m.get("upload", {}).get("complete")


@dataclass
class WorkerPass:
    """One pass over ROOT, by session id."""

    archived: list[str] = field(default_factory=list)
    leased_elsewhere: list[str] = field(default_factory=list)  # another worker holds the lease
    failed: dict[str, str] = field(default_factory=dict)
    split: dict[str, list[str]] = field(default_factory=dict)  # a session of several cameras -> its per-camera ones

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class Worker:
    def __init__(self, root: Path, engine: Engine, *, formats: list[str], store: BlobStore | None = None,
                 delete_source: bool = False, lease_ttl_s: float = 600.0, owner: str | None = None,
                 log: Callable[[str], None] = print) -> None:
        self.root, self.engine, self.formats, self.store = Path(root), engine, formats, store
        self.delete_source, self.lease_ttl_s = delete_source, lease_ttl_s
        self.owner = owner or f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}"
        self.log = log

    def run_once(self) -> WorkerPass:
        result = WorkerPass()
        self._split_camera_sessions(result)
        for d in finished_sessions(self.root):
            if not _needs_work(d, self.formats, self.store):
                continue
            sid = read_session_meta(d).get("session_id", d.name)
            if not acquire_lease(self.engine, sid, self.owner, self.lease_ttl_s):
                result.leased_elsewhere.append(sid)
                continue
            jid = archive_job_id(d, self.formats)
            submit_job(self.engine, jid, "archive", sid, {"formats": list(self.formats)})
            start_job(self.engine, jid, self.owner)
            try:
                with _Renewal(self.engine, sid, self.owner, self.lease_ttl_s) as renewal:
                    archive_session(d, self.formats, delete_source=self.delete_source and self.store is None)
                    if self.store is not None:
                        upload_archive(self.store, self.root, d)
                        if self.delete_source:
                            archive_session(d, self.formats, delete_source=True)
                    index_session(self.engine, d)
                if renewal.lost:  # the work is idempotent and was done under the session lock; say so
                    self.log(f"warning: {sid}: the lease lapsed during the work (a pause longer than "
                             f"{self.lease_ttl_s:g} s); another worker may have started it and found it done")
                result.archived.append(sid)
                finish_job(self.engine, jid, result={"session": sid, "formats": list(self.formats)})
                self.log(f"archived {sid}")
            except ThermcapError as exc:
                result.failed[sid] = str(exc)
                finish_job(self.engine, jid, error=str(exc))
                self.log(f"error: {sid}: {exc}")
            except BaseException as exc:  # recorded, then raised as before
                finish_job(self.engine, jid, error=f"{type(exc).__name__}: {exc}")
                raise
            finally:
                release_lease(self.engine, sid, self.owner)
        return result

    def _split_camera_sessions(self, result: WorkerPass) -> None:
        """A session of several cameras becomes one session per camera (bit-exact copies), which
        this pass then archives like any other; its own segments go only with --delete-source,
        once every copy compared equal."""
        for d in finished_sessions(self.root):
            meta = read_session_meta(d)
            if not isinstance(meta.get("cameras"), dict) or (meta.get("split_into") and not (
                    self.delete_source and session_segments(d))):
                continue
            try:
                done = split_cameras(d, delete_source=self.delete_source)
                result.split[meta.get("session_id", d.name)] = sorted(Path(p).name for p in done.cameras.values())
                self.log(f"split {d.name} into {', '.join(sorted(done.cameras))}")
            except ThermcapError as exc:
                result.failed[meta.get("session_id", d.name)] = str(exc)
                self.log(f"error: {d.name}: {exc}")

    def scrub(self, repair: bool = True) -> ScrubReport:
        """Re-verify every archived copy (and the bucket's), repair what another copy covers, and
        re-index the sessions where anything was found, so the API stops offering damage at once."""
        report = ScrubReport()
        for d in list_sessions(self.root):
            if not SessionLayout.of(d).manifest.is_file():
                continue
            before = len(report.findings)
            try:
                scrub_session(d, repair=repair, store=self.store, root=self.root, report=report)
            except ThermcapError as exc:
                self.log(f"error: scrub {d.name}: {exc}")
                continue
            if len(report.findings) > before:
                index_session(self.engine, d, force=True)
        for f in report.findings:
            self.log(f"scrub: {f.session}: {f.copy} damaged ({f.problems[0]}); "
                     + (f"repaired from {f.repaired_from}" if f.repaired else f"not repaired: {f.repair_error}"))
        return report

    def heartbeat(self) -> None:
        """``ROOT/.thermcap/worker.heartbeat``, touched after every pass: the container's health check."""
        path = self.root / ".thermcap" / "worker.heartbeat"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(f"{self.owner} {time.time():.0f}\n")

    def run_forever(self, interval_s: float = 5.0, scrub_interval_s: float = 86400.0) -> None:
        next_scrub = time.monotonic() + scrub_interval_s if scrub_interval_s > 0 else None
        while True:
            self.run_once()
            self.heartbeat()
            if next_scrub is not None and time.monotonic() >= next_scrub:
                self.scrub()
                next_scrub = time.monotonic() + scrub_interval_s
            time.sleep(interval_s)
