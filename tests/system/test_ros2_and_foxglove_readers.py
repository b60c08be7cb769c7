"""Our sessions open in the ROS 2 and Foxglove ecosystems' own readers, and agree with ours:

- rosbags (``AnyReader``) opens a session folder as a rosbag2 bag (its metadata.yaml) and each
  segment alone, and decodes every topic; rosbags-image gives the frames back as uint16 arrays,
  bit-exact; the sidecar's ``json`` is the recorded sidecar byte for byte.
- metadata.yaml stays true after a kill -9 and ``recover``, and after ring eviction.
- Foxglove's JavaScript readers (@mcap/core + @foxglove/rosmsg2-serialization, from npm) decode
  every message of every topic, with the same image bytes, sidecars and annotation boxes.
- A recording made before the ROS 2 messages (JSON channels) still reads in info, archive, API.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli, wait_for
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource
from thermcap.recorder.storage.reader import iter_session_frames, session_segments
from thermcap.recorder.storage.segments import SegmentPolicy

rosbags = pytest.importorskip("rosbags", reason="rosbags is a test dependency (pip install 'thermcap[test]')")
from rosbags.highlevel import AnyReader  # noqa: E402

NODE_DIR = Path(__file__).resolve().parents[1] / "node"
LEGACY = Path(__file__).resolve().parents[1] / "fixture" / "legacy" / "legacy-json-v1"


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("ros")
    rec = Recorder(SimSource(width=96, height=64, fps=30, frames=60, paced=False, seed=7, first_cue_s=0.2), root,
                   session_id="ros", policy=SegmentPolicy(max_duration_s=0.5))
    rec.mark("deer")
    assert rec.run().ok
    return rec.session_dir


def _ours(session_dir):
    return {f.log_time: f for f in iter_session_frames(session_dir)}


def _read_bag(paths):
    from rosbags.image import message_to_cvimage

    topics: dict[str, list] = {}
    with AnyReader(paths) as r:
        for conn, t, raw in r.messages():
            m = r.deserialize(raw, conn.msgtype)
            value = message_to_cvimage(m) if conn.topic == "/thermal/image" else m
            topics.setdefault(conn.topic, []).append((t, value))
        counts = {c.topic: c.msgcount for c in r.connections}
    return topics, counts


def test_rosbags_reads_every_topic_of_a_session_folder(session):
    assert (session / "metadata.yaml").is_file()
    topics, counts = _read_bag([session])
    ours = _ours(session)
    assert {"/thermal/image", "/thermal/metadata", "/thermal/annotations", "/recorder/stats", "/recorder/events",
            "/radar/cue", "/sim/ground_truth"} <= set(topics)
    assert counts["/thermal/image"] == len(ours) == len(topics["/thermal/image"])
    for t, img in topics["/thermal/image"]:
        assert img.dtype == np.uint16 and np.array_equal(img, ours[t].pixels)
    for t, m in topics["/thermal/metadata"]:
        assert m.json.encode() == ours[t].sidecar  # the recorded sidecar, byte for byte
        doc = json.loads(m.json)
        assert m.target_count == len(doc["targets"])
        grade = doc["thermal_analysis"]["thermal_contrast_grade"]
        assert (np.isnan(m.thermal_contrast_grade) and grade is None) or m.thermal_contrast_grade == grade
    for t, m in topics["/thermal/annotations"]:
        assert len(m.points) == len(m.texts) == len(json.loads(ours[t].sidecar)["targets"])
    (event,) = [m for _, m in topics["/recorder/events"]]
    assert event.kind == "mark" and event.note == "deer"
    assert all(json.loads(m.json) for _, m in topics["/recorder/stats"])


def test_each_segment_opens_alone(session):
    for seg in session_segments(session):
        topics, _ = _read_bag([seg])
        assert topics["/thermal/image"]


def test_metadata_yaml_stays_true_after_kill_and_recover(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--root", str(tmp_path), "--session", "k",
                             "--width", "96", "--height", "64", "--segment-duration", "0.5", "--no-analysis",
                             "--duration", "30"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    session = tmp_path / "sessions" / "k"
    assert wait_for(lambda: len(list(session.glob("*.mcap"))) >= 2, 60)
    time.sleep(0.3)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert list(session.glob("*.mcap.active"))
    r = run_cli("recover", str(session))
    assert r.returncode == 0, r.stderr
    _, counts = _read_bag([session])  # every file metadata.yaml names exists and reads
    assert counts["/thermal/image"] == len(list(iter_session_frames(session)))
    listed = [line.split("'")[1] for line in (session / "metadata.yaml").read_text().splitlines()
              if line.startswith("    - '")]
    assert listed == [p.name for p in session_segments(session)]


def test_metadata_yaml_follows_ring_eviction(tmp_path):
    from thermcap.recorder.storage.ring import RingPolicy

    rec = Recorder(SimSource(width=64, height=48, fps=60, frames=900, paced=False, seed=1, cue_period_s=0), tmp_path,
                   session_id="ring", policy=SegmentPolicy(max_duration_s=0.25), analysis=False,
                   ring=RingPolicy(max_disk=1_200_000, pre_s=0.1, post_s=0.1, interval_s=0.05))
    res = rec.run()
    assert res.evicted_segments > 0
    _, counts = _read_bag([rec.session_dir])
    assert counts["/thermal/image"] == len(list(iter_session_frames(rec.session_dir)))


def _node_reader():
    node = shutil.which("node")
    if node is None or not (NODE_DIR / "node_modules" / "@mcap" / "core").is_dir():
        pytest.skip("no node or no tests/node/node_modules (run `npm install` in tests/node; .ci/run does this)")
    return node


def test_foxglove_javascript_readers_decode_every_message(session):
    node = _node_reader()
    ours = _ours(session)
    seen = 0
    for seg in session_segments(session):
        r = subprocess.run([node, str(NODE_DIR / "read_mcap.mjs"), str(seg)], capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stderr
        topics = json.loads(r.stdout)
        frames = [f for f in ours.values() if f.segment == seg.name]
        images = topics["/thermal/image"]["items"]
        assert [i["sha256"] for i in images] == \
            [hashlib.sha256(np.ascontiguousarray(f.pixels).astype("<u2").tobytes()).hexdigest() for f in frames]
        assert [i["json"].encode() for i in topics["/thermal/metadata"]["items"]] == [f.sidecar for f in frames]
        assert [a["boxes"] for a in topics["/thermal/annotations"]["items"]] == \
            [len(json.loads(f.sidecar)["targets"]) for f in frames]
        seen += len(frames)
    assert seen == len(ours)


def test_a_recording_from_before_the_ros2_messages_still_reads(tmp_path):
    session = tmp_path / "sessions" / LEGACY.name
    shutil.copytree(LEGACY, session)
    frames = list(iter_session_frames(session))
    assert len(frames) == 12 and all(json.loads(f.sidecar)["capture"] for f in frames)
    info = json.loads(run_cli("info", str(session), "--json").stdout)
    assert info["frames"] == 12
    r = run_cli("archive", str(session), "--root", str(tmp_path), "--formats", "png16", "--json")
    assert r.returncode == 0, r.stderr
    r = run_cli("serve", "--root", str(tmp_path), "--get", f"/api/v1/sessions/{LEGACY.name}/frames/3/metadata")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == json.loads(frames[3].sidecar)
