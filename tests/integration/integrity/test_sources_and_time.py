"""Defects 4 and 13: timestamps that lie, and pipes/files that lose frames."""

from __future__ import annotations

import hashlib
import json

import numpy as np
from mcap.reader import make_reader

from tests.conftest import run_cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.icd.topics import decode_image

W, H = 160, 128


def _frames(n: int) -> bytes:
    rng = np.random.default_rng(7)
    base = rng.integers(0, 16384, size=(H, W), dtype=np.uint16)
    out = np.empty((n, H, W), "<u2")
    for i in range(n):
        out[i] = base
        out[i, 0, :2] = (i & 0xFFFF, i >> 16)  # every frame distinct
    return out.tobytes()


def _read(session) -> list[tuple[int, str]]:
    got = []
    for seg in sorted(session.glob("*.mcap")):
        with open(seg, "rb") as f:
            for _, _, msg in make_reader(f).iter_messages(topics=["/thermal/image"]):
                px = decode_image(msg.data)[1]
                got.append((msg.log_time, hashlib.sha256(np.ascontiguousarray(px).tobytes()).hexdigest()))
    return got


def test_a_pipe_loses_no_frame_whatever_the_writer_speed(tmp_path):
    """Defect 13: 1200 frames piped in, 295 written. A pipe can wait: back-pressure, never drops."""
    n = 1200
    data = _frames(n)
    r = run_cli("record", "--source", "raw:-", "--width", str(W), "--height", str(H), "--root", str(tmp_path),
                "--session", "p", "--json", "--queue", "4", "--debug-writer-delay", "0.002", input=data, timeout=300)
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["frames_written"] == n
    assert summary["frames_dropped"] == 0
    assert summary["ok"] is True
    got = _read(tmp_path / "sessions" / "p")
    assert len(got) == n
    want = [hashlib.sha256(data[i * W * H * 2:(i + 1) * W * H * 2]).hexdigest() for i in range(n)]
    assert [h for _, h in got] == want


def test_a_file_without_pace_loses_nothing_and_is_stamped_at_the_declared_rate(tmp_path):
    """Defects 13 and 4: a file read fast dropped frames and was stamped at 436 fps."""
    n = 300
    raw = tmp_path / "f.raw"
    raw.write_bytes(_frames(n))
    r = run_cli("record", "--source", f"raw:{raw}", "--width", str(W), "--height", str(H), "--fps", "60",
                "--root", str(tmp_path), "--session", "f", "--json", "--queue", "4", "--debug-writer-delay", "0.002")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["frames_written"] == n
    assert summary["timing"]["time_basis"] == "stream"
    times = [t for t, _ in _read(tmp_path / "sessions" / "f")]
    steps = np.diff(times)
    assert len(times) == n
    assert np.abs(steps - 1e9 / 60).max() <= 1
    info = json.loads(run_cli("info", str(tmp_path / "sessions" / "f"), "--json").stdout)
    assert info["time_basis"] == "stream"
    assert abs(info["effective_fps"] - 60) < 0.01
    meta = json.loads((tmp_path / "sessions" / "f" / "session.json").read_text())
    assert meta["source"]["time_basis"] == "stream"


def test_a_live_source_that_cannot_keep_its_rate_is_reported_not_hidden(tmp_path):
    """Defect 4: 29.4 fps achieved, timestamps and info said 60 fps with 0 dropped."""
    fps = 1e6  # far more than any machine renders (as 1280x1024@60 is for a slow one): late whatever the host
    res = Recorder(SimSource(width=320, height=256, fps=fps, frames=150, paced=True), tmp_path, session_id="s",
                   analysis=False).run()
    timing = res.timing
    assert timing["time_basis"] == "capture"
    assert timing["achieved_fps"] < fps / 2
    assert timing["frames_late"] > 0
    assert any("late" in p for p in res.problems)
    times = [t for t, _ in _read(tmp_path / "sessions" / "s")]
    stamped_fps = (len(times) - 1) / ((times[-1] - times[0]) / 1e9)
    assert stamped_fps < fps / 2  # the stamps say what happened, not what was declared
    assert abs(stamped_fps - timing["achieved_fps"]) / timing["achieved_fps"] < 0.25
    info = json.loads(run_cli("info", str(tmp_path / "sessions" / "s"), "--json").stdout)
    assert info["frames_late"] == timing["frames_late"]
    stats = []
    with open(next((tmp_path / "sessions" / "s").glob("*.mcap")), "rb") as f:
        for _, ch, msg in make_reader(f).iter_messages(topics=["/recorder/stats"]):
            stats.append(json.loads(json_payload(ch.message_encoding, msg.data)))
    assert stats[-1]["timing"]["frames_late"] == timing["frames_late"]


def test_ok_is_false_when_a_live_source_dropped_frames(tmp_path):
    res = Recorder(SimSource(width=W, height=H, fps=120, frames=120, paced=True), tmp_path, session_id="d",
                   analysis=False, queue_frames=1, writer_delay_s=0.05).run()
    assert res.frames_dropped > 0
    assert res.ok is False
    assert res.to_dict()["ok"] is False
    assert any("dropped" in p for p in res.problems)
