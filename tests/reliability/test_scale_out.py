"""The compose topology without Docker: PostgreSQL and SeaweedFS as local processes on 127.0.0.1,
recorder -> archiver workers -> API, end to end."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys

import httpx
import numpy as np
from blake3 import blake3

from tests.conftest import ApiServer, run_cli
from thermcap.recorder.storage.reader import iter_session_frames


def test_recorder_worker_api_over_postgresql_and_seaweedfs(postgres_url, seaweedfs, tmp_path):
    root = tmp_path / "data"
    env = {"THERMCAP_DATABASE_URL": postgres_url, "THERMCAP_S3_BUCKET": seaweedfs["bucket"],
           "THERMCAP_S3_ENDPOINT": seaweedfs["endpoint"], "THERMCAP_S3_PREFIX": f"e2e-{tmp_path.name}",
           "AWS_ACCESS_KEY_ID": seaweedfs["AWS_ACCESS_KEY_ID"],
           "AWS_SECRET_ACCESS_KEY": seaweedfs["AWS_SECRET_ACCESS_KEY"]}
    for i in range(3):
        r = run_cli("record", "--duration", "0.5", "--width", "160", "--height", "128", "--root", str(root),
                    "--session", f"s{i}", "--no-pace", "--no-analysis", env=env)
        assert r.returncode == 0, r.stderr
    expected = {f"s{i}": [f.pixels.copy() for f in iter_session_frames(root / "sessions" / f"s{i}")] for i in range(3)}
    # Two workers at once on one root and one bucket (each with its own in-process cluster): the
    # session and segment locks let one write each thing, the other finds it done.
    procs = [subprocess.Popen([sys.executable, "-m", "thermcap", "worker", "--root", str(root), "--once", "--json",
                               "--formats", "png16,hdf5"], env={**__import__("os").environ, **env},
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        results.append(json.loads(out))
    archived = set(results[0]["archived"]) | set(results[1]["archived"])
    assert archived == {"s0", "s1", "s2"} and not results[0]["failed"] and not results[1]["failed"], results
    for i in range(3):
        m = json.loads((root / "sessions" / f"s{i}" / "archive" / "manifest.json").read_text())
        assert m["upload"]["complete"]
        assert all(e["verified"] for e in m["formats"].values())
    again = run_cli("worker", "--root", str(root), "--once", "--json", "--formats", "png16,hdf5", env=env)
    assert json.loads(again.stdout)["archived"] == []  # nothing left to do
    from thermcap.api.db import make_engine
    from thermcap.api.jobs.records import list_jobs

    jobs = list_jobs(make_engine(postgres_url), kind="archive", limit=1000)  # the index may be shared by other tests
    assert {"s0", "s1", "s2"} <= {j.session_id for j in jobs if j.state == "done"}
    server = ApiServer(root, env=env)
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            items = c.get("/api/v1/sessions").json()["items"]
            assert sorted(s["id"] for s in items) == ["s0", "s1", "s2"]
            for sid, frames in expected.items():
                raw = c.get(f"/api/v1/sessions/{sid}/frames/7", params={"format": "raw"}).content
                assert np.array_equal(np.frombuffer(raw, "<u2").reshape(frames[7].shape), frames[7])
            f = c.get("/api/v1/sessions/s1").json()["archives"]
            png = next(a for a in f if a["format"] == "png16")["files"][0]
            body = c.get(png["url"]).content
            assert blake3(body).hexdigest() == png["blake3"]
    finally:
        server.stop()


def test_gc_frees_local_disk_and_the_bucket_keeps_serving_dji_frames(postgres_url, seaweedfs, tmp_path, samples):
    """Scale-out retention: a DJI import archived and uploaded, then ``gc`` deletes the local
    session; the catalog keeps it, and its frames and rebuilt R-JPEG come from SeaweedFS alone
    (pixels from the png16 ZIP, DJI segments from extras.mcap, both by ranged reads)."""
    root = tmp_path / "data"
    env = {"THERMCAP_DATABASE_URL": postgres_url, "THERMCAP_S3_BUCKET": seaweedfs["bucket"],
           "THERMCAP_S3_ENDPOINT": seaweedfs["endpoint"], "THERMCAP_S3_PREFIX": f"gc-{tmp_path.name}",
           "AWS_ACCESS_KEY_ID": seaweedfs["AWS_ACCESS_KEY_ID"],
           "AWS_SECRET_ACCESS_KEY": seaweedfs["AWS_SECRET_ACCESS_KEY"]}
    r = run_cli("import", str(samples / "dji" / "DJI_H20T.jpg"), "--root", str(root), "--session", "h20t",
                "--no-analysis", "--dji-sdk", "off", env=env)
    assert r.returncode == 0, r.stderr
    r = run_cli("export", "h20t", "--root", str(root), "--to", "dji-rjpeg", "--out", str(tmp_path / "rebuilt"))
    assert r.returncode == 0, r.stderr
    rebuilt = (tmp_path / "rebuilt" / "DJI_H20T.jpg").read_bytes()
    r = run_cli("worker", "--root", str(root), "--once", "--json", "--formats", "png16", env=env)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["archived"] == ["h20t"], r.stderr
    r = run_cli("gc", "--root", str(root), "--keep-days", "0", "--json", env=env)
    assert r.returncode == 0, r.stderr
    assert not (root / "sessions" / "h20t").exists()
    ref = json.loads((samples / "dji" / "reference.json").read_text())["DJI_H20T.jpg"]
    server = ApiServer(root, env=env)
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            assert [s["id"] for s in c.get("/api/v1/sessions").json()["items"]] == ["h20t"]
            raw = c.get("/api/v1/sessions/h20t/frames/0", params={"format": "raw"}).content
            assert hashlib.sha256(raw).hexdigest() == ref["raw_sha256"]
            assert c.get("/api/v1/sessions/h20t/frames/0", params={"format": "dji-rjpeg"}).content == rebuilt
    finally:
        server.stop()
