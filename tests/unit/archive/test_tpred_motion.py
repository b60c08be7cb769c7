"""tpred's encoder steps compiled from numpy: the motion search's lines, their medians and the
shifts' costs, and the defect watch's runs, each held to the numpy it replaced. The records depend
on every one of these numbers (a different median can pick a different shift): the same, not close."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from thermcap.archive import tpred_kernels

_CLIP = 16


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 90), st.integers(1, 40), st.sampled_from([1, 3, 300, 65536]), st.integers(0, 2**32 - 1),
       st.sampled_from([np.int32, np.int64]))
def test_column_medians_are_numpys(rows, n, spread, seed, dtype):
    """Odd and even counts of rows (one middle value, or the mean of two), ties, a single value
    a column, sorted columns, and the full range of counts."""
    rng = np.random.default_rng(seed)
    x = rng.integers(0, spread, (rows, n)).astype(dtype)
    if rng.random() < 0.3:
        x = np.sort(x, axis=0)[::int(rng.choice([1, -1]))]
    got = tpred_kernels.column_medians(np.ascontiguousarray(x))
    assert got.dtype == np.float64 and np.array_equal(got, np.median(x, axis=0))


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.integers(1, 9), st.integers(-50, 50), st.integers(0, 2**32 - 1))
def test_sampled_lines_are_the_rolled_frames_lines(h, w, step, other, seed):
    """For columns (``axis`` 1) ``np.roll(f, other, 0)[::step]``; for rows (``axis`` 0) the
    same of the transpose: what the search compared before, lines wrapping at the frame's edge."""
    f = np.random.default_rng(seed).integers(0, 65536, (h, w)).astype(np.int32)
    assert np.array_equal(tpred_kernels.sampled_lines(f, 1, step, other), np.roll(f, other, 0)[::step])
    assert np.array_equal(tpred_kernels.sampled_lines(f, 0, step, other), np.roll(f.T, other, 0)[::step])


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 12), st.integers(2, 60), st.sampled_from([4, 40, 65536]), st.integers(0, 2**32 - 1))
def test_line_costs_are_the_float_costs(rows, n, spread, seed):
    """The integer lines' costs equal ``shift_costs`` on the same lines in float64 (what the
    search measured before), for every shift the overlap allows, negative ones included."""
    rng = np.random.default_rng(seed)
    x, y = (rng.integers(0, spread, (rows, n)).astype(np.int32) for _ in range(2))
    shifts = np.arange(-(n // 2), n // 2 + 1)
    want = tpred_kernels.shift_costs(x.astype(np.float64), y.astype(np.float64), shifts, _CLIP)
    assert np.array_equal(tpred_kernels.line_shift_costs(x, y, shifts, _CLIP), want)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 30), st.integers(1, 30), st.integers(0, 2**32 - 1))
def test_the_defect_watch_counts_runs_as_numpy_did(h, w, seed):
    """A pixel's run of unchanged frames goes up by one where the frame equals the last (held at
    255, never wrapping to 0) and back to naught where it does not."""
    rng = np.random.default_rng(seed)
    run = rng.integers(0, 256, (h, w)).astype(np.uint8)
    f, last = (rng.integers(0, 3, (h, w)).astype(np.int32) for _ in range(2))
    want = np.minimum(run, 254) + np.uint8(1)
    want *= f == last
    tpred_kernels.count_runs(f, last, run)
    assert np.array_equal(run, want)
