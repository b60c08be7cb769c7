"""The API's own job runner: a region series over an hour of frames is asked for, not waited on.

Why a runner and not a request: the answer may take seconds to minutes, longer than a browser or
a proxy keeps a request open. The job is recorded in the jobs table before it runs, runs on a
small thread pool (decoders release the GIL), or, with ``THERMCAP_DASK_SCHEDULER``, as a task on
the Dask cluster the archive workers use. It leaves its result in the blob store
(``jobs/<id>.json``), where any API replica finds it. A job whose process died shows as running
with a dead worker; submitting it again runs it again.
"""

from __future__ import annotations

import json
import os
import socket
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from sqlalchemy.engine import Engine

from thermcap.api.jobs.records import JobRecord, finish_job, start_job
from thermcap.api.storage import BlobStore

__all__ = ["JobRunner", "result_key"]

#: A job queued or running this long, and not in this process, is taken for lost.
STALE_AFTER_S = 600.0


def result_key(jid: str) -> str:
    return f"jobs/{jid}.json"


class JobRunner:
    def __init__(self, engine: Engine, store: BlobStore, *, threads: int = 1, scheduler: str | None = None) -> None:
        self.engine, self.store = engine, store
        self.name = f"api:{socket.gethostname()}:{os.getpid()}"
        self._scheduler = scheduler
        self._client: Any = None
        self._pool = ThreadPoolExecutor(threads, thread_name_prefix="thermcap-job")
        self._in_flight: set[str] = set()
        self._lock = threading.Lock()

    def lost(self, job: JobRecord) -> bool:
        """Whether a queued or running job will never finish: not ours, and its worker is a dead
        process on this host or it has been at it too long."""
        if job.state not in ("queued", "running"):
            return False
        with self._lock:
            if job.id in self._in_flight:
                return False
        host_pid = (job.worker or "").split(":")
        if len(host_pid) == 3 and host_pid[0] == "api" and host_pid[1] == socket.gethostname():
            try:
                os.kill(int(host_pid[2]), 0)
            except (ProcessLookupError, ValueError):
                return True
            except PermissionError:
                pass
        since = job.started_ns or job.created_ns
        return time.time_ns() - since > STALE_AFTER_S * 1e9

    def dask(self) -> Any:
        """The Dask client, connected on first use (None without a scheduler)."""
        if self._scheduler and self._client is None:
            from distributed import Client

            self._client = Client(self._scheduler, timeout=30, set_as_default=False)
        return self._client

    def run(self, job: JobRecord, work: Callable[[], dict[str, Any]], summary: Callable[[dict[str, Any]], Any],
            *, remote: tuple[Callable[..., dict[str, Any]], tuple[Any, ...]] | None = None) -> None:
        """Run ``work`` for ``job``; its whole result goes to the store, ``summary(result)`` to
        the table. ``remote`` (a picklable function and its arguments) runs it on the Dask
        cluster instead, when there is one; the job is recorded here either way."""
        with self._lock:
            if job.id in self._in_flight:
                return
            self._in_flight.add(job.id)

        def go() -> None:
            try:
                client = self.dask() if remote is not None else None
                if client is not None and remote is not None:
                    start_job(self.engine, job.id, f"dask:{self._scheduler}")
                    out = client.submit(remote[0], *remote[1], key=job.id, pure=False).result()
                else:
                    start_job(self.engine, job.id, self.name)
                    out = work()
                self.store.put_bytes(result_key(job.id), json.dumps(out).encode())
                finish_job(self.engine, job.id, result={"blob": result_key(job.id), **summary(out)})
            except Exception as exc:  # recorded with the job, never lost in the thread
                finish_job(self.engine, job.id, error=f"{type(exc).__name__}: {exc}")
            finally:
                with self._lock:
                    self._in_flight.discard(job.id)

        self._pool.submit(go)

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=False)
        if self._client is not None:
            self._client.close()
