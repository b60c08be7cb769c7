"""Jobs on Dask distributed instead of the lease loop: ``thermcap worker --scheduler ADDR`` (or
``--local-workers N`` for an in-process ``LocalCluster``, the same code path with no server).

Each session that needs work becomes one task per segment and one finalize task
(``archive.segmented``):

- Each segment's task writes and verifies that segment's share of every format, on any worker.
- The finalize task starts when they have all finished. It writes the manifest, takes the final
  folders (HDF5 assembled from the segments' compressed chunks), uploads, deletes the source
  where asked, and indexes.

A task's key is its content: the session's id, the segment's name and size (or, for the
finalize task, all the segments'), and the formats. So a resubmission while it runs (a second
submitter, a restart) is the same task, not a second one, and a session whose content changed
is a new task. Every task is recorded in the jobs table with its attempts, the worker that ran
it and its error. Durable truth stays where it was:

- the manifest and the parts' ``part.json`` say what verified, so a task that finds it done does
  no work;
- the session lock (and a lock per segment) keeps two processes on one filesystem from
  writing the same thing at once;
- the index says what is served.

A worker lost mid-task (kill -9, a node gone) has its task run again on another worker by the
scheduler. The rerun finds the dead one's ``.partial`` folders and replaces them: no partial
archive ever takes a final name. dask-jobqueue and dask-kubernetes give HPC and cloud clusters
the same ``--scheduler`` address.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from thermcap.api.jobs.records import archive_job_id, finish_job, start_job, submit_job
from thermcap.api.jobs.worker import Worker, WorkerPass, finished_sessions, needs_work
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.lock import holder
from thermcap.recorder.storage.reader import read_session_meta

__all__ = ["DaskJobs", "analysis_task", "finalize_task", "scrub_task", "segment_task", "segment_task_key",
           "session_task_key"]


@dataclass(frozen=True)
class TaskConfig:
    """What a task needs, picklable: no engine or client crosses the wire, only addresses."""

    root: str
    formats: tuple[str, ...]
    db_url: str
    s3: dict[str, Any] | None
    delete_source: bool
    analyze: bool = False  # the hot-spot analysis of sessions recorded or imported without it



def _index_store(cfg: Any) -> Any:
    """Where the index writes the sessions' frames files: the job's bucket, else its root."""
    from thermcap.archive.blobs import open_store

    return open_store(Path(cfg.root), **cfg.s3) if cfg.s3 else open_store(Path(cfg.root))

def session_task_key(session_dir: Path, formats: tuple[str, ...]) -> str:
    return archive_job_id(session_dir, formats)


def segment_task_key(session_dir: Path, segment: str, formats: tuple[str, ...]) -> str:
    sid = read_session_meta(session_dir).get("session_id", session_dir.name)
    size = (session_dir / segment).stat().st_size
    h = hashlib.sha256(f"{sid}/{segment}:{size};{','.join(formats)}".encode()).hexdigest()[:16]
    return f"thermcap-segment-{sid}-{Path(segment).stem}-{h}"


@contextlib.contextmanager
def _recorded(cfg: TaskConfig, key: str) -> Iterator[Any]:
    """A task's run in the jobs table: each attempt counts (a rerun after a lost worker shows
    two), and an error is kept with the job before it goes back to Dask for its retries."""
    from thermcap.api.db import make_engine

    engine = make_engine(cfg.db_url)
    start_job(engine, key, _worker_name())
    try:
        yield engine
    except Exception as exc:
        finish_job(engine, key, error=f"{type(exc).__name__}: {exc}")
        raise
    finally:
        engine.dispose()


def segment_task(cfg: TaskConfig, session_dir: str, segment: str, first_index: int, key: str) -> str:
    """On a Dask worker: one segment's share of every format, written and verified (idempotent)."""
    from thermcap.archive.segmented import archive_segment

    with _recorded(cfg, key) as engine:
        part = archive_segment(Path(session_dir), segment, first_index, list(cfg.formats))
        finish_job(engine, key, result={"segment": segment, "frames": part.count if part else None,
                                        "already_archived": part is None})
        return segment


def finalize_task(cfg: TaskConfig, session_dir: str, *segments_done: str) -> dict[str, Any]:
    """On a Dask worker, once every segment's task has finished (``segments_done``, which Dask
    passes in when they have): the manifest, the final folders (HDF5 from the segments'
    compressed chunks), upload, ``--delete-source``, index."""
    from thermcap.api.indexing import index_session
    from thermcap.archive.archiver import archive_session
    from thermcap.archive.blobs import open_store, upload_archive
    from thermcap.archive.segmented import finalize_session

    d = Path(session_dir)
    store = open_store(Path(cfg.root), **cfg.s3) if cfg.s3 else None
    jid = session_task_key(d, cfg.formats)
    with _recorded(cfg, jid) as engine:
        if segments_done or _formats_to_write(d, cfg.formats):
            finalize_session(d, list(cfg.formats))
        if store is not None:
            upload_archive(store, Path(cfg.root), d)
        if cfg.delete_source:
            archive_session(d, list(cfg.formats), delete_source=True)  # everything verified: only deletes
        index_session(engine, d, store=_index_store(cfg))
        sid = read_session_meta(d).get("session_id", d.name)
        finish_job(engine, jid, result={"session": sid, "formats": list(cfg.formats), "segments": len(segments_done)})
        return {"session": sid}


def scrub_task(cfg: TaskConfig, session_dir: str, key: str, repair: bool = True) -> dict[str, Any]:
    """On a Dask worker: one session's archived copies (and its bucket copies) re-verified."""
    from thermcap.api.indexing import index_session
    from thermcap.archive.blobs import open_store
    from thermcap.archive.scrub import ScrubReport, scrub_session

    d = Path(session_dir)
    with _recorded(cfg, key) as engine:
        store = open_store(Path(cfg.root), **cfg.s3) if cfg.s3 else None
        report = ScrubReport()
        scrub_session(d, repair=repair, store=store, root=Path(cfg.root), report=report)
        if report.findings:  # the API stops offering damage at once
            index_session(engine, d, force=True, store=_index_store(cfg))
        found = [{"copy": f.copy, "problem": f.problems[0], "repaired": f.repaired} for f in report.findings]
        finish_job(engine, key, result={"findings": found})
        return {"findings": len(found)}


def analysis_task(cfg: TaskConfig, session_dir: str, key: str, _after: Any = None) -> dict[str, Any]:
    """On a Dask worker, after the session's finalize: the detector run over every frame (from the
    MCAP source or, once it is deleted, the archive), then the index takes its results."""
    from thermcap.api.indexing import index_session
    from thermcap.recorder.analysis.offline import analyze_session

    d = Path(session_dir)
    with _recorded(cfg, key) as engine:
        out = analyze_session(d)
        index_session(engine, d, store=_index_store(cfg))
        summary = {"frames": out.get("frames"), "detections": out.get("detections")}
        finish_job(engine, key, result=summary)
        return summary


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return f"dask:{get_worker().address}"
    except ValueError:  # not on a Dask worker (called directly)
        return f"local:{os.getpid()}"


def _formats_to_write(d: Path, formats: tuple[str, ...]) -> list[str]:
    from thermcap.archive.manifest import load_manifest

    m = load_manifest(d, required=False) or {}
    done = {f for f, e in (m.get("formats") or {}).items() if e.get("verified") and (d / "archive" / f).is_dir()}
    return [f for f in formats if f not in done]


class DaskJobs:
    """One pass: the sessions that need work, as tasks on the cluster; waits for them."""

    def __init__(self, worker: Worker, cfg: TaskConfig, *, scheduler: str | None = None, local_workers: int = 2,
                 retries: int = 2, processes: bool = True) -> None:
        from distributed import Client, LocalCluster

        self.worker, self.cfg, self.retries = worker, cfg, retries
        if scheduler:
            self.client = Client(scheduler, timeout=30)
            self._cluster = None
        else:
            # processes: one worker process per slot, as a real cluster (the benchmark); threads:
            # one in-process worker (the embedded default), whose tasks end with the process
            where = {"host": "127.0.0.1"} if processes else {}  # threads talk in-process: no port at all
            self._cluster = LocalCluster(n_workers=local_workers if processes else 1,
                                         threads_per_worker=1 if processes else local_workers, processes=processes,
                                         dashboard_address=None, **where)
            self.client = Client(self._cluster)

    def run_once(self) -> WorkerPass:
        result = WorkerPass()
        self.worker._split_camera_sessions(result)  # local and quick: copies, then archived as tasks
        todo = []
        for d in finished_sessions(self.worker.root):
            if not needs_work(d, list(self.cfg.formats), self.worker.store):
                continue
            if holder(d) is not None:  # another submitter's finalize (or an archive) holds it now
                result.busy.append(read_session_meta(d).get("session_id", d.name))
                continue
            todo.append(d)
        futures = {self._submit(d): d for d in todo}
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

    def _submit(self, d: Path) -> Any:
        """A session as one task per segment (in parallel on any workers) and a finalize task
        that Dask starts when they have all finished. Each is recorded in the jobs table before
        the cluster sees it, so a job never exists only in the scheduler."""
        from thermcap.archive.segmented import plan_segments

        sid = read_session_meta(d).get("session_id", d.name)
        engine, formats = self.worker.engine, self.cfg.formats
        parts = []
        if _formats_to_write(d, formats):
            for segment, first in plan_segments(d):
                key = segment_task_key(d, segment, formats)
                submit_job(engine, key, "archive-segment", sid, {"segment": segment, "formats": list(formats)})
                parts.append(self.client.submit(segment_task, self.cfg, str(d), segment, first, key, key=key,
                                                retries=self.retries))
        key = session_task_key(d, formats)
        submit_job(engine, key, "archive", sid, {"formats": list(formats), "segments": len(parts)})
        done = self.client.submit(finalize_task, self.cfg, str(d), *parts, key=key, retries=self.retries)
        if self.cfg.analyze and not SessionLayout.of(d).analysis_jsonl.is_file():
            akey = key.replace("thermcap-archive-", "thermcap-analysis-", 1)
            submit_job(engine, akey, "analysis", sid, {})
            done = self.client.submit(analysis_task, self.cfg, str(d), akey, done, key=akey, retries=self.retries)
        return done

    def scrub(self, repair: bool = True) -> dict[str, Any]:
        """Every archived session re-verified as a task of its own (and repaired where another
        copy covers it); sessions where anything was found are re-indexed by their task."""
        from thermcap.recorder.storage.layout import SessionLayout
        from thermcap.recorder.storage.reader import list_sessions

        futures = {}
        for d in list_sessions(self.worker.root):
            if SessionLayout.of(d).manifest.is_file():
                key = f"thermcap-scrub-{d.name}-{time.time_ns()}"
                submit_job(self.worker.engine, key, "scrub", d.name, {"repair": repair})
                futures[d.name] = self.client.submit(scrub_task, self.cfg, str(d), key, repair, key=key,
                                                     retries=self.retries)
        out: dict[str, Any] = {"sessions": len(futures), "findings": 0, "failed": {}}
        for sid, fut in futures.items():
            try:
                out["findings"] += fut.result()["findings"]
            except Exception as exc:  # recorded in the jobs table by the task itself
                out["failed"][sid] = f"{type(exc).__name__}: {exc}"
        return out

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()
