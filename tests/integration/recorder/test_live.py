"""The live view and ``thermcap play`` as real processes, read by a real Foxglove WebSocket
client (tests/support/foxglove_client.py): what a viewer sees is the recording's own counts,
the recording loses nothing to viewers, and a replay (of MCAP or of an archive) is bit-exact."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.conftest import free_port
from tests.support.foxglove_client import FoxgloveClient
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource
from thermcap.recorder.radiometry import DEFAULT_MODEL
from thermcap.recorder.storage.reader import iter_session_frames

TOPICS = ["/thermal/image", "/thermal/metadata", "/thermal/annotations", "/thermal/temperature"]


def _connect(url: str, proc: subprocess.Popen, timeout: float = 60.0) -> FoxgloveClient:
    deadline = time.monotonic() + timeout
    while True:
        try:
            return FoxgloveClient(url)
        except OSError:
            if proc.poll() is not None:
                raise AssertionError(f"the process ended: {proc.stderr.read() if proc.stderr else ''}") from None
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def _frames_by_time(session_dir, camera=None) -> dict[int, np.ndarray]:
    return {f.log_time: np.array(f.pixels) for f in iter_session_frames(session_dir, camera)}


@pytest.mark.parametrize("width", [0, 320])
def test_viewers_see_the_recorded_counts_and_the_recording_drops_nothing(tmp_path, width):
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--root", str(tmp_path), "--session", "live",
                             "--duration", "6", "--live", "--live-port", str(port), "--live-fps", "20",
                             "--live-width", str(width), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    viewers = [_connect(f"ws://127.0.0.1:{port}", proc) for _ in range(2)]
    try:
        for v in viewers:
            v.subscribe(TOPICS)
        got = [v.receive(40, timeout=20) for v in viewers]
    finally:
        for v in viewers:
            v.close()
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    result = json.loads(out)
    assert result["frames_dropped"] == 0 and result["dropped"] == {}, result
    assert result["live"]["published"] > 10, result["live"]
    recorded = _frames_by_time(tmp_path / "sessions" / "live")
    for v, msgs in zip(viewers, got, strict=True):
        images = [m for m in msgs if m.topic == "/thermal/image"]
        assert len(images) >= 5, [m.topic for m in msgs]
        temps = {m.log_time: m.json() for m in msgs if m.topic == "/thermal/temperature"}
        for m in images:
            img = v.decode(m)
            assert img.encoding == "mono16"
            live = np.frombuffer(img.data, "<u2").reshape(img.height, img.width)
            source = recorded[m.log_time]  # the live stamp is the recording's
            expect = source if not width else source[::2, ::2]
            assert np.array_equal(live, expect), "the live picture is not the recorded counts"
            if m.log_time in temps:
                assert temps[m.log_time]["max_c"] == pytest.approx(
                    float(DEFAULT_MODEL.to_celsius(expect.max())), abs=1e-3)
        metas = [m for m in msgs if m.topic == "/thermal/metadata"]
        assert metas and all("thermal_analysis" in m.json() for m in metas)


def _record(root, frames: int = 30, session: str = "p") -> tuple:
    src = SimSource(width=160, height=128, fps=30, frames=frames, paced=False, seed=3)
    rec = Recorder(src, root, session_id=session, analysis=False)
    res = rec.run()
    assert res.ok, res.problems
    return rec.session_dir, res


def _play(session_dir, *extra: str, topic: str = "/thermal/image",
          count: int = 1000) -> tuple[list, FoxgloveClient, subprocess.Popen]:
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "play", str(session_dir), "--port", str(port),
                             "--wait-for-viewer", "30", "--rate", "2", "--json", *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    client = _connect(f"ws://127.0.0.1:{port}", proc)
    client.subscribe([topic])
    msgs = client.receive(count, timeout=30, topic=topic)
    client.close()
    proc.communicate(timeout=60)
    return msgs, client, proc


def test_play_replays_every_frame_bit_exact_then_again_from_the_archive(tmp_path):
    from thermcap.archive.archiver import archive_session

    session_dir, _ = _record(tmp_path)
    expected = _frames_by_time(session_dir)
    for source in ("mcap", "archive"):
        if source == "archive":
            archive_session(session_dir, ["png16"], delete_source=True)
            assert not list(session_dir.glob("*.mcap"))
        msgs, client, proc = _play(session_dir)
        assert proc.returncode == 0, proc.stderr.read() if proc.stderr else ""
        assert [m.log_time for m in msgs] == sorted(expected), f"{source}: frames missing or out of order"
        for m in msgs:
            img = client.decode(m)
            assert np.array_equal(np.frombuffer(img.data, "<u2").reshape(img.height, img.width), expected[m.log_time])


def test_play_of_a_missing_session_is_a_clear_error(tmp_path):
    r = subprocess.run([sys.executable, "-m", "thermcap", "play", "nope", "--root", str(tmp_path)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "nope: no such session" in r.stderr


def test_play_gives_the_temperatures_of_the_version_in_force(tmp_path):
    """After `thermcap radiometry`, `play` gave the recorded model's temperatures: the live view
    took its model once, from session.json. It now takes each frame's from the session's one
    temperature path, and names the version it used."""
    from thermcap.recorder.radiometry import model_from_dict
    from thermcap.recorder.radiometry.params import add_version
    from thermcap.recorder.storage.reader import read_session_meta

    session_dir, _ = _record(tmp_path)
    base = model_from_dict(read_session_meta(session_dir)["radiometric_model"])
    warmer = model_from_dict({**base.to_dict(), "offset_c": base.to_dict()["offset_c"] + 1.0})
    add_version(session_dir, base, {}, who="test", why="a new calibration", measured=warmer)
    expected = _frames_by_time(session_dir)
    msgs, _, _ = _play(session_dir, topic="/thermal/temperature", count=5)
    assert msgs
    for m in msgs:
        t = m.json()
        assert t["model_version"] == 1
        assert t["max_c"] == pytest.approx(float(warmer.to_celsius(expected[m.log_time].max())), abs=1e-3)
