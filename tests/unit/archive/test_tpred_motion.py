"""tpred's encoder steps compiled from numpy or measured on fewer pixels: the motion search's
lines, their medians and the shifts' costs, the defect watch's runs, version 6's correction and its
costs, and the block modes. Each is held to what it replaced or to the rule in integers: the records
depend on every one of these numbers, the same, not close."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from thermcap.archive.codecs.tpred import kernels as tpred_kernels

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


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 40), st.integers(1, 40), st.integers(-45, 45), st.integers(-45, 45), st.sampled_from([1, 4]),
       st.sampled_from([3, 40, 65536]), st.integers(0, 2**32 - 1))
def test_the_motion_checks_sums_are_numpys(h, w, dx, dy, step, spread, seed):
    """The search's last check: the clipped differences against the previous frame as it is and
    moved by (dx, dy) with its edges repeated, summed on every ``step``-th row and column, as
    numpy's fancy indexing summed them; moves past the frame's edge included."""
    rng = np.random.default_rng(seed)
    f, prev = (rng.integers(0, spread, (h, w)).astype(np.int32) for _ in range(2))
    sub = (slice(None, None, step), slice(None, None, step))
    rows = np.clip(np.arange(0, h, step) - dy, 0, h - 1)
    cols = np.clip(np.arange(0, w, step) - dx, 0, w - 1)
    still = int(np.minimum(np.abs(f[sub] - prev[sub]), _CLIP).sum())
    moved = int(np.minimum(np.abs(f[sub] - prev[rows[:, None], cols[None, :]]), _CLIP).sum())
    assert tpred_kernels.motion_sums(f, prev, dx, dy, step, _CLIP) == (still, moved)


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


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.integers(0, 2**32 - 1), st.integers(-15, 15), st.integers(-15, 15),
       st.integers(-16, 16), st.sampled_from([0, 200, 5000]))
def test_the_corrections_costs_are_the_applied_ones(h, w, seed, sx, sy, sl, spread):
    """Version 6's correction measured without writing the corrected frame gives the costs that
    applying it and measuring gives: at the frame's edge (no terms), at odd sizes (the last row
    or column is an edge counted), at the limit (terms left out) and outside the scene."""
    rng = np.random.default_rng(seed)
    m64 = (rng.integers(0, 60000 << 6) + rng.integers(0, spread + 1, (h, w))).astype(np.int32)
    est = rng.integers(-512, 513, (h, w)).astype(np.int32)
    other = rng.random((h, w)) < 0.2
    pred = ((m64.astype(np.int64) + est + 32) >> 6).astype(np.int32)
    f = np.clip(pred + rng.integers(-20, 21, (h, w)), 0, 65535).astype(np.int32)
    moved, m64c = np.empty_like(pred), np.empty_like(m64)
    limit = 64 << 6
    applied = tpred_kernels.subpel_apply(f, m64, est, other, pred, sx, sy, sl, limit, True, moved, m64c)
    assert tpred_kernels.subpel_costs(f, m64, est, other, pred, sx, sy, sl, limit) == applied


def _subpel_reference(m64, est, other, pred, sx, sy, sl, limit):
    """Version 6's correction as the bitstream specifies it, in numpy int64."""
    m = m64.astype(np.int64)
    p, mc = pred.astype(np.int64), m.copy()
    if m.shape[0] > 2 and m.shape[1] > 2:
        mm, left, right = m[1:-1, 1:-1], m[1:-1, :-2], m[1:-1, 2:]
        up, down = m[:-2, 1:-1], m[2:, 1:-1]
        gx, gy, lap = (right - left) >> 1, (down - up) >> 1, (4 * mm - left - right - up - down) >> 2
        ok = (np.abs(gx) < limit) & (np.abs(gy) < limit) & (np.abs(lap) < limit)
        inner = mm + np.where(ok, (sx * gx + sy * gy + sl * lap) >> 4, 0)
        mc[1:-1, 1:-1] = inner
        p[1:-1, 1:-1] = np.where(other[1:-1, 1:-1], p[1:-1, 1:-1], (inner + est[1:-1, 1:-1] + 32) >> 6)
    return p, mc


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.integers(0, 2**32 - 1), st.integers(-15, 15), st.integers(-15, 15),
       st.integers(-16, 16), st.sampled_from([0, 200, 5000, 65535 << 6]))
def test_the_correction_is_the_specified_integer_arithmetic(h, w, seed, sx, sy, sl, spread):
    """The compiled correction runs in float32 for speed; it must equal the specification's
    integers bit for bit: means up to 65535 counts in 1/64, terms at and beyond the limit,
    negative terms (the shifts' floor), the frame's edge, and frames too small to have an inside.
    The decoder's call (in place) too."""
    rng = np.random.default_rng(seed)
    base = int(rng.integers(0, (65535 << 6) - min(spread, (65535 << 6) - 1)))
    m64 = (base + rng.integers(0, spread + 1, (h, w))).clip(0, 65535 << 6).astype(np.int32)
    est = rng.integers(-512, 513, (h, w)).astype(np.int32)
    other = rng.random((h, w)) < 0.2
    pred = rng.integers(0, 65536, (h, w)).astype(np.int32)
    want_p, want_m = _subpel_reference(m64, est, other, pred, sx, sy, sl, 64 << 6)
    p, m64c = np.empty_like(pred), np.empty_like(m64)
    tpred_kernels.subpel_apply(pred, m64, est, other, pred, sx, sy, sl, 64 << 6, False, p, m64c)
    assert np.array_equal(p, want_p) and np.array_equal(m64c, want_m)
    in_place = pred.copy()
    tpred_kernels.subpel_apply(in_place, m64, est, other, in_place, sx, sy, sl, 64 << 6, False, in_place, m64c)
    assert np.array_equal(in_place, want_p)


def _subpel_sums_reference(f, m64, est, other, limit, clip):
    """Version 6's least-squares sums as the encoder's rule states them, in numpy int64."""
    out = np.zeros((3, 4))
    if f.shape[0] < 3 or f.shape[1] < 3:
        return out
    m = m64.astype(np.int64)
    inner = (slice(1, -1, 2), slice(1, -1, 2))
    mm = m[1:-1, 1:-1][::2, ::2]
    left, right = m[1:-1, :-2][::2, ::2], m[1:-1, 2:][::2, ::2]
    up, down = m[:-2, 1:-1][::2, ::2], m[2:, 1:-1][::2, ::2]
    gx, gy, lap = (right - left) >> 1, (down - up) >> 1, (4 * mm - left - right - up - down) >> 2
    res = (f[inner].astype(np.int64) << 6) - mm - est[inner]
    keep = ~other[inner] & (np.abs(gx) < limit) & (np.abs(gy) < limit) & (np.abs(lap) < limit) & (np.abs(res) < clip)
    terms = [np.where(keep, t, 0) for t in (gx, gy, lap)]
    for i in range(3):
        for j in range(3):
            out[i, j] = int((terms[i] * terms[j]).sum())
        out[i, 3] = int((terms[i] * res).sum())
    return out


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 30), st.integers(1, 30), st.integers(0, 2**32 - 1), st.sampled_from([0, 200, 5000, 65535 << 6]),
       st.sampled_from(["scene", "saturated", "at the clip"]))
def test_the_corrections_fit_sums_are_the_rules_integers(h, w, seed, spread, kind):
    """The fit's sums run in float32 terms and float64 sums for speed; they must equal the
    integers: means up to 65535 counts in 1/64 with the pattern's estimate on top (past 2**22),
    saturated pixels among zeros (a Laplacian's numerator past 2**24, which float32 rounds, left
    out by the limit), residuals on either side of the clip, terms beyond the limit, odd sizes."""
    rng = np.random.default_rng(seed)
    limit, clip = 64 << 6, 8 << 6
    base = int(rng.integers(0, (65535 << 6) - min(spread, (65535 << 6) - 1)))
    m64 = (base + rng.integers(0, spread + 1, (h, w))).clip(0, 65535 << 6)
    est = rng.integers(-512, 513, (h, w)).astype(np.int64)
    if kind == "saturated":  # a checkerboard of a saturated mean (plus the estimate) and a negative one
        board = (np.add.outer(np.arange(h), np.arange(w)) % 2).astype(bool)
        m64 = np.where(board, (65535 << 6) + 512, -int(rng.integers(0, 513)))
    f = np.clip(((m64 + est + 32) >> 6) + rng.integers(-12, 13, (h, w)), 0, 65535)
    if kind == "at the clip":  # the residual 64 f - m64 - est one either side of the clip, or on it
        m64 = (f << 6) - est - rng.choice([-clip - 1, -clip, -clip + 1, 0, clip - 1, clip, clip + 1], (h, w))
    other = rng.random((h, w)) < 0.2
    f, m64, est = f.astype(np.int32), m64.astype(np.int32), est.astype(np.int32)
    got = tpred_kernels.subpel_sums(f, m64, est, other, limit, clip)
    assert np.array_equal(got, _subpel_sums_reference(f, m64, est, other, limit, clip))


def _block_choices_reference(f, pred, prev, cand, wb, block, vectors):
    """The block-mode rule in numpy int64: partial blocks repeat the frame's last row and column,
    the moved previous frame is edge replicated, the first vector beating the scene by more than
    ``2 * block`` is taken (1-based), 0 where none does."""
    h, w = f.shape
    out = np.zeros(cand.size, np.uint8)
    for n, b in enumerate(cand.tolist()):
        r0, c0 = (b // wb) * block, (b % wb) * block
        rows = np.minimum(np.arange(r0, r0 + block), h - 1)[:, None]
        cols = np.minimum(np.arange(c0, c0 + block), w - 1)[None, :]
        fb = f[rows, cols].astype(np.int64)
        best = int(np.minimum(np.abs(fb - pred[rows, cols]), 20).sum())
        for k, (vx, vy) in enumerate(vectors.tolist()):
            qr = np.clip(np.arange(r0, r0 + block) - vy, 0, h - 1)[:, None]
            qc = np.clip(np.arange(c0, c0 + block) - vx, 0, w - 1)[None, :]
            cost = 2 * block + int(np.minimum(np.abs(fb - prev[qr, qc]), 20).sum())
            if cost < best:
                best, out[n] = cost, k + 1
    return out


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 70), st.integers(1, 70), st.integers(0, 2**32 - 1), st.sampled_from([30, 65536]))
def test_block_modes_are_chosen_by_the_rule(h, w, seed, spread):
    """Blocks inside the frame take the unclamped float32 sums, blocks at its edge or moved past
    it the clamped ones; both choose as the rule does, ties included (small spreads)."""
    from thermcap.archive.codecs.tpred.codec import _VECTOR_ARRAY, BLOCK

    rng = np.random.default_rng(seed)
    f = rng.integers(0, spread, (h, w)).astype(np.int32)
    pred, prev = ((f + rng.integers(-40, 40, (h, w))).astype(np.int32) for _ in range(2))
    hb, wb = -(-h // BLOCK), -(-w // BLOCK)
    cand = rng.permutation(hb * wb)[: int(rng.integers(1, hb * wb + 1))].astype(np.int64)
    got = tpred_kernels.block_choices(f, pred, prev, cand, wb, BLOCK, _VECTOR_ARRAY)
    assert np.array_equal(got, _block_choices_reference(f, pred, prev, cand, wb, BLOCK, _VECTOR_ARRAY))


def test_the_windows_passes_read_contiguous_rows():
    """The window's canvases go to ``predict``, ``learn_and_push`` and ``trim`` whole, with the
    frame's offset: a slice of them is compiled for any strides, and those passes then ran a
    pixel at a time (2.5x slower). A pan moves the frame across the canvas, so every call has an
    offset."""
    from thermcap.archive.codecs.tpred.codec import TemporalEncoder
    from thermcap.recorder.capture.sources.sim import SimSource

    enc = TemporalEncoder(window=4)  # frames leave the window from the fifth on
    for frame in SimSource(width=96, height=64, frames=12, paced=False, seed=3, view="patrol").frames():
        enc.encode(frame.pixels)
    for kernel in (tpred_kernels.predict, tpred_kernels.learn_and_push, tpred_kernels.trim):
        assert kernel.signatures
        assert all(getattr(t, "layout", "C") == "C" for sig in kernel.signatures for t in sig), kernel


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 30), st.integers(1, 40), st.integers(0, 2**32 - 1),
       st.sampled_from(["none", "edges", "scattered", "edges and scattered", "all"]))
def test_the_residuals_split_as_the_mask_says(h, w, seed, where):
    """The scene's residuals and the others', each in raster order, and the least and greatest
    residual: rows with no other pixel, with others at their ends only (a pan's uncovered edge),
    with others inside, and rows of others alone; predictions past the counts' range."""
    rng = np.random.default_rng(seed)
    f = rng.integers(0, 65536, (h, w)).astype(np.int32)
    p = (f + rng.integers(-70_000, 70_001, (h, w))).astype(np.int32)
    other = np.zeros((h, w), bool)
    if "edges" in where:
        other[:, :int(rng.integers(0, w + 1))] = True
        other[:, w - int(rng.integers(0, w + 1)):] = True
    if "scattered" in where:
        other |= rng.random((h, w)) < 0.05
    if where == "all":
        other[:] = True
    scene, rest = np.empty(f.size, np.int32), np.empty(f.size, np.int32)
    n0, n1, lo, hi = tpred_kernels.split_residuals(f, p, other, scene, rest)
    res = f.astype(np.int64) - p
    assert (n0, n1, lo, hi) == (int((~other).sum()), int(other.sum()), int(res.min()), int(res.max()))
    assert np.array_equal(scene[:n0], res[~other]) and np.array_equal(rest[:n1], res[other])
