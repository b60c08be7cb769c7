"""Defect 7: export.mcap repeated messages at chunk boundaries. A property test over random
ranges, topic sets and chunk layouts against a brute-force read of the segments."""

from __future__ import annotations

import hashlib
import io
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from thermcap.archive.reading.mcap_slice import export_mcap
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy

T0 = 1_800_000_000_000_000_000
TOPICS = ["/thermal/image", "/thermal/metadata", "/recorder/stats", "/radar/cue", "/sim/ground_truth"]


@pytest.fixture(scope="module", params=[(24_000, 0.5), (200_000, 10.0)], ids=["tiny-chunks", "big-chunks"])
def session(request, tmp_path_factory) -> Path:
    chunk, seg_s = request.param
    root = tmp_path_factory.mktemp("export")
    Recorder(SimSource(width=96, height=64, frames=150, paced=False, start_time_ns=T0, first_cue_s=0.2,
                       cue_period_s=0.5), root, session_id="s",
             policy=SegmentPolicy(max_duration_s=seg_s, chunk_size=chunk), analysis=False, stats_interval_s=0.01).run()
    return root / "sessions" / "s"


def _messages(paths_or_bytes) -> Counter:
    out: Counter = Counter()
    for item in paths_or_bytes:
        with io.BytesIO(item) if isinstance(item, bytes) else open(item, "rb") as f:
            for _, ch, msg in make_reader(f).iter_messages(log_time_order=False):
                out[(ch.topic, msg.log_time, hashlib.sha256(msg.data).hexdigest())] += 1
    return out


def _brute(session: Path, t0, t1, topics) -> Counter:
    return Counter({k: n for k, n in _messages(sorted(session.glob("*.mcap"))).items()
                    if (t0 is None or k[1] >= t0) and (t1 is None or k[1] < t1) and (not topics or k[0] in topics)})


def test_whole_session_and_image_topic_have_each_message_once(session):
    whole = b"".join(export_mcap(session, None, None, None))
    assert _messages([whole]) == _brute(session, None, None, None)
    images = _messages([b"".join(export_mcap(session, None, None, ["/thermal/image"]))])
    assert sum(images.values()) == 150
    assert max(images.values()) == 1


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(a=st.integers(-5, 155), b=st.integers(-5, 155), open_a=st.booleans(), open_b=st.booleans(),
       topics=st.lists(st.sampled_from(TOPICS), unique=True, max_size=3))
def test_any_range_and_topics_give_exactly_the_messages_in_it(session, a, b, open_a, open_b, topics):
    period = 1e9 / 60
    t0 = None if open_a else T0 + int(min(a, b) * period)
    t1 = None if open_b else T0 + int(max(a, b) * period) + 1
    got = _messages([b"".join(export_mcap(session, t0, t1, topics or None))])
    assert got == _brute(session, t0, t1, topics)


def test_attachments_and_metadata_of_every_segment_are_kept_once(session):
    out = b"".join(export_mcap(session, None, None, None))
    reader = make_reader(io.BytesIO(out))
    names = [a.name for a in reader.iter_attachments()]
    assert names.count("bad_pixel_map.json") == 1
    segs = sorted(session.glob("*.mcap"))
    seg_records = set()
    for seg in segs:
        with open(seg, "rb") as f:
            seg_records |= {(m.name, tuple(sorted(m.metadata.items()))) for m in make_reader(f).iter_metadata()}
    got = [(m.name, tuple(sorted(m.metadata.items()))) for m in make_reader(io.BytesIO(out)).iter_metadata()]
    assert set(got) == seg_records
    assert len(got) == len(set(got))
