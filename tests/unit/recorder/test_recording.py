"""Record real sessions and read them back with the official mcap reader."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from thermcap.benches.record import MemorySource
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.icd.rosmsg import json_payload
from thermcap.recorder.icd.sidecar import validate_sidecar
from thermcap.recorder.icd.topics import decode_image
from thermcap.recorder.storage.segments import SegmentPolicy
from thermcap.recorder.storage.writer import Compression

W, H = 160, 128


def _sim(**kw):
    return SimSource(width=W, height=H, paced=False, start_time_ns=1_800_000_000_000_000_000, **kw)


def _read_all(session_dir: Path):
    out = {"frames": [], "meta": [], "stats": [], "cue": [], "truth": [], "schemas": {}, "attachments": [],
           "metadata": []}
    for seg in sorted(session_dir.glob("*.mcap")):
        with open(seg, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            for s in summary.schemas.values():
                out["schemas"][s.name] = s.encoding
            out["attachments"] += [a.name for a in reader.iter_attachments()]
            out["metadata"] += [(m.name, m.metadata) for m in reader.iter_metadata()]
            for _schema, channel, msg in reader.iter_messages(log_time_order=False):
                doc = None if channel.topic in ("/thermal/image", "/thermal/annotations") else \
                    json.loads(json_payload(channel.message_encoding, msg.data))
                if channel.topic == "/thermal/image":
                    stamp, px = decode_image(msg.data)
                    assert stamp == msg.log_time
                    out["frames"].append((msg.log_time, px.copy()))
                elif channel.topic == "/thermal/metadata":
                    out["meta"].append((msg.log_time, doc))
                elif channel.topic == "/recorder/stats":
                    out["stats"].append(doc)
                elif channel.topic == "/radar/cue":
                    out["cue"].append(doc)
                elif channel.topic == "/sim/ground_truth":
                    out["truth"].append(doc)
    return out


def test_recorded_session_reads_back_bit_exact(tmp_path):
    res = Recorder(_sim(frames=90, seed=5), tmp_path, session_id="s1").run()
    assert res.ok
    assert res.frames_written == 90
    assert res.frames_dropped == 0
    data = _read_all(tmp_path / "sessions" / "s1")
    expected = list(_sim(frames=90, seed=5).frames())
    assert len(data["frames"]) == 90 == len(data["meta"])
    for (t, px), exp in zip(data["frames"], expected, strict=True):
        assert t == exp.timestamp_ns
        assert px.dtype == np.dtype("<u2")
        assert np.array_equal(px, exp.pixels)
    times = [t for t, _ in data["frames"]]
    assert times == sorted(times)
    assert len(set(times)) == len(times)
    # the sidecar has the frame's log time and validates
    for (t_img, _), (t_meta, meta) in zip(data["frames"], data["meta"], strict=True):
        assert t_img == t_meta
        validate_sidecar(meta)
    assert data["schemas"]["sensor_msgs/msg/Image"] == "ros2msg"
    assert data["schemas"]["thermcap_msgs/msg/ThermalSidecar"] == "ros2msg"
    assert set(data["schemas"].values()) == {"ros2msg"}  # every topic a ROS 2 message
    assert "bad_pixel_map.json" in data["attachments"]
    session_meta = dict(data["metadata"])["thermcap.session"]
    assert json.loads(session_meta["radiometric_model"]) == {"kind": "linear", "scale_c_per_count": 0.036,
                                                              "offset_c": -40.0, "bit_depth": 14}
    assert session_meta["software_version"]
    assert session_meta["host"]
    assert data["truth"]
    assert data["stats"]


def test_image_decodes_with_the_ros2_decoder(tmp_path):
    Recorder(_sim(frames=3), tmp_path, session_id="s").run()
    seg = next((tmp_path / "sessions" / "s").glob("*.mcap"))
    with open(seg, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        _, _, _, msg = next(reader.iter_decoded_messages(topics=["/thermal/image"]))
    assert (msg.encoding, msg.width, msg.height, msg.step, msg.is_bigendian) == ("mono16", W, H, W * 2, 0)
    assert len(msg.data) == W * H * 2


@pytest.mark.parametrize("compression", list(Compression))
def test_every_chunk_compression_round_trips(tmp_path, compression):
    policy = SegmentPolicy(compression=compression, compression_level=1 if compression is Compression.ZSTD else 0)
    Recorder(_sim(frames=20, seed=1), tmp_path, session_id="c", policy=policy).run()
    data = _read_all(tmp_path / "sessions" / "c")
    for (_, px), exp in zip(data["frames"], _sim(frames=20, seed=1).frames(), strict=True):
        assert np.array_equal(px, exp.pixels)


def test_segments_rotate_by_duration(tmp_path):
    policy = SegmentPolicy(max_duration_s=0.5, max_bytes=None)
    res = Recorder(_sim(frames=120, fps=60), tmp_path, session_id="r", policy=policy).run()
    names = sorted(p.name for p in (tmp_path / "sessions" / "r").glob("*.mcap*"))
    assert names == ["0000.mcap", "0001.mcap", "0002.mcap", "0003.mcap"]
    assert [s["frames"] for s in res.segments] == [30, 30, 30, 30]
    data = _read_all(tmp_path / "sessions" / "r")
    assert len(data["frames"]) == 120
    for seg in (tmp_path / "sessions" / "r").glob("*.mcap"):  # each segment stands alone
        with open(seg, "rb") as f:
            reader = make_reader(f)
            assert [a.name for a in reader.iter_attachments()] == ["bad_pixel_map.json"]
            assert "thermcap.session" in {m.name for m in reader.iter_metadata()}


def test_segments_rotate_by_size(tmp_path):
    policy = SegmentPolicy(max_duration_s=None, max_bytes=400_000, chunk_size=64 * 1024)
    res = Recorder(_sim(frames=60), tmp_path, session_id="b", policy=policy).run()
    assert len(res.segments) > 2
    assert sum(s["frames"] for s in res.segments) == 60
    for s in res.segments:
        assert s["bytes"] <= 400_000 + 2 * W * H * 2 + 65536


def test_slow_writer_drops_are_counted_never_silent(tmp_path):
    sim = _sim(frames=60)
    frames = list(sim.frames())
    # An unpaced source into a 4-frame queue and a writer that takes 20 ms a frame.
    rec = Recorder(MemorySource(sim, frames, 200), tmp_path, session_id="d", queue_frames=4, writer_delay_s=0.02)
    res = rec.run()
    assert res.frames_dropped > 0
    assert res.frames_captured == 200
    assert res.frames_written + res.frames_dropped == 200
    assert res.dropped["/thermal/metadata"] == res.frames_dropped
    data = _read_all(tmp_path / "sessions" / "d")
    assert len(data["frames"]) == res.frames_written
    last = data["stats"][-1]
    assert last["dropped"]["/thermal/image"] == res.frames_dropped
    assert last["frames_captured"] == 200
    assert last["frames_written"] == res.frames_written
    summary = json.loads((tmp_path / "sessions" / "d" / "session.json").read_text())
    assert summary["frames_dropped"] == res.frames_dropped
    assert summary["status"] == "complete"


def test_info_reports_the_session(tmp_path):
    from thermcap.recorder.storage.info import SessionInfo, info

    Recorder(_sim(frames=60, fps=60), tmp_path, session_id="i", policy=SegmentPolicy(max_duration_s=0.5)).run()
    d = info(tmp_path / "sessions" / "i")
    assert isinstance(d, SessionInfo)
    assert d.frames == 60
    assert len(d.segments) == 2
    assert sum(s.frames for s in d.segments) == 60
    assert d.effective_fps == pytest.approx(60.0, rel=1e-3)
    assert d.topics["/thermal/image"].bytes == 60 * (W * H * 2 + 52)  # pixels + 52-byte CDR prefix
    assert d.chunk_compression == ["zstd"]
    assert d.compression_ratio > 1.2
    assert d.status == "complete"
    assert d.frames_dropped == 0
    assert d.to_dict()["topics"]["/thermal/image"]["messages"] == 60
