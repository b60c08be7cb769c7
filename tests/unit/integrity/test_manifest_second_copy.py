"""Issue 65, defect 13: one flipped bit in ``manifest.json`` made three intact copies (png16,
tiff-lzw, hdf5) unreachable: ``verify`` and ``scrub --repair`` stopped at "unreadable manifest",
``info`` said "frames: 0". The manifest is now kept twice, each copy with its own checksum, and
read from the first that holds; a flip that still parses is caught by the checksum."""

from __future__ import annotations

import json

import numpy as np
import pytest

import thermcap
from thermcap.archive.archiver import archive_session
from thermcap.archive.exceptions import ManifestError
from thermcap.archive.manifest import load_manifest
from thermcap.archive.verify import verify_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.info import session_info
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.segments import SegmentPolicy


@pytest.fixture
def archived(tmp_path):
    root = tmp_path / "root"
    Recorder(SimSource(width=64, height=48, frames=30, paced=False, seed=5, start_time_ns=1_700_000_000_000_000_000),
             root, session_id="s", analysis=False, policy=SegmentPolicy(max_duration_s=0.25)).run()
    session = root / "sessions" / "s"
    truth = [f.pixels.copy() for f in iter_session_frames(session)]
    archive_session(session, ["png16", "tiff-lzw", "hdf5"], delete_source=True)
    return session, truth


@pytest.mark.parametrize("flip", ["breaks the JSON", "still parses"])
def test_one_flipped_bit_in_the_manifest_loses_nothing(archived, flip):
    session, truth = archived
    path = session / "archive" / "manifest.json"
    raw = bytearray(path.read_bytes())
    if flip == "breaks the JSON":
        raw[raw.index(b'"formats"')] ^= 0x04  # the opening quote: no longer JSON
    else:
        # a digit of the source's frame count: still JSON, a wrong number
        at = next(i for i in range(raw.index(b'"source"'), len(raw)) if chr(raw[i]).isdigit())
        raw[at] ^= 0x01
    path.write_bytes(bytes(raw))
    m = load_manifest(session)
    assert m["source"]["frames"] == len(truth)
    assert all(c.ok for c in verify_session(session).values())
    assert session_info(session).frames == len(truth)
    opened = thermcap.open(session)
    assert len(opened) == len(truth) and np.array_equal(opened.counts(5), truth[5])


def test_both_copies_damaged_is_said_not_guessed(archived):
    session, _ = archived
    for name in ("manifest.json", "manifest.copy.json"):
        p = session / "archive" / name
        doc = json.loads(p.read_text())
        doc["source"]["frames"] += 1  # still JSON, checksum no longer holds
        p.write_text(json.dumps(doc))
    with pytest.raises(ManifestError, match="checksum"):
        load_manifest(session)
