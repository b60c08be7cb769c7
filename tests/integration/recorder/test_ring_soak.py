"""The ring buffer's soak, moved out of the unit tier (it runs 4,000 frames, about 10 s): the disk
budget kept, every protected window whole, and a source that can wait never dropped from."""

from __future__ import annotations

import json
import threading
import time

from thermcap.archive.manifest import frame_sha256
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.ring import RingPolicy, disk_usage, load_windows, read_eviction_log
from thermcap.recorder.storage.segments import SegmentPolicy

W, H, FPS = 64, 48, 60.0
T0 = 1_800_000_000_000_000_000

def _sim(frames: int) -> SimSource:
    return SimSource(width=W, height=H, fps=FPS, frames=frames, paced=False, seed=11, start_time_ns=T0,
                     cue_period_s=0)


def test_ring_soak_keeps_the_budget_and_every_protected_window(tmp_path):
    """An accelerated day: 4,000 small frames in 0.25 s segments under a budget of a few segments,
    with marks while it runs."""
    frames = 4000
    seg_bytes = int(W * H * 2 * FPS * 0.25 * 1.2)  # one segment, compressed size is below this
    budget = 12 * seg_bytes  # four windows of 0.2 s hold at most 8 segments of 0.25 s
    ring = RingPolicy(max_disk=budget, pre_s=0.1, post_s=0.1, interval_s=0.05)
    rec = Recorder(_sim(frames), tmp_path, session_id="ring", policy=SegmentPolicy(max_duration_s=0.25),
                   analysis=False, ring=ring)
    peak = [0]
    done = threading.Event()

    def watch():
        while not done.is_set():
            peak[0] = max(peak[0], disk_usage(tmp_path))
            time.sleep(0.005)

    def marks():  # at fixed points of the stream, whatever the host's speed
        for k, at in enumerate((500, 1500, 2500, 3500)):
            while rec.counters.frames_written < at and not done.is_set():
                time.sleep(0.001)
            rec.mark(f"mark {k}")

    threads = [threading.Thread(target=watch), threading.Thread(target=marks)]
    for t in threads:
        t.start()
    result = rec.run()
    done.set()
    for t in threads:
        t.join()
    assert result.error is None
    assert result.frames_written == frames
    assert result.dropped.get("/thermal/image", 0) == 0  # a source that can wait is never dropped from
    log = read_eviction_log(tmp_path)
    assert len(log) == result.evicted_segments > 5
    assert all("over --max-disk" in e["reason"] for e in log)
    assert peak[0] <= budget + 2 * seg_bytes, (peak[0], budget)  # the budget plus the open segment
    windows = load_windows(tmp_path / "sessions" / "ring")
    assert [w.note for w in windows] == [f"mark {k}" for k in range(4)]
    expected = {f.timestamp_ns: frame_sha256(f.pixels) for f in _sim(frames).frames()}
    kept = {f.log_time: frame_sha256(f.pixels) for f in iter_session_frames(tmp_path / "sessions" / "ring")}
    assert 0 < len(kept) < frames
    assert set(kept) <= set(expected)
    for w in windows:
        inside = [t for t in expected if w.start_ns <= t <= w.end_ns]
        assert len(inside) >= int((w.end_ns - w.start_ns) / 1e9 * FPS) - 1
        for t in inside:
            assert t in kept, f"the frame at {t} in protected window {w.note} was evicted"
            assert kept[t] == expected[t]
    meta = json.loads((tmp_path / "sessions" / "ring" / "session.json").read_text())
    assert meta["evicted_segments"] == len(log)
    assert meta["ring"]["max_disk"] == budget
