"""Jobs on a real Dask cluster of processes on 127.0.0.1 (a scheduler and two workers without
nannies): kill -9 the worker running a session's task. The scheduler runs it again on the other
worker, the result is exactly one verified archive, and no partial archive is left under a final
name. Then the scheduler itself is killed mid-task; a new one and a rerun finish from durable
state (the manifest and the .partial folders the rerun replaces)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from tests.conftest import free_port
from tests.support.dask_cluster import start_cluster, stop_cluster
from thermcap.archive.verify import verify_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy

pytestmark = pytest.mark.slow
distributed = pytest.importorskip("distributed", reason="Dask distributed is in the scale extra")
FORMATS = "png16,tiff-lzw,hdf5"


def _cluster(tmp_path, port):
    return start_cluster(tmp_path, port)


def _stop(client, processes):
    stop_cluster(client, processes)


def _running_worker_pid(client, timeout=60.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        busy = [addr for addr, keys in client.processing().items() if keys]
        if busy:
            return client.run(os.getpid, workers=busy[:1])[busy[0]]
        time.sleep(0.1)
    raise TimeoutError("no worker took the task")


def _record(root, sid):
    Recorder(SimSource(width=640, height=512, frames=240, paced=False, seed=3), root, session_id=sid,
             analysis=False, recover_leftovers=False, policy=SegmentPolicy(max_duration_s=1.0)).run()
    return root / "sessions" / sid


def _worker_cmd(root, port):
    return [sys.executable, "-m", "thermcap", "worker", "--root", str(root), "--formats", FORMATS,
            "--scheduler", f"tcp://127.0.0.1:{port}", "--once", "--json"]


def _check_one_verified_archive(session):
    checks = verify_session(session, FORMATS.split(","))
    assert all(c.ok for c in checks.values()), checks
    assert not list((session / "archive").glob("*.partial")), "a partial archive was left behind"
    assert sorted(p.name for p in (session / "archive").iterdir() if p.is_dir()) == sorted(FORMATS.split(","))


def _check_job(env, sid):
    """The jobs table tells the story: the session's archive job done, every segment's job done,
    and the one the kill interrupted run more than once, on Dask."""
    from thermcap.api.db import make_engine
    from thermcap.api.jobs.records import list_jobs

    jobs = list_jobs(make_engine(env["THERMCAP_DATABASE_URL"]), session_id=sid)
    archive = [j for j in jobs if j.kind == "archive"]
    assert len(archive) == 1 and archive[0].state == "done", jobs
    assert all(j.state == "done" for j in jobs) and any(j.kind == "archive-segment" for j in jobs), jobs
    assert any(j.attempts >= 2 for j in jobs), jobs
    assert all((j.worker or "").startswith("dask:tcp://127.0.0.1:") for j in jobs)


def test_a_worker_killed_mid_task_costs_a_rerun_not_an_archive(tmp_path):
    root = tmp_path / "root"
    session = _record(root, "big")
    port = free_port()
    sched, workers, client = _cluster(tmp_path, port)
    env = {**os.environ, "THERMCAP_DATABASE_URL": f"sqlite:///{tmp_path / 'index.sqlite'}"}
    try:
        job = subprocess.Popen(_worker_cmd(root, port), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        pid = _running_worker_pid(client)
        time.sleep(1.0)  # mid-task
        os.kill(pid, signal.SIGKILL)
        out, err = job.communicate(timeout=300)
        assert job.returncode == 0, err
        assert json.loads(out)["archived"] == ["big"]
        _check_one_verified_archive(session)
        _check_job(env, "big")
    finally:
        _stop(client, (*workers, sched))


def test_the_scheduler_killed_mid_task_and_a_rerun_finish_from_durable_state(tmp_path):
    root = tmp_path / "root"
    session = _record(root, "big2")
    env = {**os.environ, "THERMCAP_DATABASE_URL": f"sqlite:///{tmp_path / 'index.sqlite'}"}
    port = free_port()
    sched, workers, client = _cluster(tmp_path, port)
    try:
        job = subprocess.Popen(_worker_cmd(root, port), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        _running_worker_pid(client)
        time.sleep(1.0)
        _stop(client, (sched, *workers))  # the scheduler dies; its workers go with it
        job.communicate(timeout=120)
        assert job.returncode != 0  # the submitter saw the cluster go
    finally:
        for p in (*workers, sched):  # already stopped unless the test failed before
            p.kill()
    port = free_port()
    sched, workers, client = _cluster(tmp_path, port)
    try:
        r = subprocess.run(_worker_cmd(root, port), env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["archived"] == ["big2"]
        _check_one_verified_archive(session)
        _check_job(env, "big2")
    finally:
        _stop(client, (*workers, sched))
