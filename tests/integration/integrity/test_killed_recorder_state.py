"""Issue 64: a recorder killed with SIGKILL showed `recording` in `ls`, `ls --json` and the API,
even after reindexing; only `info` said `interrupted`. A fleet dashboard showed a dead vehicle
as recording. Every reader now asks the session lock (held only by a live recorder)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import httpx
import pytest

from tests.conftest import ApiServer, run_cli, wait_for

pytestmark = pytest.mark.integration


def test_a_killed_recorder_is_interrupted_everywhere(tmp_path):
    root = tmp_path / "root"
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--root", str(root), "--session", "k",
                             "--width", "64", "--height", "48", "--no-analysis"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    session = root / "sessions" / "k"
    assert wait_for(lambda: any(session.glob("*.mcap.active")), 60)
    listed = json.loads(run_cli("ls", "--root", str(root), "--json").stdout)["sessions"]
    assert listed[0]["state"] == "recording"  # alive: it holds the lock
    proc.send_signal(signal.SIGKILL)
    proc.wait(30)
    assert json.loads((session / "session.json").read_text())["status"] == "recording"  # what it left
    listed = json.loads(run_cli("ls", "--root", str(root), "--json").stdout)["sessions"]
    assert listed[0]["state"].startswith("interrupted"), listed
    assert "interrupted" in run_cli("ls", "--root", str(root)).stdout
    server = ApiServer(root, env={k: v for k, v in os.environ.items() if k != "THERMCAP_TOKENS"})
    try:
        with httpx.Client(base_url=server.url, timeout=30) as c:
            assert c.post("/api/v1/index", params={"force": True}).status_code == 200
            (row,) = c.get("/api/v1/sessions").json()["items"]
            assert row["status"] == "interrupted", row
    finally:
        server.stop()
