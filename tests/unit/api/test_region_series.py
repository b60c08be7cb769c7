"""A region's time series read as little as gives the exact answer, against plain numpy over every
decoded frame.

- The whole frame comes from the frame summary: no frame decoded.
- A box reads only its TIFF strips, each checked against its band's CRC-32, including the short
  last band of a frame whose height is not a multiple of 64.
- A damaged strip is reported and that frame is read whole, so the numbers stay right.
- A damaged summary is not trusted.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import tifffile
from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.radiometry import DEFAULT_MODEL
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.segments import SegmentPolicy

SID = "s-strips"
W, H = 96, 150  # three bands of rows: 64, 64 and a short 22


def _record(root, sid=SID, frames=48):
    Recorder(SimSource(width=W, height=H, frames=frames, paced=False, seed=9), root, session_id=sid,
             policy=SegmentPolicy(max_duration_s=0.3), analysis=False).run()
    counts = [f.pixels.copy() for f in iter_session_frames(root / "sessions" / sid)]
    archive_session(root / "sessions" / sid, ["png16", "tiff-lzw"], delete_source=True)
    return counts


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    root = tmp_path_factory.mktemp("strips")
    counts = _record(root)
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        yield root, c, [np.asarray(DEFAULT_MODEL.to_celsius(f), dtype=np.float32).astype(np.float64)
                        for f in counts]


def _series(client, sid=SID, **q):
    r = client.get(f"/api/v1/sessions/{sid}/series", params=q)
    assert r.status_code == 200, r.text
    return r.json()


@pytest.mark.parametrize("stat", ["max", "min", "mean"])
def test_the_whole_frame_comes_from_the_summary_without_decoding(world, stat):
    _, client, temps = world
    body = _series(client, tool="frame", stat=stat)
    assert body["method"] == "summary" and body["frames_decoded"] == 0
    ref = [getattr(t, stat)() for t in temps]
    assert [p["celsius"] for p in body["points"]] == pytest.approx(ref, abs=2e-4)
    assert body["model_versions"] == [0]


@pytest.mark.parametrize(("tool", "rows"), [("box:10,60,40,70", (60, 71)),  # across the first band edge
                                            ("box:5,130,90,149", (130, 150)),  # the short last band
                                            ("spot:7,3", (3, 4))])
@pytest.mark.parametrize("stat", ["max", "mean"])
def test_a_box_reads_only_its_strips(world, tool, rows, stat):
    _, client, temps = world
    body = _series(client, tool=tool, stat=stat)
    assert body["method"] == "strips" and body["frames_decoded"] == 0 and body["strip_frames"] == len(temps)
    kind, nums = tool.split(":")
    v = [int(x) for x in nums.split(",")]
    x0, x1 = v[0], (v[2] if kind == "box" else v[0]) + 1
    ref = [getattr(t[rows[0]:rows[1], x0:x1], stat)() for t in temps]
    assert [p["celsius"] for p in body["points"]] == pytest.approx(ref, abs=2e-4)


def test_start_end_and_step_cross_files(world):
    _, client, temps = world
    body = _series(client, tool="box:0,0,20,20", start=3, end=41, step=5)
    assert [p["frame"] for p in body["points"]] == list(range(3, 41, 5))
    assert [p["celsius"] for p in body["points"]] == pytest.approx([temps[i][:21, :21].max()
                                                                    for i in range(3, 41, 5)], abs=2e-4)


def test_a_damaged_strip_is_reported_and_its_frame_read_whole(tmp_path):
    counts = _record(tmp_path, "s-bad", frames=20)
    tif = sorted((tmp_path / "sessions" / "s-bad" / "archive" / "tiff-lzw").glob("*.tif"))[0]
    with tifffile.TiffFile(tif) as t:
        page = t.pages[2]
        off, n = page.dataoffsets[1], page.databytecounts[1]
    data = bytearray(tif.read_bytes())
    data[off + n // 2: off + n // 2 + 8] = b"\x00" * 8  # rows 64..127 of frame 2
    tif.write_bytes(bytes(data))
    temps = [np.asarray(DEFAULT_MODEL.to_celsius(f), dtype=np.float32).astype(np.float64) for f in counts]
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as client:
        body = _series(client, "s-bad", tool="box:0,60,95,100")
        assert [p["celsius"] for p in body["points"]] == pytest.approx([t[60:101].max() for t in temps], abs=2e-4)
        assert body["frames_decoded"] == 1 and body["strip_frames"] == len(temps) - 1
        health = client.get("/healthz").json()
        assert health["status"] == "degraded" and any(d["frame"] == 2 for d in health["recent"])


def test_a_damaged_summary_is_not_trusted(tmp_path):
    counts = _record(tmp_path, "s-sum", frames=12)
    summary = tmp_path / "sessions" / "s-sum" / "archive" / "summary.npz"
    data = bytearray(summary.read_bytes())
    data[-40] ^= 0xFF
    summary.write_bytes(bytes(data))
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as client:
        body = _series(client, "s-sum", tool="frame")
        assert body["method"] == "frames" and body["frames_decoded"] == len(counts)
        ref = [float(np.asarray(DEFAULT_MODEL.to_celsius(f), dtype=np.float32).max()) for f in counts]
        assert [p["celsius"] for p in body["points"]] == pytest.approx(ref, abs=2e-4)
        assert client.get("/healthz").json()["status"] == "degraded"


def test_the_summary_is_in_the_manifest_and_uploaded_with_the_archive(world):
    root, _, temps = world
    manifest = json.loads((root / "sessions" / SID / "archive" / "manifest.json").read_text())
    entry = manifest["summary"]
    assert entry["frames"] == len(temps) and entry["band_rows"] == 64
    from thermcap.archive.manifest import archived_files

    assert "summary.npz" in {f.rel for f in archived_files(manifest)}


def test_sessions_archived_before_the_summary_are_read_frame_by_frame(tmp_path):
    counts = _record(tmp_path, "s-old", frames=10)
    adir = tmp_path / "sessions" / "s-old" / "archive"
    manifest = json.loads((adir / "manifest.json").read_text())
    del manifest["summary"]
    # as an archive of that release: one manifest, no checksum, no second copy
    manifest.pop("checksum", None)
    (adir / "manifest.copy.json").unlink()
    (adir / "manifest.json").write_text(json.dumps(manifest))
    (adir / "summary.npz").unlink()
    shutil.rmtree(adir / "png16")  # tiff-lzw alone still serves whole frames
    manifest["formats"].pop("png16")
    (adir / "manifest.json").write_text(json.dumps(manifest))
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as client:
        body = _series(client, "s-old", tool="box:1,1,30,30", stat="min")
        assert body["method"] == "frames" and body["frames_decoded"] == len(counts)
        ref = [float(np.asarray(DEFAULT_MODEL.to_celsius(f), dtype=np.float32)[1:31, 1:31].min()) for f in counts]
        assert [p["celsius"] for p in body["points"]] == pytest.approx(ref, abs=2e-4)


def _wait_job(client, jid, timeout=30.0):
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.get(f"/api/v1/jobs/{jid}").json()
        if job["state"] in ("done", "failed"):
            return job
        time.sleep(0.05)
    raise AssertionError(f"job {jid} did not finish: {job}")


def test_a_series_as_a_job_kept_and_found_again(world):
    _, client, temps = world
    q = {"tool": "box:10,60,40,70", "stat": "max", "step": 2}
    r = client.post(f"/api/v1/sessions/{SID}/series/jobs", params=q)
    assert r.status_code in (200, 202), r.text
    job = _wait_job(client, r.json()["id"])
    assert job["state"] == "done" and job["attempts"] == 1 and job["kind"] == "series"
    assert job["result"]["method"] == "strips" and job["result"]["points"] == len(range(0, len(temps), 2))
    got = client.get(job["links"]["result"]).json()
    assert got["points"] == _series(client, **q)["points"]
    csv_rows = client.get(job["links"]["result"], params={"format": "csv"}).text.strip().splitlines()
    assert len(csv_rows) == 1 + len(got["points"])
    again = client.post(f"/api/v1/sessions/{SID}/series/jobs", params=q)  # the same work: the same job, done
    assert again.status_code == 200 and again.json()["id"] == job["id"] and again.json()["attempts"] == 1
    listed = client.get("/api/v1/jobs", params={"kind": "series", "session": SID}).json()["items"]
    assert job["id"] in [j["id"] for j in listed]


def test_a_failing_job_says_why_and_runs_again_when_asked(tmp_path):
    _record(tmp_path, "s-gone", frames=8)
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as client:
        adir = tmp_path / "sessions" / "s-gone" / "archive"
        for fmt in ("png16", "tiff-lzw"):
            shutil.rmtree(adir / fmt)  # every copy gone after indexing
        r = client.post("/api/v1/sessions/s-gone/series/jobs", params={"tool": "box:0,0,10,10"})
        job = _wait_job(client, r.json()["id"])
        assert job["state"] == "failed" and "no verified copy" in job["error"]
        assert client.get(job["links"]["result"]).status_code == 409
        again = client.post("/api/v1/sessions/s-gone/series/jobs", params={"tool": "box:0,0,10,10"})
        assert again.json()["id"] == job["id"]
        assert _wait_job(client, job["id"])["attempts"] == 2


def test_bad_series_jobs_are_400s_and_unknown_jobs_404s(world):
    _, client, _ = world
    assert client.post(f"/api/v1/sessions/{SID}/series/jobs", params={"tool": "box:0,0,500,5"}).status_code == 400
    assert client.get("/api/v1/jobs/series-nope").status_code == 404


def test_thermcap_jobs_lists_them(world):
    from click.testing import CliRunner

    from thermcap.api.cli import jobs

    root, client, _ = world
    client.post(f"/api/v1/sessions/{SID}/series/jobs", params={"tool": "spot:1,1"})
    out = CliRunner().invoke(jobs, ["--root", str(root), "--kind", "series", "--json"])
    assert out.exit_code == 0, out.output
    rows = json.loads(out.output)
    assert rows and all(r["kind"] == "series" and r["session_id"] == SID for r in rows)
    table = CliRunner().invoke(jobs, ["--root", str(root)])
    assert table.exit_code == 0 and "series" in table.output
