"""What ``thermcap worker`` does besides running tasks: which sessions are finished and still
need work, splitting sessions of several cameras, scrubbing, and the heartbeat.

A session is finished when it has a summary and no ``.active`` segment and nobody holds its
recording lock. The work itself runs as Dask tasks (``api.jobs.dask_jobs``). The lease loop
that used to coordinate workers through a table is gone. The durable truth is the manifest and
the segments' parts; the session and segment locks keep two processes from writing the same
thing; the jobs table records what was asked and how it went. Uploads use create-only writes:
an object that is already there with the same content is left alone, and one with different
content is an error, never an overwrite.
"""

from __future__ import annotations

import os
import socket
import time
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sqlalchemy.engine import Engine

from thermcap.api.indexing import index_session
from thermcap.api.storage import BlobStore
from thermcap.archive.manifest import load_manifest
from thermcap.archive.scrub import ScrubReport, scrub_session
from thermcap.recorder.exceptions import ThermcapError
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.lock import is_locked
from thermcap.recorder.storage.reader import list_sessions, read_session_meta, session_segments
from thermcap.recorder.storage.split import split_cameras

__all__ = ["Worker", "WorkerPass", "finished_sessions", "needs_work"]


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


def needs_work(d: Path, formats: list[str], store: BlobStore | None) -> bool:
    if isinstance(read_session_meta(d).get("cameras"), dict):
        return False  # archived through its per-camera sessions
    try:
        m = load_manifest(d, required=False)
    except ThermcapError:
        return True
    if m is None or any(not m["formats"].get(f, {}).get("verified") or m["formats"][f].get("damaged")
                        for f in formats):
        return True
    return store is not None and not m.get("upload", {}).get("complete")


@dataclass
class WorkerPass:
    """One pass over ROOT, by session id."""

    archived: list[str] = field(default_factory=list)
    busy: list[str] = field(default_factory=list)  # another process holds the session now: next pass
    failed: dict[str, str] = field(default_factory=dict)
    split: dict[str, list[str]] = field(default_factory=dict)  # a session of several cameras -> its per-camera ones

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class Worker:
    def __init__(self, root: Path, engine: Engine, *, formats: list[str], store: BlobStore | None = None,
                 delete_source: bool = False, owner: str | None = None,
                 log: Callable[[str], None] = print) -> None:
        self.root, self.engine, self.formats, self.store = Path(root), engine, formats, store
        self.delete_source = delete_source
        self.owner = owner or f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:6]}"
        self.log = log

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
                index_session(self.engine, d, force=True, store=self.store)
        for f in report.findings:
            self.log(f"scrub: {f.session}: {f.copy} damaged ({f.problems[0]}); "
                     + (f"repaired from {f.repaired_from}" if f.repaired else f"not repaired: {f.repair_error}"))
        return report

    def heartbeat(self) -> None:
        """``ROOT/.thermcap/worker.heartbeat``, touched after every pass: the container's health check."""
        path = self.root / ".thermcap" / "worker.heartbeat"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(f"{self.owner} {time.time():.0f}\n")
