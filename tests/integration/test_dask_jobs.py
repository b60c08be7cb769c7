"""``thermcap worker --local-workers 2``: sessions archived, verified and indexed as Dask tasks
on a LocalCluster of two worker processes, the same code path as a remote cluster. Each task is
keyed by the session's content, so a second pass does nothing and a resubmission is the same task."""

from __future__ import annotations

import json

import pytest

from tests.conftest import run_cli
from thermcap.api.db import make_engine, migrate
from thermcap.api.jobs.worker import Worker
from thermcap.archive.manifest import load_manifest
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource

pytest.importorskip("distributed", reason="Dask distributed is in the scale extra")


def test_sessions_are_archived_as_tasks_on_a_local_cluster(tmp_path):
    root = tmp_path / "root"
    for k in range(3):
        Recorder(SimSource(width=96, height=64, frames=30, paced=False, seed=k), root, session_id=f"s{k}",
                 analysis=False, recover_leftovers=False).run()
    env = {"THERMCAP_DATABASE_URL": f"sqlite:///{tmp_path / 'index.sqlite'}"}
    r = run_cli("worker", "--root", str(root), "--formats", "png16,hdf5", "--local-workers", "2", "--once",
                "--json", env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert sorted(res["archived"]) == ["s0", "s1", "s2"] and not res["failed"]
    for k in range(3):
        m = load_manifest(root / "sessions" / f"s{k}")
        assert m["formats"]["png16"]["verified"] and m["formats"]["hdf5"]["verified"]
    engine = make_engine(env["THERMCAP_DATABASE_URL"])
    from sqlalchemy import text

    with engine.connect() as c:
        assert c.execute(text("select count(*) from sessions")).scalar() == 3
    from thermcap.api.jobs.records import list_jobs

    jobs = list_jobs(engine, kind="archive")  # each session's task, as `thermcap jobs` shows it
    assert sorted(j.session_id for j in jobs) == ["s0", "s1", "s2"]
    assert all(j.state == "done" and j.attempts == 1 and (j.worker or "").startswith("dask:") for j in jobs)
    again = run_cli("worker", "--root", str(root), "--formats", "png16,hdf5", "--local-workers", "2", "--once",
                    "--json", env=env, timeout=300)
    assert again.returncode == 0 and json.loads(again.stdout)["archived"] == []  # nothing to do twice


def test_the_task_key_is_the_content(tmp_path):
    from thermcap.api.jobs.dask_jobs import session_task_key

    root = tmp_path / "root"
    Recorder(SimSource(width=64, height=48, frames=10, paced=False, seed=1), root, session_id="a",
             analysis=False, recover_leftovers=False).run()
    d = root / "sessions" / "a"
    k1 = session_task_key(d, ("png16",))
    assert k1 == session_task_key(d, ("png16",)) and k1.startswith("thermcap-archive-a-")
    assert session_task_key(d, ("png16", "hdf5")) != k1
    engine = make_engine(f"sqlite:///{tmp_path / 'i.sqlite'}")
    migrate(engine)
    from thermcap.api.jobs.dask_jobs import DaskJobs, TaskConfig
    from thermcap.api.jobs.records import get_job

    jobs = DaskJobs(Worker(root, engine, formats=["png16"]),
                    TaskConfig(str(root), ("png16",), f"sqlite:///{tmp_path / 'i.sqlite'}", None, False),
                    local_workers=1, processes=False)
    try:
        assert jobs.run_once().archived == ["a"]
    finally:
        jobs.close()
    job = get_job(engine, k1)  # the task's key is the job's id
    assert job is not None and job.state == "done" and job.kind == "archive" and job.attempts == 1


def test_analysis_runs_as_a_task_after_the_archive(tmp_path):
    """``--analyze``: the detector over a session recorded without it, as a task after its
    finalize; the index then has its targets, and the jobs table the task."""
    root = tmp_path / "root"
    Recorder(SimSource(width=96, height=64, frames=30, paced=False, seed=4, first_cue_s=0.1), root,
             session_id="quiet", analysis=False, recover_leftovers=False).run()
    env = {"THERMCAP_DATABASE_URL": f"sqlite:///{tmp_path / 'index.sqlite'}"}
    r = run_cli("worker", "--root", str(root), "--formats", "png16", "--analyze", "--once", "--json", env=env,
                timeout=300)
    assert r.returncode == 0, r.stderr
    assert (root / "sessions" / "quiet" / "analysis.jsonl").is_file()
    from thermcap.api.jobs.records import list_jobs

    engine = make_engine(env["THERMCAP_DATABASE_URL"])
    kinds = {j.kind: j for j in list_jobs(engine, session_id="quiet")}
    assert kinds["analysis"].state == "done" and kinds["analysis"].result["frames"] == 30
    from sqlalchemy import text

    with engine.connect() as c:
        assert c.execute(text("select has_targets from sessions where id = 'quiet'")).scalar()
