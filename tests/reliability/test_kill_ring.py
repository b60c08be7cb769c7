"""kill -9 an always-on recording (``--ring``) while it evicts; nothing protected is lost.

A paced 60 fps recording in 0.25 s segments under a budget of 16 segments evicts after
every segment once full; two marks (SIGUSR1) protect 0.5 s either side. The recorder is killed at a
random moment, always at least ``post`` + 1 s after the last mark, often in the middle of an
eviction pass. After ``recover``: every frame left is bit-exact and in order, each protected
window holds all its frames, the eviction log names only unprotected segments that are gone,
and the budget held (plus the open segment).

THERMCAP_RING_KILLS sets the number of kills (3 in the default run, 12 for README.md).
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli, wait_for
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.ring import load_windows, read_eviction_log

pytestmark = pytest.mark.slow

W, H, FPS = 160, 128, 60
SEG_S, PRE, POST = 0.25, 0.5, 0.5


def test_kill_9_during_eviction_loses_nothing_protected(tmp_path):
    kills = int(os.environ.get("THERMCAP_RING_KILLS", "3"))
    rng = random.Random(515)
    report = []
    for k in range(kills):
        root = tmp_path / f"k{k}"
        seg_bytes = int(W * H * 2 * FPS * SEG_S)
        # two windows of 1 s hold 8-10 segments; the rest of the budget keeps more than --pre of
        # rolling history (a budget smaller than the windows plus --pre cannot keep a new pre-window);
        # their share is raised from half the budget so that neither window expires
        budget = 16 * seg_bytes
        proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--duration", "60", "--width", str(W),
                                 "--height", str(H), "--segment-duration", str(SEG_S), "--seed", str(k),
                                 "--root", str(root), "--session", "s", "--no-analysis", "--ring",
                                 "--max-disk", str(budget), "--max-protected", str(12 * seg_bytes),
                                 "--pre", str(PRE), "--post", str(POST),
                                 "--compression", "none", "--cue-period", "0"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        session = root / "sessions" / "s"
        assert wait_for(lambda s=session: any(s.glob("*.mcap.active")))
        marks = []
        for _ in range(2):
            time.sleep(rng.uniform(2.0, 3.0))
            proc.send_signal(signal.SIGUSR1)
            marks.append(time.time_ns())
        assert wait_for(lambda s=session: len(load_windows(s)) == 2, 10)
        time.sleep(POST + 1.0 + rng.uniform(0.0, 1.5))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        evictions = read_eviction_log(root)
        assert evictions, "the budget should have made it evict"
        r = run_cli("recover", str(session), "--json")
        assert r.returncode == 0, r.stderr
        frames = list(iter_session_frames(session))
        index = [json.loads(f.sidecar)["capture"]["frame_index"] for f in frames]
        assert index == sorted(index)
        sim = SimSource(width=W, height=H, fps=FPS, seed=k, paced=False, frames=index[-1] + 1)
        want = {i: f.pixels for i, f in enumerate(sim.frames())}
        for f, i in zip(frames, index, strict=True):
            assert np.array_equal(f.pixels, want[i]), f"frame {i} is not the camera's"
        times = [f.log_time for f in frames]
        for w in load_windows(session):
            inside = [t for t in times if w.start_ns <= t <= w.end_ns]
            expect = (w.end_ns - w.start_ns) / 1e9 * FPS
            assert len(inside) >= expect - 2, f"kill {k}: window {w.reason} kept {len(inside)} of ~{expect:.0f} frames"
            first, last = times.index(inside[0]), times.index(inside[-1])
            gaps = [b - a for a, b in zip(times[first:last], times[first + 1:last + 1], strict=True)]
            assert max(gaps) < 2.5e9 / FPS, f"kill {k}: a hole inside window {w.reason}"
        gone = {e["segment"] for e in evictions}
        assert not gone & {p.name for p in session.glob("*.mcap")}, "the log names a segment that is still there"
        report.append({"kill": k, "evicted_segments": len(evictions), "frames_kept": len(frames),
                       "windows": len(load_windows(session)), "window_frames_lost": 0})
    out = Path(os.environ.get("THERMCAP_RELIABILITY_OUT", tmp_path)) / "kill_ring.json"
    out.write_text(json.dumps(report, indent=1))
    print(json.dumps({"kills": kills, "evictions": sum(r["evicted_segments"] for r in report)}))
