"""A segment's close must not hold the writer thread on fsync.

In CI a close waited 1.5 s on fsync while the suite's earlier tests flushed gigabytes; the frames
captured meanwhile were queued in memory only, and ``kill -9`` took them (1.5 s lost against a
1 s bound). What makes a frame survive ``kill -9`` is that it was written (the page cache keeps
it), not that it was fsynced, so the writer thread must go on writing while a closed segment's
fsync and rename finish elsewhere.
"""

from __future__ import annotations

import os
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from thermcap.recorder.exceptions import RecordingError
from thermcap.recorder.icd.topics import TOPIC_IMAGE, decode_image, image_message_parts
from thermcap.recorder.storage.recover import recover_path
from thermcap.recorder.storage.segments import SegmentPolicy, SessionWriter

STEP_NS = 50_000_000  # 20 fps: a 0.1 s segment holds two frames


def _writer(session: Path, fsync_interval_s: float = 0) -> SessionWriter:
    session.mkdir()
    return SessionWriter(session, session_meta={"session_id": "s"}, extra_topics={},
                         policy=SegmentPolicy(max_duration_s=0.1, fsync_interval_s=fsync_interval_s, workers=0))


def _frame(i: int) -> np.ndarray:
    return np.full((8, 8), i, dtype=np.uint16)


def _write(sw: SessionWriter, frames: range) -> None:
    for i in frames:
        sw.write_frame(i * STEP_NS, image_message_parts(_frame(i), i * STEP_NS), b"{}")


def _images(session: Path, pattern: str, skip_last: bool = False) -> list[tuple[int, int]]:
    out = []
    segments = sorted(session.glob(pattern))
    for seg in segments[:-1] if skip_last else segments:
        with open(seg, "rb") as f:
            for _, _, msg in make_reader(f).iter_messages(topics=[TOPIC_IMAGE]):
                out.append((msg.log_time, int(decode_image(msg.data)[1][0, 0])))
    return out


@pytest.fixture
def held_fsync(monkeypatch):
    """fsync blocks until the test lets it go: a disk busy with someone else's writes."""
    gate = threading.Event()
    real = os.fsync

    def fsync(fd: int) -> None:
        gate.wait(30)
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    yield gate
    gate.set()


@pytest.mark.parametrize("periodic_fsync", [False, True], ids=["close-only", "with-periodic-fsync"])
def test_a_stalled_fsync_never_holds_the_writer_thread(tmp_path, held_fsync, periodic_fsync):
    """With the periodic fsync of the open segment on too: its thread, stuck in fsync, must not
    hold the writer either when a segment closes or opens."""
    session = tmp_path / "s"
    sw = _writer(session, fsync_interval_s=0.01 if periodic_fsync else 0)
    if periodic_fsync:
        _write(sw, range(1))
        time.sleep(0.1)  # the syncer is now inside a held fsync of segment 0
    done = threading.Event()
    t = threading.Thread(target=lambda: (_write(sw, range(1 if periodic_fsync else 0, 12)), done.set()), daemon=True)
    t.start()
    try:
        assert done.wait(10), "the writer thread waited on a closed segment's fsync"
        # Every closed segment is finished in its file (the open one is the last), as kill -9
        # would leave it: complete, only not yet fsynced and renamed.
        written = _images(session, "*.mcap.active", skip_last=True)
        assert [v for _, v in written] == list(range(10))
        assert not list(session.glob("*.mcap")), "renamed before its fsync"
    finally:
        held_fsync.set()
        t.join(10)
    sw.close()
    assert not list(session.glob("*.active"))
    assert _images(session, "*.mcap") == [(i * STEP_NS, i) for i in range(12)]
    assert len(list(session.glob("*.mcap"))) == 6


def test_kill_during_a_stalled_close_loses_no_written_frame(tmp_path, held_fsync):
    """Several segments wait to be settled (``.active`` though finished), and one is open:
    ``recover`` names the finished ones and keeps every chunk of the open one."""
    session = tmp_path / "s"
    sw = _writer(session)
    t = threading.Thread(target=_write, args=(sw, range(9)), daemon=True)
    t.start()
    t.join(10)
    assert not t.is_alive()
    sw._writer.flush()  # the open segment's last chunk written, as max_chunk_age_s would have done
    actives = sorted(p.name for p in session.glob("*.mcap.active"))
    assert len(actives) >= 2
    # kill -9: the process is gone, its files stay as they are on disk. Copy them away before
    # the held threads are let go.
    crashed = tmp_path / "crashed"
    crashed.mkdir()
    for p in session.iterdir():
        if p.name.endswith(".active"):
            (crashed / p.name).write_bytes(p.read_bytes())
    held_fsync.set()
    sw.abandon()
    results = recover_path(crashed)
    assert sorted(Path(r.source).name for r in results) == actives
    assert not list(crashed.glob("*.active"))
    assert _images(crashed, "*.mcap") == [(i * STEP_NS, i) for i in range(9)]


def test_a_failed_close_is_reported_naming_the_segment(tmp_path, monkeypatch):
    """The closing thread's error reaches the writer's caller (on the next write, poll or
    close) naming the segment, and the segment stays ``.active`` for ``recover``."""
    real = os.replace

    def replace(src, dst):
        if str(src).endswith("0000.mcap.active"):
            raise OSError(5, "Input/output error")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    session = tmp_path / "s"
    sw = _writer(session)
    with pytest.raises(RecordingError, match=r"0000\.mcap\.active.*Input/output error"):
        _write(sw, range(40))
        sw.close()
    sw.abandon()
    assert (session / "0000.mcap.active").exists()


def test_a_live_camera_drops_nothing_while_fsync_stalls(tmp_path, monkeypatch):
    """The recorder end to end: a paced 60 fps camera (which cannot wait), half-second
    segments, a 30-frame queue, and a disk whose fsync of segments stalls for 2 s from the
    first one asked. The old writer stopped at the first segment boundary and the queue
    overflowed (frames dropped, counted); now every frame is written, and every segment has its
    final name once the disk answers. Meanwhile the status shows the segments waiting, and
    health names the stall."""
    import thermcap.recorder.capture.recorder as recorder_module
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource

    monkeypatch.setattr(recorder_module, "SETTLE_STALL_S", 0.5)
    gate, real = threading.Event(), os.fsync
    stall = threading.Lock()

    def fsync(fd: int) -> None:  # only segments stall: session.json and folders go through
        if os.readlink(f"/proc/self/fd/{fd}").endswith(".mcap.active"):
            with stall:
                if not getattr(fsync, "armed", False):
                    fsync.armed = True  # type: ignore[attr-defined]
                    threading.Timer(2.0, gate.set).start()
            gate.wait(30)
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    rec = Recorder(SimSource(width=64, height=48, fps=60, frames=150, paced=True), tmp_path, session_id="s",
                   analysis=False, recover_leftovers=False, queue_frames=30,
                   policy=SegmentPolicy(max_duration_s=0.5, workers=0))
    seen: list[tuple[list, list[str]]] = []
    agree: list[bool] = []

    def watch() -> None:
        while not gate.is_set():
            if rec._session is not None:
                seen.append((rec.status()["segments_settling"], rec.health()[1]))
                st = rec.status()  # its problems judge the very list it shows
                stalled = bool(st["segments_settling"]) and st["segments_settling"][0]["waiting_s"] > 0.5
                agree.append(stalled == any(p.startswith("disk: ") for p in st["problems"]))
            time.sleep(0.05)

    threading.Thread(target=watch, daemon=True).start()
    try:
        res = rec.run()
    finally:
        gate.set()
    assert getattr(fsync, "armed", False), "no segment was ever fsynced"
    assert res.error is None
    assert not any(res.dropped.values()), res.dropped
    assert res.frames_written == 150
    waiting = [s for s, _ in seen if s]
    # the first segment, stalled, is shown waiting (the last sample may fall after the disk answered it)
    assert any(w[0]["name"] == "0000.mcap" and w[0]["waiting_s"] > 0.5 for w in waiting), waiting[-3:]
    assert any(any(p.startswith("disk: segment 0000.mcap has waited") for p in problems) for _, problems in seen)
    assert agree and all(agree)
    assert rec.status()["segments_settling"] == [] and rec.health()[0]
    session = tmp_path / "sessions" / "s"
    assert not list(session.glob("*.active"))
    assert len(_images(session, "*.mcap")) == 150


def test_ctl_status_names_the_segments_waiting_for_the_disk():
    from thermcap.recorder.cli.record import status_text

    st = {"session_id": "s", "paused": False, "healthy": False,
          "problems": ["disk: segment 0003.mcap has waited 42 s for fsync (2 closed segments waiting; ...)"],
          "frames_captured": 10, "frames_written": 10, "dropped": {}, "frames_paused": 0, "queue_depth": 0,
          "queue_capacity": 120, "segment": "0005.mcap", "cameras": {"": {}},
          "segments_settling": [{"name": "0003.mcap", "waiting_s": 42.04}, {"name": "0004.mcap", "waiting_s": 41.0}]}
    text = status_text(st)
    assert "UNHEALTHY: disk: segment 0003.mcap has waited 42 s" in text
    assert "disk: 2 closed segments waiting for fsync, the oldest 0003.mcap for 42.0 s" in text
    assert "waiting for fsync" not in status_text({**st, "segments_settling": [], "healthy": True, "problems": []})
