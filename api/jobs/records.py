"""The jobs table: what each job was asked, where it stands, how often it ran and why it failed.

Why: a job's fate must outlive the process that ran it. The API's series jobs, the lease loop
and the Dask tasks all write here, so `thermcap jobs` and `GET /api/v1/jobs` show retries and
failures from any machine, without the Dask dashboard. A job's id is its content (the kind, the
session, the parameters and what the session held), so submitting the same work again finds
the same job. A finished one is its own cache.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import insert, select, update
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError

from thermcap.api import db
from thermcap.recorder.storage.reader import read_session_meta, session_segments

__all__ = ["STATES", "JobRecord", "archive_job_id", "finish_job", "get_job", "job_id", "list_jobs", "start_job",
           "submit_job"]

STATES = ("queued", "running", "done", "failed")


@dataclass(frozen=True)
class JobRecord:
    id: str
    kind: str
    session_id: str | None
    params: dict[str, Any]
    state: str
    attempts: int
    worker: str | None
    error: str | None
    result: Any
    created_ns: int
    started_ns: int | None
    finished_ns: int | None

    @property
    def seconds(self) -> float | None:
        if self.started_ns is None:
            return None
        return ((self.finished_ns or time.time_ns()) - self.started_ns) / 1e9

    def to_dict(self, *, with_result: bool = True) -> dict[str, Any]:
        out = asdict(self)
        out["seconds"] = round(self.seconds, 3) if self.seconds is not None else None
        if not with_result:
            out.pop("result")
        return out


def job_id(kind: str, session_id: str | None, params: dict[str, Any], content: str = "") -> str:
    h = hashlib.sha256(json.dumps([kind, session_id, params, content], sort_keys=True).encode()).hexdigest()
    return f"{kind}-{h[:24]}"


def archive_job_id(session_dir: Path, formats: tuple[str, ...] | list[str]) -> str:
    """A session's archive job (and Dask task key): its id, its segments' names and sizes, and
    the formats. A resubmission while it runs is the same job; a session whose content
    changed is a new one."""
    sid = read_session_meta(session_dir).get("session_id", session_dir.name)
    h = hashlib.sha256(sid.encode())
    for seg in session_segments(session_dir):
        h.update(f"{seg.name}:{seg.stat().st_size};".encode())
    h.update(",".join(formats).encode())
    return f"thermcap-archive-{sid}-{h.hexdigest()[:16]}"


def _record(row: Any) -> JobRecord:
    return JobRecord(row["id"], row["kind"], row["session_id"], json.loads(row["params"] or "{}"), row["state"],
                     int(row["attempts"] or 0), row["worker"], row["error"],
                     json.loads(row["result"]) if row["result"] else None, int(row["created_ns"]),
                     row["started_ns"], row["finished_ns"])


def get_job(engine: Engine, jid: str) -> JobRecord | None:
    with engine.connect() as conn:
        row = conn.execute(select(db.jobs).where(db.jobs.c.id == jid)).mappings().first()
    return _record(row) if row is not None else None


def submit_job(engine: Engine, jid: str, kind: str, session_id: str | None, params: dict[str, Any]) -> \
        tuple[JobRecord, bool]:
    """(the job, whether it is new). A failed job submitted again is queued again; any other
    existing one is returned as it is."""
    now = time.time_ns()
    try:
        with engine.begin() as conn:
            conn.execute(insert(db.jobs).values(id=jid, kind=kind, session_id=session_id, params=json.dumps(params),
                                                state="queued", attempts=0, created_ns=now))
        new = True
    except IntegrityError:  # the same work, asked before (or at the same time by another process)
        with engine.begin() as conn:
            new = conn.execute(update(db.jobs).where(db.jobs.c.id == jid, db.jobs.c.state == "failed")
                               .values(state="queued", error=None, finished_ns=None)).rowcount > 0
    job = get_job(engine, jid)
    assert job is not None
    return job, new


def start_job(engine: Engine, jid: str, worker: str) -> None:
    with engine.begin() as conn:
        conn.execute(update(db.jobs).where(db.jobs.c.id == jid)
                     .values(state="running", worker=worker, attempts=db.jobs.c.attempts + 1,
                             started_ns=time.time_ns(), finished_ns=None, error=None))


def finish_job(engine: Engine, jid: str, *, result: Any = None, error: str | None = None) -> None:
    with engine.begin() as conn:
        conn.execute(update(db.jobs).where(db.jobs.c.id == jid)
                     .values(state="failed" if error is not None else "done", error=error,
                             result=json.dumps(result) if result is not None else None, finished_ns=time.time_ns()))


def list_jobs(engine: Engine, *, state: str | None = None, kind: str | None = None, session_id: str | None = None,
              limit: int = 100) -> list[JobRecord]:
    q = select(db.jobs).order_by(db.jobs.c.created_ns.desc()).limit(limit)
    if state:
        q = q.where(db.jobs.c.state == state)
    if kind:
        q = q.where(db.jobs.c.kind == kind)
    if session_id:
        q = q.where(db.jobs.c.session_id == session_id)
    with engine.connect() as conn:
        return [_record(r) for r in conn.execute(q).mappings().all()]
