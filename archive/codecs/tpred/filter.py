"""tpred version 8's prediction filters: two 5x5 filters on the scene mean, fitted to each frame.

A camera that shakes moves each frame by a random fraction of a pixel. Version 6 moves the
window's mean by a first-order shift and weighs its Laplacian, three numbers; a bilinear move
also blurs the picture by an amount that depends on the fraction, and the mean of frames at other
fractions is blurred differently, which no shift and no single Laplacian follow. A 5x5 filter
fitted by least squares to each frame follows both. Where the scene is flat the best filter
mostly averages the mean's noise away, and where it has detail it mostly moves it, so there are
two, one for each (split at ``FILTER_SPLIT``). On 120 frames of the simulator's 0.5 px shake,
2026-12-06, against version 7's three terms: one filter in 1/64 +2.1 % (a still view) and +2.5 %
(a pan), its coefficients in 1/256-1/512 +0.2 % more, every pixel to the frame's edge
(replicated) +0.2 %, and the second filter +0.35-0.5 %; 3x3 and 7x7 filters, three classes, and a
split at 4, 6, 11 or 16 counts were each worse (``docs/explanation/tpred.md``, v8).

Specified in ``archive.codecs.tpred.codec``'s docstring (version 8). The decoder's step
(``filter_apply``) is integer arithmetic in effect; the encoder's fit (``fit``) gathers exact
integer sums (int16 samples, their products summed in int32 blocks and the blocks in int64, so
any order gives the same numbers) and solves a 24x24 system a filter in float64, which only
decides the coefficients the record carries.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from thermcap.archive.codecs.tpred.kernels import row_costs

__all__ = ["FILTERS", "FILTER_LIMIT", "FILTER_SPLIT", "PRECISIONS", "TAPS", "filter_apply", "fit"]

#: The 24 neighbours of a 5x5 filter, (dy, dx) in row-major order without the centre: the order
#: of each filter's coefficients in a record.
TAPS = np.asarray([(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if dy or dx], np.int64)
#: How many filters a record carries: the first for pixels whose 24 neighbours all lie within
#: ``FILTER_SPLIT`` of them in the scene mean, the second for the rest within ``FILTER_LIMIT``.
FILTERS = 2
FILTER_SPLIT = 8 << 6
#: A pixel whose neighbours differ from it by this much or more in the scene mean (64 counts, in
#: 1/64 counts) sits on an edge no small move follows linearly, or beside a defect: left as it is.
FILTER_LIMIT = 64 << 6
#: The coefficients are int8 in units of ``2**-precision``, the finest of these in which every
#: one of a filter fits.
PRECISIONS = range(4, 10)
_CLIP = 8 << 6  # residuals the fit leaves out: something moving on its own
_ROW_STEP, _COL_STEP = 2, 7  # the fit's pixels: 1/14 of them, within 0.05 % of 1/4's fit


@numba.njit(cache=True, nogil=True, inline="always")
def _row_taps(line: np.ndarray, c: int, mm: Any, out: np.ndarray, t: int, n: int,
              centre: bool) -> int:  # pragma: no cover
    """One row of sample ``n``'s taps into ``out[t:, n]`` (the centre's column left out where
    ``centre`` is False); returns the next tap's row. Inlined where it is called, so the five
    calls compile as five rows of constant columns, read through a slice of the row (no check of
    a negative index a tap). A difference is stored as int16, which holds it wherever a sample
    is kept (below ``FILTER_LIMIT``, 2**12)."""
    seg = line[c - 2:c + 3]
    out[t, n] = np.int16(np.int64(seg[0]) - mm)
    out[t + 1, n] = np.int16(np.int64(seg[1]) - mm)
    if centre:
        out[t + 2, n] = np.int16(np.int64(seg[2]) - mm)
        out[t + 3, n] = np.int16(np.int64(seg[3]) - mm)
        out[t + 4, n] = np.int16(np.int64(seg[4]) - mm)
        return t + 5
    out[t + 2, n] = np.int16(np.int64(seg[3]) - mm)
    out[t + 3, n] = np.int16(np.int64(seg[4]) - mm)
    return t + 4


@numba.njit(cache=True, nogil=True, inline="always")
def _put_sample(out: np.ndarray, n: int, q0: np.ndarray, q1: np.ndarray, q2: np.ndarray, q3: np.ndarray,
                q4: np.ndarray, c: int, mm: Any, res: Any) -> None:  # pragma: no cover
    """Sample ``n`` of ``out``: the differences at ``TAPS``, in their order, then the residual."""
    t = _row_taps(q0, c, mm, out, 0, n, True)
    t = _row_taps(q1, c, mm, out, t, n, True)
    t = _row_taps(q2, c, mm, out, t, n, False)
    t = _row_taps(q3, c, mm, out, t, n, True)
    t = _row_taps(q4, c, mm, out, t, n, True)
    out[t, n] = res


@numba.njit(cache=True, nogil=True)
def _samples(f: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray, split: int, limit: int, clip: int,
             flat: np.ndarray, detail: np.ndarray) -> tuple[int, int]:  # pragma: no cover
    """The fit's samples (a column each: the differences at ``TAPS``, in their order, then the
    residual ``64 f - m64 - est``) at the sampled scene pixels inside the frame's 2-pixel edge
    whose residual is within ``clip``: into ``flat`` where every neighbour lies within ``split``,
    into ``detail`` where within ``limit``; returns how many of each. Int16 samples
    (``_normal_equations`` says why).

    A sample's span (its largest difference) comes from each column's least and greatest mean
    over the five rows, worked out for every column of the row at once (a pass that vectorises),
    then five of each a sample; only a sample that is kept has its differences written, straight
    into its own array. 0.98 -> 0.67 ms a 640x512 frame on a Zen 4, against a span from each
    difference in turn, every sample written and the detail ones copied (2026-12-07); the same
    samples."""
    h, w = f.shape
    nf = nd = 0
    hi = np.empty(w, np.int32)
    lo = np.empty(w, np.int32)
    for r in range(2, h - 2, _ROW_STEP):
        q0, q1, q2, q3, q4 = m64[r - 2], m64[r - 1], m64[r], m64[r + 1], m64[r + 2]
        fr, er, orow = f[r], est[r], other[r]
        for c in range(w):
            a, b, m, d, e = q0[c], q1[c], q2[c], q3[c], q4[c]
            hi[c] = max(max(max(a, b), max(d, e)), m)
            lo[c] = min(min(min(a, b), min(d, e)), m)
        for c in range(2, w - 2, _COL_STEP):
            if orow[c]:
                continue
            res = (np.int64(fr[c]) << 6) - q2[c] - er[c]
            if abs(res) >= clip:
                continue
            mm = np.int64(q2[c])
            top = max(max(max(hi[c - 2], hi[c - 1]), max(hi[c + 1], hi[c + 2])), hi[c])
            low = min(min(min(lo[c - 2], lo[c - 1]), min(lo[c + 1], lo[c + 2])), lo[c])
            span = max(np.int64(top) - mm, mm - np.int64(low))
            if span < split:
                _put_sample(flat, nf, q0, q1, q2, q3, q4, c, mm, res)
                nf += 1
            elif span < limit:
                _put_sample(detail, nd, q0, q1, q2, q3, q4, c, mm, res)
                nd += 1
    return nf, nd


def _block_for(bound: int) -> int:
    """Samples a block of ``_normal_equations`` for differences below ``bound``: as many as keep
    a sum of their products within int32 (at most 4,096), in whole vectors of 16. A bound where
    16 would not fit is refused: the filters' differences are far below it."""
    block = min(4096, (2**31 - 1) // max(1, bound - 1) ** 2 // 16 * 16)
    if block < 16:
        raise ValueError(f"tpred: samples below {bound} do not fit int32 sums of 16")
    return block


@numba.njit(cache=True, nogil=True, boundscheck=False)
def _normal_equations(x: np.ndarray, n: int, block: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """``X^T X`` and ``X^T y`` over the first ``n`` samples of ``x`` (int16, one row a tap, the
    last the residual), as float64 holding the exact integers. Integer arithmetic, exact: each
    product of two samples fits int32, and so does a sum of ``block`` of them (``_block_for``
    the samples' bound: 128 for the detail filter's differences below 2**12, 4,096 for the flat
    one's below 2**9); the blocks' sums add in int64. Each step is truncated to int32, which
    numba would otherwise widen to int64: AVX2 then multiplies and adds 16 samples' pairs in one
    instruction (``vpmaddwd``) where float64 took four products and their conversions. Two rows
    against two at a time, four sums from four loads: 0.17-0.20 against 0.32 ms for 11,000
    samples on a Zen 4, the same numbers (2026-12-07)."""
    k = x.shape[0] - 1
    acc = np.zeros((k + 1, k + 1), np.int64)
    for start in range(0, n, block):
        stop = min(start + block, n)
        m = stop - start
        for i in range(0, k - 1, 2):
            a0 = x[i, start:stop]
            a1 = x[i + 1, start:stop]
            for j in range(i, k - 1, 2):
                b0 = x[j, start:stop]
                b1 = x[j + 1, start:stop]
                s00 = s01 = s10 = s11 = np.int32(0)
                for q in range(m):
                    u0, u1, v0, v1 = np.int32(a0[q]), np.int32(a1[q]), np.int32(b0[q]), np.int32(b1[q])
                    s00 = np.int32(s00 + u0 * v0)
                    s01 = np.int32(s01 + u0 * v1)
                    s10 = np.int32(s10 + u1 * v0)
                    s11 = np.int32(s11 + u1 * v1)
                acc[i, j] += s00
                acc[i, j + 1] += s01
                acc[i + 1, j] += s10
                acc[i + 1, j + 1] += s11
            for j in range(k - 1 if k % 2 else k, k + 1):  # the columns no pair covers
                b0 = x[j, start:stop]
                s0 = s1 = np.int32(0)
                for q in range(m):
                    v0 = np.int32(b0[q])
                    s0 = np.int32(s0 + np.int32(a0[q]) * v0)
                    s1 = np.int32(s1 + np.int32(a1[q]) * v0)
                acc[i, j] += s0
                acc[i + 1, j] += s1
        if k % 2:  # the last tap's row alone
            i = k - 1
            a0 = x[i, start:stop]
            for j in range(i, k + 1):
                b0 = x[j, start:stop]
                s0 = np.int32(0)
                for q in range(m):
                    s0 = np.int32(s0 + np.int32(a0[q]) * np.int32(b0[q]))
                acc[i, j] += s0
    g = np.empty((k, k))
    b = np.empty(k)
    for i in range(k):
        for j in range(i, k):
            g[i, j] = np.float64(acc[i, j])
            g[j, i] = np.float64(acc[i, j])
        b[i] = np.float64(acc[i, k])
    return g, b


@numba.njit(cache=True, nogil=True, inline="always")
def _pad_row(m64: np.ndarray, y: int, out: np.ndarray) -> None:  # pragma: no cover
    """Row ``y`` of ``m64`` into ``out`` in float32, two columns of its edge replicated each side."""
    src = m64[y]
    w = src.shape[0]
    out[0] = out[1] = src[0]
    for c in range(w):
        out[c + 2] = src[c]
    out[w + 2] = out[w + 3] = src[w - 1]


@numba.njit(cache=True, nogil=True, inline="always")
def _tap(d: Any, ak: Any, bk: Any, sa: Any, sb: Any, span: Any) -> tuple[Any, Any, Any]:  # pragma: no cover
    """One tap's difference ``d`` added to both filters' sums and the span."""
    return sa + ak * d, sb + bk * d, max(span, abs(d))


@numba.njit(cache=True, nogil=True, boundscheck=False, fastmath={"contract"})
def filter_apply(f: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray, pred: np.ndarray,
                 coefs: np.ndarray, precisions: np.ndarray, split: int, limit: int, measure: bool, p: np.ndarray,
                 m64c: np.ndarray) -> tuple[int, int]:  # pragma: no cover
    """Version 8's filtered scene mean and prediction. At each pixel not in ``other``, with
    ``d_k = m64[r + dy_k, c + dx_k] - m64[r, c]`` (rows and columns outside the frame replicate
    its edge) and ``span = max |d_k|``: where ``span < limit``, filter ``i`` (0 where ``span <
    split``, else 1) gives ``m64c = m64 + (sum(coefs[i, k] * d_k) >> precisions[i])`` and ``p =
    (m64c + est + 32) >> 6``; every other pixel keeps ``m64`` and ``pred``. ``measure`` (the
    encoder): also the sums of ``|f - pred|`` and ``|f - p|`` over the scene's pixels on every
    other row and column (``residual_costs``' measure, taken a row at a time while the row is in
    cache). ``p`` may be ``pred`` itself where ``measure`` is False: the decoder filters in place.

    In float32, which is exact here and vectorises where numba's integers (widened to int64)
    do not: every value is an integer below 2**24 (a count in 1/64 is below 2**22; a term's
    product below 2**12 * 2**7, 24 of them below 2**24), a pixel whose sum could be larger is one
    the limit leaves as it is, and the scaling by ``2**-precision`` is exact. So any order of
    adding, and a multiply fused with its add (``contract``), gives the same numbers. Each tap is
    used as soon as it is read, its terms going to two sums a filter in turn: the pass stays in
    AVX2's 16 vector registers, where all 24 differences first and one chain of adds spilled to
    the stack (1.6 against 2.6 ms a 640x512 frame on a Zen 4, with the two changes below). Both
    filters' sums are computed at every pixel and one kept: a choice per pixel would not
    vectorise, and every pixel's result is written as a select. The five rows a row reads are a
    ring of rows padded once each, read from column 0, so the indices are never negative and the
    loop has no wraparound branch (4-7 times faster)."""
    h, w = m64.shape
    a = coefs[0].astype(np.float32)
    b = coefs[1].astype(np.float32)
    scale_a = np.float32(2.0 ** -precisions[0])
    scale_b = np.float32(2.0 ** -precisions[1])
    lim, cut = np.float32(limit), np.float32(split)
    sixty_fourth = np.float32(1.0 / 64.0)
    half = np.float32(32.0)
    zero = np.float32(0.0)
    moved = np.empty(w, np.float32)
    inside = np.empty(w, np.bool_)
    ring = np.empty((5, w + 4), np.float32)  # padded row i (m64's row i - 2, clamped) in ring[i % 5]
    for i in range(4):
        _pad_row(m64, min(max(i - 2, 0), h - 1), ring[i])
    before = 0
    after = 0
    for r in range(h):
        _pad_row(m64, min(r + 2, h - 1), ring[(r + 4) % 5])
        q0, q1, q2, q3, q4 = ring[r % 5], ring[(r + 1) % 5], ring[(r + 2) % 5], ring[(r + 3) % 5], ring[(r + 4) % 5]
        for c in range(w):
            mc = q2[c + 2]
            sa0 = sa1 = sb0 = sb1 = span = zero
            sa0, sb0, span = _tap(q0[c] - mc, a[0], b[0], sa0, sb0, span)
            sa1, sb1, span = _tap(q0[c + 1] - mc, a[1], b[1], sa1, sb1, span)
            sa0, sb0, span = _tap(q0[c + 2] - mc, a[2], b[2], sa0, sb0, span)
            sa1, sb1, span = _tap(q0[c + 3] - mc, a[3], b[3], sa1, sb1, span)
            sa0, sb0, span = _tap(q0[c + 4] - mc, a[4], b[4], sa0, sb0, span)
            sa1, sb1, span = _tap(q1[c] - mc, a[5], b[5], sa1, sb1, span)
            sa0, sb0, span = _tap(q1[c + 1] - mc, a[6], b[6], sa0, sb0, span)
            sa1, sb1, span = _tap(q1[c + 2] - mc, a[7], b[7], sa1, sb1, span)
            sa0, sb0, span = _tap(q1[c + 3] - mc, a[8], b[8], sa0, sb0, span)
            sa1, sb1, span = _tap(q1[c + 4] - mc, a[9], b[9], sa1, sb1, span)
            sa0, sb0, span = _tap(q2[c] - mc, a[10], b[10], sa0, sb0, span)
            sa1, sb1, span = _tap(q2[c + 1] - mc, a[11], b[11], sa1, sb1, span)
            sa0, sb0, span = _tap(q2[c + 3] - mc, a[12], b[12], sa0, sb0, span)
            sa1, sb1, span = _tap(q2[c + 4] - mc, a[13], b[13], sa1, sb1, span)
            sa0, sb0, span = _tap(q3[c] - mc, a[14], b[14], sa0, sb0, span)
            sa1, sb1, span = _tap(q3[c + 1] - mc, a[15], b[15], sa1, sb1, span)
            sa0, sb0, span = _tap(q3[c + 2] - mc, a[16], b[16], sa0, sb0, span)
            sa1, sb1, span = _tap(q3[c + 3] - mc, a[17], b[17], sa1, sb1, span)
            sa0, sb0, span = _tap(q3[c + 4] - mc, a[18], b[18], sa0, sb0, span)
            sa1, sb1, span = _tap(q4[c] - mc, a[19], b[19], sa1, sb1, span)
            sa0, sb0, span = _tap(q4[c + 1] - mc, a[20], b[20], sa0, sb0, span)
            sa1, sb1, span = _tap(q4[c + 2] - mc, a[21], b[21], sa1, sb1, span)
            sa0, sb0, span = _tap(q4[c + 3] - mc, a[22], b[22], sa0, sb0, span)
            sa1, sb1, span = _tap(q4[c + 4] - mc, a[23], b[23], sa1, sb1, span)
            moved[c] = mc + (np.floor((sa0 + sa1) * scale_a) if span < cut else np.floor((sb0 + sb1) * scale_b))
            inside[c] = span < lim
        e, o, mo, po, m_in, p_in = est[r], other[r], m64c[r], p[r], m64[r], pred[r]
        for c in range(w):
            m = moved[c]
            keep = inside[c] and not o[c]
            mo[c] = np.int32(m) if keep else m_in[c]
            po[c] = np.int32(np.floor((m + np.float32(e[c]) + half) * sixty_fourth)) if keep else p_in[c]
        if measure and r % 2 == 0:
            row_before, row_after = row_costs(f[r], p_in, po, o)
            before += row_before
            after += row_after
    return before, after


def _solve(x: np.ndarray, n: int, bound: int) -> tuple[np.ndarray, int] | None:
    """One filter's coefficients as int8 and their precision, fitted to ``x``'s first ``n``
    samples (each below ``bound``); ``None`` where they are too few or too flat to fit 24 numbers."""
    if n < 4 * TAPS.shape[0]:
        return None
    g, b = _normal_equations(x, n, _block_for(bound))
    diag = g.diagonal()
    if not np.all(diag > 0):
        return None
    scale = np.sqrt(diag)
    try:  # scaled to a unit diagonal, so a flat direction shows as a small pivot, not a small number
        c = np.linalg.solve(g / np.outer(scale, scale), b / scale) / scale
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(c)):
        return None
    precision = next((q for q in reversed(PRECISIONS) if np.abs(np.rint(c * 2.0 ** q)).max() <= 127), PRECISIONS[0])
    return np.clip(np.rint(c * 2.0 ** precision), -127, 127).astype(np.int8), precision


def fit(f: np.ndarray, pred: np.ndarray, m64: np.ndarray, est: np.ndarray,
        other: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int] | None:
    """The encoder's side: ``(coefficients (2, 24) int8, precisions (2,), prediction, scene
    mean, cost before, cost after)`` with both filters fitted to ``f`` by least squares and
    applied, each cost the sum of ``|f - p|`` on every other row and column (``pred``'s, the
    filtered one's); ``None`` where the frame is too small or too flat to fit either. A filter
    that cannot be fitted is all zeros (it changes nothing)."""
    h, w = f.shape
    if h < 5 or w < 5:
        return None
    rows = ((h - 4 + _ROW_STEP - 1) // _ROW_STEP) * ((w - 4 + _COL_STEP - 1) // _COL_STEP)
    flat, detail = np.empty((TAPS.shape[0] + 1, rows), np.int16), np.empty((TAPS.shape[0] + 1, rows), np.int16)
    nf, nd = _samples(f, m64, est, other, FILTER_SPLIT, FILTER_LIMIT, _CLIP, flat, detail)
    coefs = np.zeros((FILTERS, TAPS.shape[0]), np.int8)
    precisions = np.full(FILTERS, PRECISIONS[0], np.int64)
    for i, (x, n, bound) in enumerate(((flat, nf, max(FILTER_SPLIT, _CLIP)),
                                           (detail, nd, max(FILTER_LIMIT, _CLIP)))):
        solved = _solve(x, n, bound)
        if solved is not None:
            coefs[i], precisions[i] = solved
    if not coefs.any():
        return None
    p, m64c = np.empty_like(pred), np.empty_like(m64)
    before, after = filter_apply(f, m64, est, other, pred, coefs, precisions, FILTER_SPLIT, FILTER_LIMIT, True, p,
                                 m64c)
    return coefs, precisions, p, m64c, before, after
