"""``thermcap info`` on a long session: each segment is opened once and its summary read once
(it was read a second time for the frames' times), and the figures are those of the two reads."""

from __future__ import annotations

import builtins
from pathlib import Path

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.info import session_info
from thermcap.recorder.storage.segments import SegmentPolicy


def test_each_segment_is_opened_once(tmp_path, monkeypatch):
    Recorder(SimSource(width=32, height=24, frames=90, fps=30, paced=False, seed=3), tmp_path, session_id="s",
             policy=SegmentPolicy(max_duration_s=1.0), analysis=False).run()
    session = tmp_path / "sessions" / "s"
    segments = sorted(session.glob("*.mcap"))
    assert len(segments) >= 3
    opened: list[str] = []
    real_open = builtins.open

    def counting(file, *a, **k):
        if str(file).endswith(".mcap"):
            opened.append(Path(file).name)
        return real_open(file, *a, **k)

    monkeypatch.setattr(builtins, "open", counting)
    info = session_info(session)
    assert sorted(opened) == [s.name for s in segments]
    assert info.frames == 90 and info.gaps == []
    assert info.duration_s > 2.9  # the frames' own span (89 periods at 30 fps), not a segment's
