"""The fleet's topology, end to end, without Docker, as processes on 127.0.0.1: PostgreSQL,
SeaweedFS, a Dask scheduler and two workers, the API, and a "vehicle" syncing through a link
that throttles and cuts its connection every few MB.

The vehicle records two sessions and ships them with ``thermcap sync --max-rate``. The cloud
then receipts every segment and lands the sessions whole (``thermcap sync-confirm --into``).
The workers archive them segment by segment and upload and index them (``thermcap worker
--scheduler``), and the API serves every frame bit-exact from the bucket. The vehicle sees
every segment confirmed and frees its disk by the receipts.
"""

from __future__ import annotations

import json
import os

import httpx
import numpy as np
import pytest

from tests.conftest import ApiServer, free_port, run_cli
from tests.support.dask_cluster import start_cluster, stop_cluster
from tests.support.link import FlakyLink
from thermcap.recorder.storage.reader import iter_session_frames

pytest.importorskip("boto3", reason="boto3 is in the sync extra (pip install 'thermcap[sync]')")
MiB = 1 << 20


def test_vehicle_to_catalog_through_a_flaky_link_on_a_dask_cluster(postgres_url, seaweedfs, tmp_path):
    vehicle, cloud = tmp_path / "vehicle", tmp_path / "cloud"
    prefix = f"fleet-{tmp_path.name}"
    creds = {"AWS_ACCESS_KEY_ID": seaweedfs["AWS_ACCESS_KEY_ID"],
             "AWS_SECRET_ACCESS_KEY": seaweedfs["AWS_SECRET_ACCESS_KEY"]}
    for sid in ("v1", "v2"):
        r = run_cli("record", "--duration", "1.5", "--width", "320", "--height", "256", "--root", str(vehicle),
                    "--session", sid, "--no-pace", "--no-analysis", "--segment-duration", "0.5")
        assert r.returncode == 0, r.stderr
    recorded = {sid: [f.pixels.copy() for f in iter_session_frames(vehicle / "sessions" / sid)]
                for sid in ("v1", "v2")}
    host, port = seaweedfs["endpoint"].removeprefix("http://").split(":")
    link = FlakyLink((host, int(port)), rate=3_000_000, cut_every=7 * MiB)  # parts of 5 MiB
    try:
        r = run_cli("sync", "--root", str(vehicle), "--bucket", seaweedfs["bucket"], "--endpoint", link.endpoint,
                    "--prefix", prefix, "--max-rate", "2MB/s", "--part-size", "5", "--json",
                    env={**os.environ, **creds}, timeout=600)
        assert r.returncode == 0, r.stderr
    finally:
        link.close()
    assert link.cuts >= 1, "the link never cut: the test did not test resumption"
    env = {**os.environ, **creds, "THERMCAP_DATABASE_URL": postgres_url, "THERMCAP_S3_BUCKET": seaweedfs["bucket"],
           "THERMCAP_S3_ENDPOINT": seaweedfs["endpoint"], "THERMCAP_S3_PREFIX": prefix}
    r = run_cli("sync-confirm", "--into", str(cloud), "--json", env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    confirmed = json.loads(r.stdout)
    assert sorted(confirmed["landing"]["landed"]) == ["v1", "v2"], confirmed
    port_ = free_port()
    sched, workers, client = start_cluster(tmp_path, port_, env=env)
    try:
        r = run_cli("worker", "--root", str(cloud), "--scheduler", f"tcp://127.0.0.1:{port_}", "--once", "--json",
                    "--formats", "png16,tiff-lzw,hdf5", env=env, timeout=600)
        assert r.returncode == 0, r.stderr
        assert sorted(json.loads(r.stdout)["archived"]) == ["v1", "v2"]
        ran_on = {w for w in client.run(os.getpid).values()}
        assert len(ran_on) == 2
    finally:
        stop_cluster(client, (*workers, sched))
    r = run_cli("jobs", "--root", str(cloud), "--json", env=env)
    jobs = [j for j in json.loads(r.stdout) if j["session_id"] in ("v1", "v2")]
    assert {j["kind"] for j in jobs} == {"archive", "archive-segment"} and all(j["state"] == "done" for j in jobs)
    assert len({j["worker"] for j in jobs}) == 2, "the segments did not spread over both workers"
    server = ApiServer(cloud, env=env)
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            assert sorted(s["id"] for s in c.get("/api/v1/sessions").json()["items"]) == ["v1", "v2"]
            for sid, frames in recorded.items():
                for n in (0, len(frames) // 2, len(frames) - 1):
                    raw = c.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw"}).content
                    assert np.array_equal(np.frombuffer(raw, "<u2").reshape(frames[n].shape), frames[n])
                series = c.get(f"/api/v1/sessions/{sid}/series", params={"tool": "frame"}).json()
                assert series["method"] == "summary" and len(series["points"]) == len(frames)
    finally:
        server.stop()
    r = run_cli("sync", "--root", str(vehicle), "--bucket", seaweedfs["bucket"], "--endpoint", seaweedfs["endpoint"],
                "--prefix", prefix, "--delete-confirmed", "--json", env={**os.environ, **creds})
    assert r.returncode == 0, r.stderr
    assert not list((vehicle / "sessions").glob("*/*.mcap")), "confirmed segments stayed on the vehicle"
