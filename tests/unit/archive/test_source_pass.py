"""The archiver's one read of the source hands its codecs aligned pixels: about half of a
recording's frames sit at an odd address inside their chunk, and each of three codecs read them
by its unaligned path."""

from __future__ import annotations

import numpy as np
import pytest

from thermcap.archive.source_pass import SourcePass
from thermcap.recorder.storage.reader import count_frames, iter_session_frames


def test_the_pass_gives_every_frame_aligned_read_only_and_equal(session):
    as_read = list(iter_session_frames(session))
    if all(f.pixels.flags.aligned for f in as_read):
        pytest.fail("the recorded session has no unaligned frame: this test would check nothing")
    passed = list(SourcePass(session, count_frames(session)).frames())
    assert len(passed) == len(as_read)
    for got, want in zip(passed, as_read, strict=True):
        assert got.pixels.flags.aligned
        assert got.pixels.ctypes.data % got.pixels.dtype.alignment == 0
        assert not got.pixels.flags.writeable  # the consumers share it, as they shared the view
        assert np.array_equal(got.pixels, want.pixels)
        assert (got.index, got.segment, got.log_time, got.sidecar) == (want.index, want.segment, want.log_time,
                                                                        want.sidecar)
