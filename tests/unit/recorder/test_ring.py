"""Always-on recording within a disk budget (``--ring``): eviction keeps the budget, protected
event windows survive bit-exact, nothing is dropped while eviction runs, and when everything is
protected the recorder says so and drops (counted) instead of filling the disk."""

from __future__ import annotations

import threading
import time

import pytest

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.capture.triggers import TriggerPolicy, TriggerWatch
from thermcap.recorder.sizes import parse_size
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.ring import RingPolicy
from thermcap.recorder.storage.segments import SegmentPolicy

W, H, FPS = 64, 48, 60.0
T0 = 1_800_000_000_000_000_000


def _sim(frames: int) -> SimSource:
    return SimSource(width=W, height=H, fps=FPS, frames=frames, paced=False, seed=11, start_time_ns=T0,
                     cue_period_s=0)


def test_sizes_and_policies_parse():
    assert parse_size("500M") == 500 << 20
    assert parse_size("1.5G") == int(1.5 * (1 << 30))
    assert parse_size("123456") == 123456
    assert parse_size("2GiB") == 2 << 30
    with pytest.raises(ValueError, match="not a size"):
        parse_size("lots")
    p = RingPolicy.parse("20G", "10%", 5, 7)
    assert (p.max_disk, p.min_free, p.min_free_percent, p.pre_s, p.post_s) == (20 << 30, None, 10.0, 5, 7)
    assert RingPolicy.parse(None, "5G", 1, 1).min_free == 5 << 30


def test_triggers_fire_on_edges_only():
    w = TriggerWatch(TriggerPolicy(hot_spot_c=80.0, target_count=True))
    hot = {"targets": [{"max_temp_c": 95.0}], "thermal_analysis": {"thermal_contrast_grade": 0.9, "source": "x",
                                                                    "delta_t_deg_c": 30.0}}
    cold = {"targets": [], "thermal_analysis": {"thermal_contrast_grade": 0.0, "source": "none"}}
    assert w.check(cold) == []
    fired = w.check(hot)
    assert len(fired) == 2
    assert fired[0].startswith("hot_spot")
    assert fired[1].startswith("target_count: 0 -> 1")
    assert w.check(hot) == []  # still hot: the same event, not a new one
    assert w.check(cold)[0].startswith("target_count: 1 -> 0")
    cue = TriggerWatch(TriggerPolicy())
    assert cue.check({"slew_to_cue": {"radar_cue_received": True}}) == ["radar_cue: cue received"]
    assert cue.check({"slew_to_cue": {"radar_cue_received": True}}) == []


def test_everything_protected_blocks_and_counts_the_drops(tmp_path):
    """The camera runs until the ring has blocked and dropped a frame (waited for, not timed: a
    fixed 600 frames could end on a loaded machine before the first segment closed)."""
    # one mark protects all time, and the operator keeps events over new frames
    ring = RingPolicy(max_disk=1, pre_s=1e6, post_s=1e6, interval_s=0.02, keep_events=True)
    live = SimSource(width=W, height=H, fps=600.0, frames=None, paced=True, seed=11, start_time_ns=T0,
                     cue_period_s=0)  # a live camera, which cannot wait: its frames are dropped and counted
    rec = Recorder(live, tmp_path, session_id="full", policy=SegmentPolicy(max_duration_s=0.1), analysis=False,
                   ring=ring)
    rec.mark("keep everything")
    out = {}
    t = threading.Thread(target=lambda: out.setdefault("res", rec.run()))
    t.start()
    try:
        assert _wait(lambda: rec.status().get("ring", {}).get("blocked")
                     and sum(rec.status()["dropped"].values()) > 0, 120)
    finally:
        rec.stop()
        t.join(120)
    result = out["res"]
    assert result.evicted_segments == 0
    assert result.frames_written + result.frames_dropped == result.frames_captured
    assert result.frames_dropped > 0
    assert not result.ok
    status_problems = [p for p in result.problems if "dropped" in p]
    assert status_problems
    kept = [f.index for f in iter_session_frames(tmp_path / "sessions" / "full")]
    assert kept == sorted(kept)
    assert len(kept) == result.frames_written


def test_a_source_that_can_wait_waits_for_disk_instead_of_dropping(tmp_path):
    """A file or a pipe is never dropped from: with everything protected and the budget
    exceeded, the recorder stops reading it (the pipe backs up) until space frees, and says so."""
    import io

    import numpy as np

    from thermcap.recorder.capture.sources.raw import RawSource

    px = np.random.default_rng(2).integers(0, 1 << 14, size=(300, 48, 64), dtype=np.uint16)
    src = RawSource("pipe", width=64, height=48, fps=60, stream=io.BytesIO(px.astype("<u2").tobytes()))
    ring = RingPolicy(max_disk=1, pre_s=1e6, post_s=1e6, interval_s=0.02, keep_events=True)
    rec = Recorder(src, tmp_path, session_id="w", policy=SegmentPolicy(max_duration_s=0.1), analysis=False,
                   ring=ring)
    rec.mark("keep everything")
    out = {}
    t = threading.Thread(target=lambda: out.setdefault("res", rec.run()))
    t.start()
    assert _wait(lambda: rec.status().get("ring", {}).get("blocked"), 20)
    time.sleep(0.5)
    st = rec.status()
    assert st["dropped"] == {} and any("waiting for disk" in p for p in st["problems"]), st
    written = st["frames_written"]
    time.sleep(0.5)
    assert rec.status()["frames_written"] == written  # it waits, it does not write past the budget
    rec.stop()
    t.join(30)
    res = out["res"]
    assert res.frames_written + res.frames_dropped == res.frames_captured
    assert any("waiting for disk" in p or "dropped" in p for p in res.problems)


def _wait(pred, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.02)
    return False


def test_segments_waiting_for_fsync_are_named_when_the_ring_cannot_free_space(tmp_path):
    """A stalled disk leaves closed segments ``.active`` (not candidates) beside the open one:
    the ring's reason says so instead of blaming protection alone. A session nobody records
    has leftovers for ``recover``, which are not counted."""
    import json

    from thermcap.recorder.storage.lock import lock_session
    from thermcap.recorder.storage.ring import Evictor

    for name in ("r", "crashed"):
        session = tmp_path / "sessions" / name
        session.mkdir(parents=True)
        (session / "session.json").write_text(json.dumps({"ring": {"max_disk": 1}}))
        for i in range(3):
            (session / f"{i:04d}.mcap.active").write_bytes(b"\0" * 4096)
    session = tmp_path / "sessions" / "r"
    lock = lock_session(session, "recorder")
    assert lock is not None
    try:
        evictor = Evictor(tmp_path, RingPolicy(max_disk=1), {})
        assert evictor.evict_once() == []
        assert evictor.state.blocked
        assert "2 closed segments still wait for fsync" in (evictor.state.blocked_reason or "")
        (session / "0000.mcap.active").unlink()
        (session / "0001.mcap.active").unlink()
        evictor.evict_once()
        assert "fsync" not in (evictor.state.blocked_reason or "")
    finally:
        lock.release()


def _run_bounded(rec: Recorder, timeout: float = 120):
    """Run a recording on a thread; a ring that stops recording for good shows as a hang here."""
    out = {}
    t = threading.Thread(target=lambda: out.setdefault("res", rec.run()), daemon=True)
    t.start()
    t.join(timeout)
    if t.is_alive():
        rec.stop()
        t.join(30)
        pytest.fail(f"the recording never finished: {rec.status().get('ring')}")
    return out["res"]


def test_the_ring_keeps_recording_when_a_window_outgrows_its_share(tmp_path):
    """Issue 36: a budget near one protected window's size (one mark, a long pre/post) left every
    segment protected and the recorder dropped (or, from a file, waited) for the rest of the run.
    Windows now hold at most --max-protected (default half of --max-disk); past it the oldest goes,
    logged, in protected.json's "expired", and on health."""
    import json

    from thermcap.recorder.storage.ring import read_eviction_log

    ring = RingPolicy(max_disk=300_000, pre_s=1e8, post_s=1e8, interval_s=0.02)  # the mark covers the run
    rec = Recorder(_sim(1200), tmp_path, session_id="r", policy=SegmentPolicy(max_duration_s=0.5),
                   analysis=False, ring=ring)
    rec.mark("one long event")
    res = _run_bounded(rec)
    assert res.frames_written == res.frames_captured == 1200 and res.frames_dropped == 0
    assert res.evicted_segments > 0
    log = read_eviction_log(tmp_path)
    expired = [e for e in log if "expired_window" in e]
    assert expired and ("over --max-protected" in expired[0]["reason"] or "nothing else can go" in expired[0]["reason"])
    doc = json.loads((tmp_path / "sessions" / "r" / "protected.json").read_text())
    assert doc["windows"] == [] and doc["expired"][0]["note"] == "one long event"
    kept = [f.index for f in iter_session_frames(tmp_path / "sessions" / "r")]
    assert kept == sorted(kept) and len(kept) > 0


def test_the_oldest_window_goes_first_and_health_says_so(tmp_path):
    """Two events: when their share is exceeded the older one expires, the newer one is kept."""
    from thermcap.recorder.storage.ring import Evictor, ProtectionBook, Window

    rec = Recorder(_sim(600), tmp_path, session_id="e", policy=SegmentPolicy(max_duration_s=0.5), analysis=False)
    rec.run()
    session = tmp_path / "sessions" / "e"
    (session / "session.json").write_text(
        (session / "session.json").read_text().replace('"status"', '"ring": {"max_disk": 1}, "status"', 1))
    book = ProtectionBook(session)
    book.add(Window(T0, T0 + 2_000_000_000, "manual", "old"))
    book.add(Window(T0 + 8_000_000_000, T0 + 10_000_000_000, "manual", "new"))
    seg_bytes = sum(p.stat().st_blocks * 512 for p in session.glob("*.mcap"))
    ev = Evictor(tmp_path, RingPolicy(max_disk=seg_bytes // 2, max_protected=seg_bytes // 3), {session: book})
    ev.evict_once()
    assert [w.note for w in book.windows] == ["new"]
    assert ev.state.windows_expired == 1 and "old" in (ev.state.last_expired or "")


def test_keep_events_keeps_every_window(tmp_path):
    from thermcap.recorder.storage.ring import Evictor, ProtectionBook, Window

    rec = Recorder(_sim(300), tmp_path, session_id="k", policy=SegmentPolicy(max_duration_s=0.5), analysis=False)
    rec.run()
    session = tmp_path / "sessions" / "k"
    book = ProtectionBook(session)
    book.add(Window(0, 2**62, "manual", "all"))
    ev = Evictor(tmp_path, RingPolicy(max_disk=1, keep_events=True), {session: book})
    ev.evict_once()
    assert [w.note for w in book.windows] == ["all"] and ev.state.blocked
    assert "--keep-events" in (ev.state.blocked_reason or "")


def test_info_counts_evictions_after_a_crash(tmp_path):
    """Issue 36: after a crash ``info`` showed 0 evictions while eviction.log listed 6: the count
    came only from session.json's end-of-run summary."""
    import json

    from thermcap.recorder.storage.info import session_info

    ring = RingPolicy(max_disk=300_000, pre_s=0, post_s=0, interval_s=0.02)
    Recorder(_sim(600), tmp_path, session_id="c", policy=SegmentPolicy(max_duration_s=0.5), analysis=False,
             ring=ring).run()
    session = tmp_path / "sessions" / "c"
    meta = json.loads((session / "session.json").read_text())
    logged = sum(1 for line in (tmp_path / "eviction.log").read_text().splitlines() if '"segment"' in line)
    assert logged > 0
    meta.pop("evicted_segments", None)  # what a recorder killed before its summary leaves
    meta["status"] = "recording"
    (session / "session.json").write_text(json.dumps(meta))
    assert session_info(session).evicted_segments == logged
