"""One definition of a session's gaps (issue 64): jitter is not a gap, a pause is, and a gap's
seconds are the time without frames, not the whole step."""

from __future__ import annotations

import numpy as np

from thermcap.recorder.storage.coverage import coverage, gaps

PERIOD = 1e9 / 60


def test_arrival_jitter_is_not_a_gap():
    rng = np.random.default_rng(3)
    # frames stamped when they arrive: each up to one period late, 31 s at 60 fps
    times = sorted(int(i * PERIOD + rng.uniform(0, 0.95) * PERIOD) for i in range(31 * 60))
    assert len(coverage(times)) == 1  # was 705 gaps at 1.5 periods


def test_a_pause_is_one_gap_of_the_time_without_frames():
    times = [int(i * PERIOD) for i in range(120)] + [int(3e9 + i * PERIOD) for i in range(120)]
    spans = coverage(times)
    assert len(spans) == 2
    ((before, after, seconds),) = gaps(spans, PERIOD)
    assert before == times[119] and after == times[120]
    assert abs(seconds - (3e9 - int(119 * PERIOD) - PERIOD) / 1e9) < 1e-9


def test_ring_defaults_fit_the_budget_and_stand_on_a_real_disk():
    from thermcap.recorder.storage.ring import fit_to_budget

    raw = 640 * 512 * 2 * 60  # 39.3 MB/s
    small = fit_to_budget(200_000_000, 100_000_000, raw)
    assert 0.25 <= small.segment_s <= 0.6 and 0 < small.pre_s == small.post_s < 1
    # two windows, each counted by the whole segments it touches, fit the protected share
    span = small.pre_s + small.post_s
    assert 2 * (span + small.segment_s) * raw <= 100_000_000
    big = fit_to_budget(500_000_000_000, 250_000_000_000, raw)
    assert (big.segment_s, big.pre_s, big.post_s) == (60.0, 30.0, 30.0)
