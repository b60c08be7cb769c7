"""Cameras that arrive through a pipe: ``raw:`` takes any readable path (a named FIFO, a device,
/dev/stdin), and ``exec:COMMAND`` supervises a command that writes raw Gray16 (ffmpeg reading a
V4L2 camera, a vendor's tool): when the command ends, the recording goes on, the command is
started again with backoff, and the gap is recorded. Real processes throughout: ffmpeg's
``testsrc`` is the camera, and it is killed mid-stream."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.conftest import run_cli, wait_for
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.integration

W, H = 64, 48
TOKEN = "command-source-token-0123456789"
needs_ffmpeg = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg is not installed (apt: ffmpeg)")


def _ffmpeg_frames(n: int) -> np.ndarray:
    """The first ``n`` frames ffmpeg's testsrc gives, read straight from ffmpeg."""
    out = subprocess.run(["ffmpeg", "-v", "error", "-f", "lavfi", "-i", f"testsrc=size={W}x{H}:rate=30",
                          "-frames:v", str(n), "-pix_fmt", "gray16le", "-f", "rawvideo", "-"],
                         capture_output=True, check=True, timeout=60).stdout
    return np.frombuffer(out, "<u2").reshape(n, H, W)


def test_raw_reads_a_named_fifo(tmp_path):
    """Issue 63: ``raw:FIFO`` was refused with "no such file" (the source wanted a regular file)."""
    fifo = tmp_path / "camera.fifo"
    os.mkfifo(fifo)
    frames = (np.arange(12 * H * W, dtype=np.uint32) % 16384).astype("<u2").reshape(12, H, W)

    def feed() -> None:
        with open(fifo, "wb") as f:  # blocks until the recorder opens the other end
            for frame in frames:
                f.write(frame.tobytes())

    writer = threading.Thread(target=feed, daemon=True)
    writer.start()
    root = tmp_path / "root"
    r = run_cli("record", "--root", str(root), "--session", "fifo", "--source", f"raw:{fifo}", "--width", str(W),
                "--height", str(H), "--json")
    writer.join(timeout=60)
    assert r.returncode == 0, r.stderr
    got = [f.pixels for f in iter_session_frames(root / "sessions" / "fifo")]
    assert len(got) == len(frames) and all(np.array_equal(a, b) for a, b in zip(got, frames, strict=True))


def test_raw_refuses_a_path_it_cannot_read(tmp_path):
    r = run_cli("record", "--root", str(tmp_path / "root"), "--source", f"raw:{tmp_path / 'nothing'}", "--width",
                "32", "--height", "24")
    assert r.returncode != 0 and "no such file" in r.stderr and "Traceback" not in r.stderr


@needs_ffmpeg
def test_a_command_that_dies_is_started_again_and_the_gap_recorded(tmp_path):
    pids = tmp_path / "pids"
    camera = (f"sh -c 'echo $$ >> {pids}; exec ffmpeg -v error -re -f lavfi -i testsrc=size={W}x{H}:rate=30 "
              f"-pix_fmt gray16le -f rawvideo -'")
    root = tmp_path / "root"
    env = {**os.environ, "THERMCAP_CONTROL_TOKEN": TOKEN}
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--root", str(root), "--session", "cam",
                             "--source", f"exec:{camera}", "--width", str(W), "--height", str(H), "--fps", "30",
                             "--control", "--json"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        address = root / "run" / "cam.control.json"
        assert wait_for(address.is_file, 60), proc.stderr.read() if proc.poll() is not None else "no control file"
        url = json.loads(address.read_text())["url"]
        with httpx.Client(base_url=url, timeout=10, headers={"Authorization": f"Bearer {TOKEN}"}) as c:
            def status() -> dict:
                return c.get("/status").json()

            assert wait_for(lambda: status()["frames_written"] >= 10, 60)
            (first,) = [int(p) for p in pids.read_text().split()]
            os.kill(first, signal.SIGKILL)  # the camera goes away mid-stream
            assert wait_for(lambda: status()["source_health"].get("restarts") == 1, 60), status()
            before = status()["frames_written"]
            # frames flow again from the command started anew, in the same recording
            assert wait_for(lambda: status()["frames_written"] >= before + 10, 60), status()
            assert status()["source_health"]["gaps"] == 1 and proc.poll() is None
    finally:
        proc.send_signal(signal.SIGINT)  # a clean stop, as Ctrl-C
        out, err = proc.communicate(timeout=120)
    assert proc.returncode == 4, err  # the recording held; the source lost frames: the exit status says so
    result = json.loads(out)
    assert result["source_health"]["restarts"] == 1 and not result["ok"], result
    assert any("started again" in p for p in result["problems"]), result["problems"]
    events = json.loads((root / "sessions" / "cam" / "events.json").read_text())["events"]
    gaps = [e for e in events if e["kind"] == "source_gap"]
    assert len(gaps) == 1 and gaps[0]["duration_s"] > 0 and "SIGKILL" in gaps[0]["reason"], events
    frames = list(iter_session_frames(root / "sessions" / "cam"))
    # every frame recorded is a whole frame of the camera's: the first run's from testsrc's start
    first_run = [f for f in frames if f.log_time <= gaps[0]["start_ns"]]
    want = _ffmpeg_frames(len(first_run))
    assert first_run and all(np.array_equal(f.pixels, w) for f, w in zip(first_run, want, strict=True))
    second_run = [f for f in frames if f.log_time >= gaps[0]["end_ns"]]
    assert len(second_run) >= 10 and np.array_equal(second_run[0].pixels, want[0])  # testsrc from its start
    assert len(first_run) + len(second_run) == len(frames)
    times = [f.log_time for f in frames]
    assert times == sorted(times) and len(set(times)) == len(times)


def test_exec_refuses_a_program_that_does_not_exist(tmp_path):
    r = run_cli("record", "--root", str(tmp_path / "root"), "--source", "exec:no-such-camera-tool --go",
                "--width", "32", "--height", "24", "--duration", "1")
    assert r.returncode != 0 and "no-such-camera-tool" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_the_vehicle_page_names_both(tmp_path):
    page = (Path(__file__).resolve().parents[3] / "docs" / "how-to" / "vehicle.md").read_text()
    assert "exec:" in page and "Boson" in page and "Lepton" in page
