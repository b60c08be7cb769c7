"""`thermcap scrub [--repair]`: damaged copies are found, marked (the API stops offering them)
and rebuilt from another verified copy."""

from __future__ import annotations

import json

import numpy as np
from fastapi.testclient import TestClient

from tests.conftest import run_cli
from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.archive.archiver import archive_session
from thermcap.archive.manifest import load_manifest
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames


def _flip(path, at=None):
    data = bytearray(path.read_bytes())
    data[len(data) // 2 if at is None else at] ^= 0x04
    path.write_bytes(bytes(data))


def _root(tmp_path, formats=("png16", "hdf5"), delete=True):
    Recorder(SimSource(width=64, height=48, frames=24, paced=False, start_time_ns=1_800_000_000_000_000_000),
             tmp_path, session_id="s", analysis=False).run()
    session = tmp_path / "sessions" / "s"
    truth = [np.array(f.pixels) for f in iter_session_frames(session)]
    archive_session(session, list(formats), delete_source=delete)
    return session, truth


def test_scrub_marks_damage_and_the_api_stops_offering_that_copy(tmp_path):
    session, truth = _root(tmp_path)
    _flip(session / "archive" / "png16" / "0000.zip")
    r = run_cli("scrub", str(tmp_path), "--json")
    assert r.returncode == 1
    report = json.loads(r.stdout)
    assert report["damaged"] == 1
    assert report["findings"][0]["copy"] == "png16"
    assert load_manifest(session)["formats"]["png16"]["damaged"]["problems"]
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as c:
        offered = {a["format"]: a["verified"] for a in c.get("/api/v1/sessions/s").json()["archives"]}
        assert offered == {"png16": False, "hdf5": True}
        for i in range(24):
            raw = c.get(f"/api/v1/sessions/s/frames/{i}", params={"format": "raw"}).content
            assert raw == truth[i].astype("<u2").tobytes()
        assert c.get("/api/v1/sessions/s/archives/png16/0000.zip").status_code == 404
        assert c.get("/healthz").json()["damaged_copies_seen"] == 0  # nothing damaged was even tried


def test_scrub_repair_rebuilds_from_another_verified_copy_and_verifies_it(tmp_path):
    session, _truth = _root(tmp_path)
    good = (session / "archive" / "png16" / "0000.zip").read_bytes()
    _flip(session / "archive" / "png16" / "0000.zip")
    r = run_cli("scrub", str(tmp_path), "--repair", "--json")
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.loads(r.stdout)
    assert report["repaired"] == 1
    assert report["findings"][0]["repaired_from"] == "hdf5"
    m = load_manifest(session)
    assert "damaged" not in m["formats"]["png16"]
    assert (session / "archive" / "png16" / "0000.zip").read_bytes() == good  # deterministic: the same bytes
    assert run_cli("verify", str(session)).returncode == 0
    again = json.loads(run_cli("scrub", str(tmp_path), "--json").stdout)
    assert again["damaged"] == 0


def test_scrub_repair_from_the_mcap_source_while_it_is_there(tmp_path):
    session, _ = _root(tmp_path, formats=("tiff-lzw",), delete=False)
    _flip(session / "archive" / "tiff-lzw" / "0000.tif")
    report = json.loads(run_cli("scrub", str(tmp_path), "--repair", "--json").stdout)
    assert report["findings"][0]["repaired_from"] == "mcap source"
    assert report["ok"] is True


def test_a_copy_that_cannot_be_repaired_stays_marked_and_exits_1(tmp_path):
    session, _ = _root(tmp_path, formats=("png16",))
    _flip(session / "archive" / "extras.mcap", at=200)
    r = run_cli("scrub", str(tmp_path), "--repair", "--json")
    assert r.returncode == 1
    report = json.loads(r.stdout)
    assert report["findings"][0]["copy"] == "extras"
    assert report["findings"][0]["repaired"] is False
    assert "no MCAP source" in report["findings"][0]["repair_error"]
    assert load_manifest(session)["extras"]["damaged"]
