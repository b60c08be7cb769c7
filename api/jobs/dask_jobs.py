"""Jobs on Dask distributed instead of the lease loop: ``thermcap worker --scheduler ADDR`` (or
``--local-workers N`` for an in-process ``LocalCluster``, the same code path with no server).

Each session that needs work becomes one task that archives it, verifies it, uploads it and
indexes it. The task's key is the session's content: its id, its segments' names and sizes,
and the formats. So a resubmission while it runs (a second submitter, a restart) is the same
task, not a second one, and a session whose content changed is a new task. Durable truth stays
where it was:

- the manifest says which formats verified, so a task that finds them verified does no work;
- the session lock keeps two processes on one filesystem from archiving a session at once;
- the index says what is served.

A worker lost mid-task (kill -9, a node gone) has its task run again on another worker by the
scheduler. The rerun finds the dead one's ``.partial`` folders and replaces them: no partial
archive ever takes a final name. dask-jobqueue and dask-kubernetes give HPC and cloud clusters
the same ``--scheduler`` address.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from api.jobs.records import archive_job_id, finish_job, start_job, submit_job
from api.jobs.worker import Worker, WorkerPass, _needs_work, finished_sessions
from recorder.storage.reader import read_session_meta

__all__ = ["DaskJobs", "archive_task", "session_task_key"]


@dataclass(frozen=True)
class TaskConfig:
    """What a task needs, picklable: no engine or client crosses the wire, only addresses."""

    root: str
    formats: tuple[str, ...]
    db_url: str
    s3: dict[str, Any] | None
    delete_source: bool


def session_task_key(session_dir: Path, formats: tuple[str, ...]) -> str:
    return archive_job_id(session_dir, formats)


def archive_task(cfg: TaskConfig, session_dir: str) -> dict[str, Any]:
    """On a Dask worker: archive, verify, upload and index one session (idempotent)."""
    from api.db import make_engine
    from api.indexing import index_session
    from archive.archiver import archive_session
    from archive.blobs import open_store, upload_archive

    d = Path(session_dir)
    store = open_store(Path(cfg.root), **cfg.s3) if cfg.s3 else None
    engine = make_engine(cfg.db_url)
    jid = session_task_key(d, cfg.formats)
    start_job(engine, jid, _worker_name())  # each attempt counts, so a rerun after a lost worker shows
    try:
        archive_session(d, list(cfg.formats), delete_source=cfg.delete_source and store is None)
        if store is not None:
            upload_archive(store, Path(cfg.root), d)
            if cfg.delete_source:
                archive_session(d, list(cfg.formats), delete_source=True)
        index_session(engine, d)
        sid = read_session_meta(d).get("session_id", d.name)
        finish_job(engine, jid, result={"session": sid, "formats": list(cfg.formats)})
        return {"session": sid}
    except Exception as exc:
        finish_job(engine, jid, error=f"{type(exc).__name__}: {exc}")
        raise
    finally:
        engine.dispose()


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return f"dask:{get_worker().address}"
    except ValueError:  # not on a Dask worker (called directly)
        return f"local:{os.getpid()}"


class DaskJobs:
    """One pass: the sessions that need work, as tasks on the cluster; waits for them."""

    def __init__(self, worker: Worker, cfg: TaskConfig, *, scheduler: str | None = None, local_workers: int = 2,
                 retries: int = 2) -> None:
        from distributed import Client, LocalCluster

        self.worker, self.cfg, self.retries = worker, cfg, retries
        if scheduler:
            self.client = Client(scheduler, timeout=30)
            self._cluster = None
        else:
            self._cluster = LocalCluster(n_workers=local_workers, threads_per_worker=1, processes=True,
                                         host="127.0.0.1", dashboard_address=None)
            self.client = Client(self._cluster)

    def run_once(self) -> WorkerPass:
        result = WorkerPass()
        self.worker._split_camera_sessions(result)  # local and quick: copies, then archived as tasks
        todo = [d for d in finished_sessions(self.worker.root)
                if _needs_work(d, list(self.cfg.formats), self.worker.store)]
        for d in todo:  # recorded before the cluster sees it: a job never exists only in the scheduler
            submit_job(self.worker.engine, session_task_key(d, self.cfg.formats), "archive",
                       read_session_meta(d).get("session_id", d.name), {"formats": list(self.cfg.formats)})
        futures = {self.client.submit(archive_task, self.cfg, str(d), key=session_task_key(d, self.cfg.formats),
                                      retries=self.retries): d for d in todo}
        for fut, d in futures.items():
            sid = read_session_meta(d).get("session_id", d.name)
            try:
                fut.result()
                result.archived.append(sid)
                self.worker.log(f"archived {sid} (task {fut.key})")
            except Exception as exc:  # raised on the worker, re-raised here: this session failed
                result.failed[sid] = f"{type(exc).__name__}: {exc}"
                self.worker.log(f"error: {sid}: {exc}")
        return result

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()
