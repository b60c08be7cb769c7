"""A real Dask cluster as processes on 127.0.0.1: ``dask scheduler`` and ``dask worker``s
without nannies (so a SIGKILL takes a worker for good), with their log in the test's folder."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any


def start_cluster(tmp_path: Path, port: int, workers: int = 2, env: dict[str, str] | None = None) -> \
        tuple[subprocess.Popen, list[subprocess.Popen], Any]:
    import distributed

    log = open(tmp_path / f"dask-{port}.log", "ab")  # noqa: SIM115 - the processes' log, closed with them
    sched = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                              "--port", str(port), "--no-dashboard"], stdout=log, stderr=log, env=env)
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", f"tcp://127.0.0.1:{port}",
                               "--nthreads", "1", "--no-nanny", "--no-dashboard", "--name", f"w{k}",
                               "--host", "127.0.0.1"], stdout=log, stderr=log, env=env) for k in range(workers)]
    client = distributed.Client(f"tcp://127.0.0.1:{port}", timeout=60)
    client.wait_for_workers(workers, timeout=60)
    return sched, procs, client


def stop_cluster(client: Any, processes: tuple[subprocess.Popen, ...] | list[subprocess.Popen]) -> None:
    client.close()
    for p in processes:
        p.kill()
        p.wait()
