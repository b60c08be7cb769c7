"""Several cameras in one session: each under /thermal/<name>/ with its own sensor, model and
counts on one clock; one failing or stalling is reported and the others go on; a single camera
keeps today's layout; nothing downstream reads a session of several as if it had none."""

from __future__ import annotations

import hashlib
import json
import threading
import time

import pytest
from mcap.reader import make_reader

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import FrameSource, SimSource
from thermcap.recorder.capture.sources.spec import parse_source_spec
from thermcap.recorder.exceptions import McapFileError, SourceError
from thermcap.recorder.storage.info import info
from thermcap.recorder.storage.reader import count_frames, iter_session_frames, read_session_meta, session_cameras


def _sim(w: int, h: int, fps: float, frames: int, seed: int) -> SimSource:
    return SimSource(width=w, height=h, fps=fps, frames=frames, paced=False, seed=seed, start_time_ns=10**18)


def _hashes(frames) -> list[str]:
    return [hashlib.sha256(f.pixels.tobytes()).hexdigest() for f in frames]


def test_two_cameras_record_bit_exact_under_their_own_topics(tmp_path):
    rec = Recorder({"left": _sim(160, 128, 60, 40, 1), "aux": _sim(80, 64, 30, 20, 2)}, tmp_path, session_id="two",
                   analysis=False)
    res = rec.run()
    assert res.ok, res.problems
    assert res.cameras["left"]["frames_written"] == 40 and res.cameras["aux"]["frames_written"] == 20
    assert res.frames_written == 60
    d = rec.session_dir
    assert session_cameras(d) == ["aux", "left"]
    meta = read_session_meta(d)
    assert meta["cameras"]["aux"]["sensor"]["resolution"]["width"] == 80
    with open(next(d.glob("*.mcap")), "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert {"/thermal/left/image", "/thermal/left/metadata", "/thermal/aux/image", "/thermal/aux/metadata"} <= topics
    assert "/thermal/image" not in topics
    for name, (w, h, fps, n, seed) in {"left": (160, 128, 60, 40, 1), "aux": (80, 64, 30, 20, 2)}.items():
        got = list(iter_session_frames(d, name))
        assert _hashes(got) == _hashes(_sim(w, h, fps, n, seed).frames()), name
        sidecar = json.loads(got[0].sidecar)
        assert sidecar["sensor"]["resolution"]["width"] == w  # each camera's own sensor block
        assert sum(count_frames(d, name).values()) == n
    i = info(d)
    assert i.frames == 60 and i.cameras["aux"].frames == 20 and i.cameras["left"].frames == 40
    # reading the session as if it had one camera would silently find nothing: it is an error
    with pytest.raises(McapFileError, match="several cameras"):
        list(iter_session_frames(d))


def test_a_single_camera_keeps_the_plain_layout(tmp_path):
    rec = Recorder(_sim(80, 64, 30, 5, 1), tmp_path, session_id="one", analysis=False)
    assert rec.run().ok
    with open(next(rec.session_dir.glob("*.mcap")), "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert "/thermal/image" in topics and not any(t.startswith("/thermal/") and t.count("/") > 2 for t in topics)
    assert "cameras" not in read_session_meta(rec.session_dir)


class _Breaks(FrameSource):
    """A pipe that closes badly after a few frames."""

    can_wait = True

    def __init__(self, after: int):
        self.inner = _sim(80, 64, 30, 1000, 5)
        self.sensor, self.model, self.after = self.inner.sensor, self.inner.model, after

    def frames(self):
        for i, f in enumerate(self.inner.frames()):
            if i == self.after:
                raise SourceError("pipe /dev/thermal1 closed: device unplugged")
            yield f


class _Stalls(FrameSource):
    """A device whose read never returns after a few frames (and ignores stop)."""

    def __init__(self):
        self.inner = _sim(80, 64, 30, 1000, 6)
        self.sensor, self.model = self.inner.sensor, self.inner.model
        self.release = threading.Event()

    def frames(self):
        for i, f in enumerate(self.inner.frames()):
            if i == 3:
                self.release.wait(30)
                return
            yield f


def test_one_camera_failing_is_reported_and_the_other_records_on(tmp_path):
    rec = Recorder({"good": _sim(80, 64, 30, 200, 1), "bad": _Breaks(after=7)}, tmp_path, session_id="f",
                   analysis=False)
    res = rec.run()
    assert res.error is None  # the session did not fail: one camera did
    assert res.cameras["good"]["frames_written"] == 200
    assert res.cameras["bad"]["frames_written"] == 7
    assert "device unplugged" in res.cameras["bad"]["error"]
    assert not res.ok and any("camera bad" in p for p in res.problems)
    assert read_session_meta(rec.session_dir)["status"] == "complete"
    assert info(rec.session_dir).cameras["bad"].error
    assert len(list(iter_session_frames(rec.session_dir, "bad"))) == 7


def test_a_stalled_camera_does_not_hold_the_session_open(tmp_path):
    stall = _Stalls()
    rec = Recorder({"live": SimSource(width=80, height=64, fps=30, paced=True, seed=1), "stuck": stall},
                   tmp_path, session_id="s", analysis=False, stall_s=0.5, stop_grace_s=1.0)
    done = threading.Event()
    out = {}

    def run():
        out["res"] = rec.run(duration_s=2.0)
        done.set()

    threading.Thread(target=run, daemon=True).start()
    time.sleep(1.5)
    healthy, reasons = rec.health()
    assert not healthy and any("stuck" in r for r in reasons), reasons
    assert done.wait(20), "the session waited for a camera that never stops"
    stall.release.set()
    res = out["res"]
    assert res.cameras["live"]["frames_written"] > 30
    assert "stalled" in res.cameras["stuck"]["error"]
    assert res.cameras["stuck"]["frames_written"] == 3


def test_source_specs():
    s = parse_source_spec("aux=sim,width=320,height=256,fps=30,pace=false")
    assert (s.name, s.kind, s.options) == ("aux", "sim", {"width": 320, "height": 256, "fps": 30.0, "pace": False})
    assert parse_source_spec("raw:/data/a=b.raw").name is None  # '=' inside a path is not a name
    assert parse_source_spec("cam-1=raw:-").kind == "raw:-"
    for bad, why in [("Left=sim", "camera name"), ("x=usb", "unknown source"), ("sim,depth=3", "depth"),
                     ("sim,fps=fast", "fps")]:
        with pytest.raises(SourceError, match=why):
            parse_source_spec(bad)


def test_every_kind_of_source_is_registered_once_and_parsed_by_its_own_rules():
    from thermcap.recorder.capture.sources import source_registry

    assert set(source_registry) == {"sim", "raw", "exec", "gige"}
    g = parse_source_spec("front=gige:10.0.0.5,fps=30,ExposureTime=8000,PixelFormat=Mono14")
    assert (g.name, g.target, g.options) == ("front", "10.0.0.5",
                                            {"fps": 30.0, "own": {"ExposureTime": "8000", "PixelFormat": "Mono14"}})
    assert parse_source_spec("gige:").target == ""  # the first camera found
    assert parse_source_spec("gige:cam,silence=30").options == {"own": {"silence": "30"}}
    e = parse_source_spec("exec:ffmpeg -vf scale=1,crop=2 -")
    assert e.target == "ffmpeg -vf scale=1,crop=2 -" and e.options == {}
    for bad, why in [("sim,ExposureTime=1", "ExposureTime"), ("raw:", "needs a target"), ("usb:0", "gige:CAMERA")]:
        with pytest.raises(SourceError, match=why):
            parse_source_spec(bad)


def test_block_ids_wrap_without_counting_a_loss():
    from thermcap.recorder.capture.sources.gige import block_ids_missed

    assert block_ids_missed(65534, 65535) == 0 and block_ids_missed(65535, 1) == 0  # 0 is never a block id
    assert block_ids_missed(65533, 2) == 3 and block_ids_missed(10, 14) == 3


def test_a_source_that_lost_frames_says_so_in_words():
    from thermcap.recorder.capture.sources.health import source_line, source_losses

    assert source_losses({"gaps": 0, "incomplete_frames": 0, "frames_missed": 0}) == []
    said = source_losses({"gaps": 1, "gap_s": 4.5, "reconnects": 1, "incomplete_frames": 3,
                          "incomplete_by_status": {"missing-packets": 3}, "frames_missed": 270})
    assert len(said) == 3 and "reconnected 1 times" in said[0] and "missing-packets: 3" in said[1]
    line = source_line({"source": "gige", "camera": "10.0.0.5", "genicam": {"DeviceVendorName": "FLIR",
                        "DeviceModelName": "A70", "DeviceSerialNumber": "77"}}, {"gaps": 1, "gap_s": 4.5})
    assert line.startswith("source: gige 10.0.0.5 (FLIR A70, serial 77)") and "gaps: 1 (4.5 s)" in line


def test_a_late_buffer_is_not_a_wrap():
    """The hour-long soak's health said 67,112 frames missed where its six gaps held 1,512: a
    buffer the stream handed over after a newer one (an incomplete frame's, completed late) read
    as a step back, and a step back was taken for a wrap of the 16-bit ids (65,533 "missed")."""
    from thermcap.recorder.capture.sources.gige import block_ids_missed, newest_block_id

    assert block_ids_missed(100, 99) == 0 and block_ids_missed(5000, 4990) == 0
    assert newest_block_id(100, 99) == 100 and newest_block_id(100, 101) == 101
    assert newest_block_id(65535, 1) == 1 and newest_block_id(2, 65530) == 2  # across the wrap, both ways
    assert block_ids_missed(65535, 1) == 0 and block_ids_missed(65533, 2) == 3  # a real wrap still counts
