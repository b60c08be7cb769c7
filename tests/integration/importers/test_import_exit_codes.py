"""Issue 37: ``thermcap import`` exited 1 when every file imported, with no reason printed, and its
JSON blamed "the detector fell behind" for DJI frames that only lack temperatures. Exit codes
now mean one thing each: 0 every file imported (with or without temperature), 1 a file failed,
with the reason; the JSON says per file what is missing and why."""

from __future__ import annotations

import json

from tests.conftest import run_cli


def test_dji_frames_without_temperatures_import_with_exit_0(samples, tmp_path):
    files = sorted(str(p) for p in (samples / "dji").glob("*.[jJ][pP][gG]"))
    assert files
    r = run_cli("import", *files, "--root", str(tmp_path), "--dji-sdk", "off", "--json", timeout=600)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert len(doc["files"]) == len(files) and not doc["failed"]
    no_temps = [f for f in doc["files"] if f["celsius"] is None]
    assert no_temps, "some DJI layouts have no temperature without DJI's SDK"
    for f in no_temps:
        assert "temperature" in f["missing"] and f["missing"]["temperature"]
    for s in doc["sessions"]:
        assert not any("fell behind" in p for p in s["problems"]), s["problems"]
        assert s["analysis_skipped"] == 0


def test_a_broken_file_exits_1_and_says_why(samples, tmp_path):
    bad = tmp_path / "cut.jpg"
    bad.write_bytes((samples / "flir" / "FLIR_E40.jpg").read_bytes()[:3000])
    r = run_cli("import", str(bad), str(samples / "flir" / "FLIR_E40.jpg"), "--root", str(tmp_path / "r"))
    assert r.returncode == 1
    assert "cut.jpg" in r.stderr and "error:" in r.stderr and "Traceback" not in r.stderr
