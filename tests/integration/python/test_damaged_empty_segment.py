"""Issue 65, defect 8: a segment that holds no frame (what `recover` leaves after a kill early in
a segment), with one byte damaged, hid the whole session from ``thermcap.open`` (UnicodeDecodeError,
EndOfFile, InvalidMagic ... escaped the reader). A damaged part hides only itself."""

from __future__ import annotations

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

import thermcap
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy


@pytest.fixture(scope="module")
def with_empty_segment(tmp_path_factory):
    root = tmp_path_factory.mktemp("root")
    Recorder(SimSource(width=48, height=32, frames=20, paced=False, start_time_ns=1_800_000_000_000_000_000), root,
             session_id="s", analysis=False, policy=SegmentPolicy(max_duration_s=0.15)).run()
    session = root / "sessions" / "s"
    first = sorted(session.glob("*.mcap"))[0]
    with open(first, "rb") as f:
        summary = make_reader(f).get_summary()
    with open(session / "0099.mcap", "wb") as f:  # the schemas and channels, no message
        w = Writer(f)
        w.start(profile="", library="thermcap-test")
        for schema in summary.schemas.values():
            w.register_schema(schema.name, schema.encoding, schema.data)
        for ch in summary.channels.values():
            w.register_channel(ch.topic, ch.message_encoding, ch.schema_id, dict(ch.metadata))
        w.finish()
    return root


def test_one_damaged_byte_in_an_empty_segment_hides_only_that_segment(with_empty_segment):
    path = with_empty_segment / "sessions" / "s" / "0099.mcap"
    good = path.read_bytes()
    escaped = {}
    for at in range(0, len(good), 11):  # every 11th byte: the header, schemas, channels, summary, footer
        data = bytearray(good)
        data[at] ^= 0x41
        path.write_bytes(bytes(data))
        try:
            session = thermcap.open(with_empty_segment / "sessions" / "s")
            assert len(session) == 20 and session.counts(19).shape == (32, 48), f"byte {at}"
        except AssertionError:
            raise
        except Exception as exc:
            escaped[at] = f"{type(exc).__name__}: {exc}"
    path.write_bytes(good)
    assert not escaped, escaped
