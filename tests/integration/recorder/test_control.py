"""``thermcap record --control`` and ``thermcap ctl`` as real processes over HTTP on 127.0.0.1:
splits lose and repeat no frame, a pause is a recorded gap, marks land on the events topic and in
events.json, the token guards every route but /healthz, metrics and health tell the truth."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from itertools import pairwise

import httpx

from tests.conftest import run_cli, wait_for
from thermcap.recorder.storage.info import info
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

TOKEN = "control-test-token-0123456789"


def _start(root, *extra: str) -> tuple[subprocess.Popen, str]:
    env = {**os.environ, "THERMCAP_CONTROL_TOKEN": TOKEN}
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--root", str(root), "--session", "c",
                             "--width", "160", "--height", "128", "--control", "--no-analysis", *extra],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    address = root / "run" / "c.control.json"
    assert wait_for(address.is_file, 60), proc.stderr.read() if proc.poll() is not None else "no control file"
    return proc, json.loads(address.read_text())["url"]


def test_splits_pause_and_marks_while_recording(tmp_path):
    proc, url = _start(tmp_path)
    auth = {"Authorization": f"Bearer {TOKEN}"}
    try:
        with httpx.Client(base_url=url, timeout=10) as c:
            assert c.get("/healthz").status_code == 200  # open, for the supervisor
            assert c.get("/status").status_code == 401
            assert c.post("/split").status_code == 401
            assert wait_for(lambda: c.get("/status", headers=auth).json()["frames_written"] > 10, 30)
            for _ in range(100):
                assert c.post("/split", headers=auth).status_code == 202
                time.sleep(0.01)
            assert c.post("/mark", headers=auth, json={"note": "deer on the road"}).status_code == 202
            assert c.post("/pause", headers=auth).json()["changed"] is True
            time.sleep(0.5)
            assert c.get("/healthz").status_code == 200  # paused is not stalled
            assert c.post("/resume", headers=auth).json()["changed"] is True
            time.sleep(0.3)
            status = c.get("/status", headers=auth).json()
            assert status["healthy"], status
            metrics = c.get("/metrics", headers=auth).text
            assert "thermcap_recorder_frames_written_total{camera=" in metrics
            assert "thermcap_recorder_disk_free_bytes" in metrics
            assert "thermcap_recorder_segments_settling " in metrics  # a gauge, also when nothing waits
        ctl = run_cli("ctl", "status", "--root", str(tmp_path), env={"THERMCAP_CONTROL_TOKEN": TOKEN})
        assert ctl.returncode == 0, ctl.stderr
        assert "c: recording, healthy" in ctl.stdout
        assert run_cli("ctl", "mark", "--root", str(tmp_path), "--note", "second",
                       env={"THERMCAP_CONTROL_TOKEN": TOKEN}).returncode == 0
        assert run_cli("ctl", "status", "--root", str(tmp_path)).returncode == 1  # no token: refused
        time.sleep(0.3)
    finally:
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    session = tmp_path / "sessions" / "c"
    d = info(session)
    assert len(d.segments) > 50  # the splits really split
    frames = list(iter_session_frames(session))
    assert len(frames) == d.frames
    meta = read_session_meta(session)
    assert meta["frames_captured"] == d.frames + meta["frames_paused"]
    # no frame lost or repeated across 100 splits: the sidecar frame indices run on, except the pause
    idx = [json.loads(f.sidecar)["capture"]["frame_index"] for f in frames]
    assert len(set(idx)) == len(idx)
    gaps = [(a, b) for a, b in pairwise(idx) if b != a + 1]
    assert len(gaps) == 1
    assert gaps[0][1] - gaps[0][0] - 1 == meta["frames_paused"] > 0
    assert len(d.pauses) == 1
    start, end = d.pauses[0]
    assert end - start > 0.3e9
    events = json.loads((session / "events.json").read_text())["events"]
    marks = [e for e in events if e["kind"] == "mark"]
    assert [m["note"] for m in marks] == ["deer on the road", "second"]
    assert sum(e["kind"] == "split" for e in events) == 100
    assert {"pause", "resume"} <= {e["kind"] for e in events}
    recorded = [e for e in events if e["kind"] in ("mark", "split", "pause", "resume", "trigger")]
    assert d.topics["/recorder/events"].messages == len(recorded)  # each also on the events topic
    assert not (tmp_path / "run" / "c.control.json").exists()  # the address goes with the recorder
