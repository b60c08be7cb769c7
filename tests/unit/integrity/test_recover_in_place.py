"""Issue 36, high: following the archiver's own advice took frames out of the session. For a
cut-short closed segment, ``recover SEG.mcap`` wrote ``SEG.recovered.mcap`` (which no command
counts as a segment) and deleted ``SEG.mcap``; ``recover SESSION`` said "nothing to recover".
Now a closed segment is repaired in place, atomically, the original kept beside it until the
result reads back, and session.json says what the segments now hold."""

from __future__ import annotations

import errno
import json

import pytest

from tests.conftest import run_cli
from thermcap.archive.archiver import archive_session
from thermcap.archive.verify import verify_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.storage import recover as recover_mod
from thermcap.recorder.storage.reader import count_frames, iter_session_frames
from thermcap.recorder.storage.recover import recover_path, recover_segment
from thermcap.recorder.storage.segments import SegmentPolicy


@pytest.fixture
def session(tmp_path):
    Recorder(SimSource(width=64, height=48, frames=60, paced=False, start_time_ns=1_700_000_000_000_000_000),
             tmp_path, session_id="s", analysis=False,
             policy=SegmentPolicy(max_duration_s=0.5, chunk_size=16 << 10)).run()
    return tmp_path / "sessions" / "s"


def _cut(seg, fraction=0.7):
    data = seg.read_bytes()
    seg.write_bytes(data[: int(len(data) * fraction)])


def _frames(session):
    return [(f.log_time, f.pixels.tobytes()) for f in iter_session_frames(session)]


def test_recover_a_closed_segment_replaces_it_in_place(session):
    segs = sorted(session.glob("*.mcap"))
    assert len(segs) >= 2
    before = {s.name: n for s, n in zip(segs, count_frames(session).values(), strict=True)}
    _cut(segs[0])
    [res] = recover_path(segs[0])  # what `thermcap recover SEG.mcap` runs
    assert res.output == str(segs[0])
    assert 0 < res.frames < before[segs[0].name]
    assert sorted(p.name for p in session.iterdir() if ".mcap" in p.name) == sorted(s.name for s in segs)
    counts = count_frames(session)
    assert counts[segs[0].name] == res.frames
    meta = json.loads((session / "session.json").read_text())
    assert meta["frames_written"] == sum(counts.values())
    assert meta["status"] == "recovered"
    assert meta["recovered_segments"][segs[0].name]["frames"] == res.frames
    # and the rest of the lifecycle takes it: every frame kept is archived and verified
    archive_session(session, ["png16"], delete_source=True)
    assert all(c.ok for c in verify_session(session).values())
    assert len(_frames(session)) == sum(counts.values())


def test_recover_session_finds_a_cut_closed_segment(session):
    segs = sorted(session.glob("*.mcap"))
    _cut(segs[-1])
    r = run_cli("recover", str(session), "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert [o["output"] for o in out] == [str(segs[-1])]
    assert out[0]["frames"] > 0
    r = run_cli("info", str(session), "--json")
    assert r.returncode == 0, r.stderr
    archive_session(session, ["hdf5"])


def test_a_complete_closed_segment_reports_its_frames(session):
    seg = sorted(session.glob("*.mcap"))[0]
    n = count_frames(session)[seg.name]
    res = recover_segment(seg)
    assert res.frames == n and res.stopped_because == "file was complete"
    assert seg.is_file()


def test_recover_that_cannot_write_says_so_and_keeps_the_original(session, monkeypatch):
    seg = sorted(session.glob("*.mcap"))[0]
    _cut(seg)
    data = seg.read_bytes()

    def full(*a, **kw):
        raise OSError(errno.ENOSPC, "No space left on device", str(seg) + ".recovering")

    monkeypatch.setattr(recover_mod.ChunkedWriter, "start", full)
    with pytest.raises(McapFileError, match="No space left") as exc:
        recover_segment(seg)
    assert "no MCAP header survived" not in str(exc.value)
    assert seg.read_bytes() == data
    assert not list(session.glob("*.recovering")) and not list(session.glob("*.orig"))


def test_a_zero_byte_segment_is_moved_aside_not_a_dead_end(session):
    segs = sorted(session.glob("*.mcap"))
    extra = session / f"{int(segs[-1].stem) + 1:04d}.mcap"
    extra.write_bytes(b"")
    results = recover_path(session)
    assert [r.source for r in results] == [str(extra)]
    assert not extra.exists() and extra.with_name(extra.name + ".unreadable").is_file()
    assert "no bytes" in results[0].stopped_because
    archive_session(session, ["png16"])
    assert all(c.ok for c in verify_session(session).values())
