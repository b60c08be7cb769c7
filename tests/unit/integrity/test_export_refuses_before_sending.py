"""Issue 65, defect 17: ``export.mcap`` of a session with a zero-byte segment sent 200 and stopped
mid-body (the server logged "response already started"). An unreadable segment is now said
before the first byte: 409 naming it, and ``cut`` names it too."""

from __future__ import annotations

from fastapi.testclient import TestClient

from tests.conftest import run_cli
from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy


def test_a_zero_byte_segment_is_refused_before_a_byte_is_sent(tmp_path):
    root = tmp_path / "root"
    Recorder(SimSource(width=32, height=24, frames=30, paced=False, seed=6), root, session_id="s", analysis=False,
             policy=SegmentPolicy(max_duration_s=0.25)).run()
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        (root / "sessions" / "s" / "0001.mcap").write_bytes(b"")
        r = c.get("/api/v1/sessions/s/export.mcap")
        assert r.status_code == 409 and "0001.mcap" in r.json()["error"], (r.status_code, r.content[:200])
    cut = run_cli("cut", "--root", str(root), "s", "--out", str(tmp_path / "c.mcap"))
    assert cut.returncode != 0 and "0001.mcap" in cut.stderr and "Traceback" not in cut.stderr
    assert not (tmp_path / "c.mcap").exists()
