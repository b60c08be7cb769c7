"""Bounded fuzzing of everything that reads bytes from outside: MCAP recovery, the raw source,
the importers. Every input ends in data or a clean ThermcapError, never a crash or a hang."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.raw import RawSource
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import McapFileError, TruncatedFrameError
from thermcap.recorder.importers import ImportFileError, read_file
from thermcap.recorder.storage.recover import recover_segment

FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                       HealthCheck.too_slow])


@pytest.fixture(scope="module")
def segment(tmp_path_factory) -> bytes:
    root = tmp_path_factory.mktemp("fz")
    Recorder(SimSource(width=48, height=32, frames=30, paced=False), root, session_id="f", analysis=False).run()
    return next((root / "sessions" / "f").glob("*.mcap")).read_bytes()


@FUZZ
@given(data=st.data())
def test_recover_any_damaged_segment(segment, tmp_path, data):
    buf = bytearray(segment)
    cut = data.draw(st.integers(0, len(buf)))
    for _ in range(data.draw(st.integers(0, 6))):
        pos = data.draw(st.integers(0, len(buf) - 1))
        buf[pos] ^= data.draw(st.integers(1, 255))
    src = tmp_path / f"x{data.draw(st.integers(0, 10**9))}.mcap.active"
    src.write_bytes(bytes(buf[:cut]))
    try:
        res = recover_segment(src)
    except McapFileError:
        return
    if res.output.endswith(".unreadable"):  # an empty file is moved aside, never taken for a segment
        assert cut == 0 and not src.exists()
        return
    with open(res.output, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == res.messages
        assert sum(1 for _ in reader.iter_messages()) == res.messages


@FUZZ
@given(n_bytes=st.integers(0, 5 * 96 * 2 + 50))
def test_raw_source_any_length(n_bytes):
    frame_bytes = 96 * 2
    stream = io.BytesIO(bytes(range(256)) * (n_bytes // 256 + 1))
    stream = io.BytesIO(stream.getvalue()[:n_bytes])
    src = RawSource("-", width=96, height=1, stream=stream)
    got = 0
    try:
        for f in src.frames():
            got += 1
            assert f.pixels.shape == (1, 96)
    except TruncatedFrameError as exc:
        assert n_bytes % frame_bytes
        assert exc.got == n_bytes % frame_bytes
    assert got == n_bytes // frame_bytes


SAMPLES = ["dji/M2EA_DJI_0001_R.JPG", "dji/DJI_H20T.jpg", "flir/FLIR_E40.jpg", "flir/frame_000000.fff",
           "flir/example_radiometric.tiff"]


@pytest.mark.parametrize("name", SAMPLES)
def test_importers_on_mutated_samples(samples, tmp_path, name):
    original = (samples / name).read_bytes()

    @FUZZ
    @given(data=st.data())
    def run(data):
        buf = bytearray(original)
        for _ in range(data.draw(st.integers(1, 8))):
            pos = data.draw(st.integers(0, len(buf) - 1))
            buf[pos] = data.draw(st.integers(0, 255))
        cut = data.draw(st.integers(1, len(buf)))
        p = tmp_path / Path(name).name
        p.write_bytes(bytes(buf[:cut]))
        try:
            frames = read_file(p)
        except ImportFileError as exc:
            assert str(p) in str(exc)
            return
        for f in frames:
            assert f.pixels.dtype == np.uint16
            assert f.pixels.ndim == 2

    run()
