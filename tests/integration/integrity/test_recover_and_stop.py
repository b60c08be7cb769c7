"""Defects 1-3 of the integrity issue: recover racing a live recording, a segment that fails to
close, a double Ctrl-C. Real recorder processes, real files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from mcap.reader import make_reader

from tests.conftest import run_cli, wait_for
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import RecordingError
from thermcap.recorder.storage.lock import holder
from thermcap.recorder.storage.recover import recover_path, recover_segment
from thermcap.recorder.storage.segments import SegmentPolicy, SessionWriter


def _images(session: Path) -> int:
    n = 0
    for seg in sorted(session.glob("*.mcap")):
        with open(seg, "rb") as f:
            s = make_reader(f).get_summary()
        ids = [c.id for c in s.channels.values() if c.topic == "/thermal/image"]
        n += sum(s.statistics.channel_message_counts.get(i, 0) for i in ids)
    return n


def _record(root: Path, *args: str, analysis: bool = False) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--width", "320", "--height", "256",
                             "--root", str(root), "--session", "s", "--analysis" if analysis else "--no-analysis",
                             *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def test_recover_skips_a_live_recording_and_loses_nothing(tmp_path):
    """Defect 1: `recover` during a recording overwrote and unlinked the recorder's files."""
    proc = _record(tmp_path, "--duration", "4", "--segment-duration", "1.5")
    session = tmp_path / "sessions" / "s"
    assert wait_for(lambda: any(session.glob("*.mcap.active")), timeout=30)
    time.sleep(1.0)
    closed = {p.name: p.read_bytes() for p in session.glob("*.mcap")}
    r = run_cli("recover", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "skipped" in (r.stdout + r.stderr)
    assert "recorder" in (r.stdout + r.stderr)
    for name, data in closed.items():
        assert (session / name).read_bytes() == data
    _out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err.decode()
    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] == "complete"
    assert not list(session.glob("*.active"))
    assert _images(session) == meta["frames_written"]
    assert meta["frames_written"] == meta["frames_captured"]


def test_recover_path_refuses_a_locked_session_in_process(tmp_path):
    rec = Recorder(SimSource(width=64, height=48, frames=None, paced=True), tmp_path, session_id="s",
                   analysis=False, policy=SegmentPolicy(max_duration_s=None))
    t = threading.Thread(target=rec.run, kwargs={"duration_s": 30})
    t.start()
    session = tmp_path / "sessions" / "s"
    try:
        assert wait_for(lambda: any(session.glob("*.active")), timeout=20)
        assert "recorder" in (holder(session) or "")
        results = recover_path(session)
        assert [r.skipped for r in results] == [True]
        assert "recorder" in results[0].stopped_because
        assert list(session.glob("*.active"))  # the live segment is untouched
    finally:
        rec.stop()
        t.join(30)
    assert not t.is_alive()
    assert json.loads((session / "session.json").read_text())["status"] == "complete"


def test_recover_never_replaces_a_file_it_did_not_create(tmp_path):
    """The final name appears between the check and the rename: recovery keeps the newcomer."""
    Recorder(SimSource(width=64, height=48, frames=30, paced=False), tmp_path, session_id="s", analysis=False).run()
    session = tmp_path / "sessions" / "s"
    seg = session / "0000.mcap"
    active = session / "0000.mcap.active"
    data = seg.read_bytes()
    active.write_bytes(data[: len(data) // 2])  # a cut copy waiting for recovery
    import thermcap.recorder.storage.recover as rmod

    real = rmod.ChunkedWriter.finish

    def finish_then_race(self, *a, **kw):
        out = real(self, *a, **kw)
        seg.write_bytes(data)  # a finished segment takes the name while we were writing
        return out

    seg.unlink()
    rmod.ChunkedWriter.finish = finish_then_race
    try:
        try:
            recover_segment(active)
            raise AssertionError("recovery replaced a file it did not create")
        except Exception as exc:
            assert "exists" in str(exc)
    finally:
        rmod.ChunkedWriter.finish = real
    assert seg.read_bytes() == data
    assert active.exists()
    assert not list(session.glob("*.recovering"))


def test_failed_last_segment_close_exits_naming_the_segment(tmp_path, monkeypatch):
    """Defect 2: the writer consumed the stop token and _abort() waited for it forever."""
    def fail_close(self):
        raise RecordingError(f"cannot close segment {self.dir / '0000.mcap.active'}: No space left on device")

    monkeypatch.setattr(SessionWriter, "close_segment", fail_close)
    rec = Recorder(SimSource(width=64, height=48, frames=20, paced=False), tmp_path, session_id="s", analysis=False)
    box = {}
    t = threading.Thread(target=lambda: box.setdefault("r", rec.run()), daemon=True)
    t.start()
    t.join(20)
    assert not t.is_alive(), "the recorder hung after a failed close"
    res = box["r"]
    assert not res.ok
    assert "0000.mcap.active" in res.error
    assert (tmp_path / "sessions" / "s" / "0000.mcap.active").exists()


def test_full_disk_at_finish_exits_1_and_leaves_active_for_recover(tmp_path):
    """Defect 2 as reported: a small tmpfs fills during finish."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=5000k", "tmpfs", str(mnt)],
                                           capture_output=True).returncode != 0:
        import pytest
        pytest.skip("cannot mount a small tmpfs here (needs root and mount rights)")
    try:
        r = run_cli("record", "--duration", "1", "--width", "320", "--height", "256", "--root", str(mnt),
                    "--session", "s", "--no-analysis", "--compression", "none", timeout=60)
        assert r.returncode == 1
        assert ".mcap" in r.stderr
        assert "No space" in r.stderr or "space" in r.stderr
        session = mnt / "sessions" / "s"
        assert list(session.glob("*.mcap.active")), "the open segment must stay for recover"
        info = json.loads(run_cli("info", str(session), "--json").stdout)
        assert info["status"] in ("interrupted", "failed")  # session.json may be unwritable: the lock tells
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def test_double_ctrl_c_finishes_and_status_tells_the_truth(tmp_path):
    """Defect 3: the second SIGINT killed the writer mid-segment and left status 'recording'."""
    # A slow writer (20 ms a frame) keeps a backlog, so the second signal lands while it drains.
    proc = _record(tmp_path, "--duration", "60", "--segment-duration", "60", "--debug-writer-delay", "0.02")
    session = tmp_path / "sessions" / "s"
    assert wait_for(lambda: any(session.glob("*.mcap.active")), timeout=30)
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.3)
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=60)
    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] == "complete", err.decode()
    assert not list(session.glob("*.active"))
    assert _images(session) == meta["frames_written"]
    assert meta["frames_written"] + meta["frames_dropped"] == meta["frames_captured"]


def test_status_is_interrupted_when_no_live_recorder_holds_the_session(tmp_path):
    proc = _record(tmp_path, "--duration", "60")
    session = tmp_path / "sessions" / "s"
    assert wait_for(lambda: any(session.glob("*.mcap.active")), timeout=30)
    time.sleep(0.5)
    r = run_cli("info", str(session), "--json")
    assert json.loads(r.stdout)["status"] == "recording"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    r = run_cli("info", str(session), "--json")
    info = json.loads(r.stdout)
    assert info["status"] == "interrupted"
    assert "recover" in info.get("hint", "")


def test_recover_marks_a_recorder_killed_between_segments(tmp_path):
    """A recorder killed after closing a segment and before opening the next leaves no
    ``.active`` file, only a session.json that still says "recording" (found by the lifecycle
    test in CI). `recover` must still mark it, with the count the segments hold, whether it is
    given the session or the data root."""
    for n, target in enumerate(("session", "root")):
        sid = f"s{n}"
        Recorder(SimSource(width=96, height=64, frames=90, paced=False, seed=n), tmp_path, session_id=sid,
                 analysis=False, recover_leftovers=False, policy=SegmentPolicy(max_duration_s=0.5)).run()
        session = tmp_path / "sessions" / sid
        meta = json.loads((session / "session.json").read_text())
        written = meta["frames_written"]
        for key in ("frames_written", "frames_captured", "ended_ns"):
            meta.pop(key, None)
        meta["status"] = "recording"  # what session.json says while the recorder runs
        (session / "session.json").write_text(json.dumps(meta))
        assert not list(session.glob("*.active")) and len(list(session.glob("*.mcap"))) >= 2
        recover_path(session if target == "session" else tmp_path)
        after = json.loads((session / "session.json").read_text())
        assert after["status"] == "recovered", target
        assert after["frames_written"] == written == _images(session), target
