"""A series job on the Dask cluster the archive workers use (THERMCAP_DASK_SCHEDULER): a
LocalCluster of one worker process, so the task and its arguments really cross a process
boundary. The answer is the one the API computes itself, and the job says where it ran."""

from __future__ import annotations

import time

import pytest
from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource

pytest.importorskip("distributed", reason="Dask distributed is in the scale extra")


def test_a_series_job_runs_on_the_cluster(tmp_path):
    from distributed import LocalCluster

    Recorder(SimSource(width=96, height=80, frames=30, paced=False, seed=2), tmp_path, session_id="s",
             analysis=False).run()
    archive_session(tmp_path / "sessions" / "s", ["png16", "tiff-lzw"])
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        settings = Settings(root=tmp_path, tokens={}, rescan_interval_s=0, dask_scheduler=cluster.scheduler_address)
        with TestClient(create_app(settings)) as client:
            q = {"tool": "box:5,60,50,70", "stat": "mean"}
            jid = client.post("/api/v1/sessions/s/series/jobs", params=q).json()["id"]
            deadline = time.monotonic() + 120
            while (job := client.get(f"/api/v1/jobs/{jid}").json())["state"] not in ("done", "failed"):
                assert time.monotonic() < deadline, job
                time.sleep(0.1)
            assert job["state"] == "done", job
            assert job["worker"] == f"dask:{cluster.scheduler_address}"
            got = client.get(f"/api/v1/jobs/{jid}/result").json()
            assert got["method"] == "strips"
            assert got["points"] == client.get("/api/v1/sessions/s/series", params=q).json()["points"]
