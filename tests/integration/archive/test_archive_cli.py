"""Archive a real recorded session in every format, read it with stock libraries, break it."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from tests.conftest import run_cli
from thermcap.archive.archiver import archive_session
from thermcap.archive.manifest import load_manifest
from thermcap.archive.verify import verify_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy

W, H = 160, 120
ALL = ["png16", "tiff-lzw", "hdf5", "jxl", "htj2k", "jpegls"]


@pytest.mark.parametrize("fid", ALL)
def test_verify_catches_one_flipped_byte(session, fid):
    archive_session(session, [fid])
    assert verify_session(session)[fid].ok
    files = sorted((session / "archive" / fid).iterdir())
    target = files[len(files) // 2]
    data = bytearray(target.read_bytes())
    data[len(data) // 2] ^= 0x01
    target.write_bytes(bytes(data))
    report = verify_session(session)[fid]
    assert not report.ok
    assert any(target.name in p for p in report.problems)
    r = run_cli("verify", str(session), "--json")
    assert r.returncode == 1


def test_killed_archive_leaves_no_half_archive_and_rerun_finishes(tmp_path):
    root = tmp_path / "d"
    Recorder(SimSource(width=320, height=256, frames=600, paced=False), root, session_id="k",
             policy=SegmentPolicy(max_duration_s=2)).run()
    session = root / "sessions" / "k"
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "archive", str(session), "--formats", "png16,jxl"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not list((session / "archive").glob("*.partial/*.zip")):
        time.sleep(0.02)
    time.sleep(0.3)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    adir = session / "archive"
    for fid in ("png16", "jxl"):
        final = adir / fid
        if final.exists():  # finished before the kill: then it must be complete and in the manifest
            assert load_manifest(session)["formats"][fid]["verified"]
    assert list(adir.glob("*.partial")), "the kill should have caught a format half-written"
    r = run_cli("archive", str(session), "--formats", "png16,jxl")
    assert r.returncode == 0, r.stderr
    assert not list(adir.glob("*.partial"))
    assert all(v.ok for v in verify_session(session).values())
    assert len(list(session.glob("*.mcap"))) == 5


def test_unknown_format_is_a_clear_cli_error(session):
    r = run_cli("archive", str(session), "--formats", "png16,gif")
    assert r.returncode != 0
    assert "unknown format(s) gif" in r.stderr


def test_audit_reports_costs_and_recommends_the_smallest_verified(archived, tmp_path):
    r = run_cli("audit", str(archived), "--json", "--project-cameras", "4", "--project-hours", "6")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    [group] = rep["groups"]
    fmts = group["formats"]
    smallest = min((k for k in fmts if k != "mcap"), key=lambda k: fmts[k]["bytes"])
    assert group["recommended_format"] == smallest
    std = fmts["png16"]["cost"]["s3-standard"]
    assert std["storage_per_month"] == pytest.approx(fmts["png16"]["bytes"] / 1024**3 * 0.023, rel=1e-3)
    assert std["put_once"] == pytest.approx(4 / 1000 * 0.005)
    assert set(fmts["png16"]["cost"]) == {"s3-standard", "s3-standard-ia", "s3-glacier-ir", "s3-deep-archive", "r2",
                                          "b2"}
    assert next(iter(rep["projection"].values()))["cameras"] == 4
    prices = tmp_path / "p.json"
    prices.write_text(json.dumps({"s3-standard": {"storage": 1.0}}))
    rep2 = json.loads(run_cli("audit", str(archived), "--json", "--prices", str(prices)).stdout)
    assert rep2["groups"][0]["formats"]["png16"]["cost"]["s3-standard"]["storage_per_month"] == pytest.approx(
        fmts["png16"]["bytes"] / 1024**3, rel=1e-3)
    md = run_cli("audit", str(archived), "--markdown").stdout
    assert "| png16 |" in md
    assert "Rule:" in md


