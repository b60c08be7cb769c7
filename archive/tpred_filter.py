"""tpred version 8's prediction filter: a 5x5 filter on the scene mean, fitted to each frame.

A camera that shakes moves each frame by a random fraction of a pixel. Version 6 moves the
window's mean by a first-order shift and weighs its Laplacian, three numbers; a bilinear move
also blurs the picture by an amount that depends on the fraction, and the mean of frames at other
fractions is blurred differently, which no shift and no single Laplacian follow. A 5x5 filter
fitted by least squares to each frame follows both: its residual's entropy on the simulator's
0.5 px shake is 2.9 % below version 6's three terms (3x3: 1.9 %, 7x7: 2.7 %; measured on 60
frames, 2026-12-06).

Specified in ``archive.temporal``'s docstring (version 8). The decoder's step
(``filter_apply``) is integer arithmetic; the encoder's fit (``fit``) gathers exact integer
sums in float64 (each product below 2**24, each sum below 2**53, so any order gives the same
numbers) and solves a 24x24 system, which only decides the coefficients the record carries.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["FILTER_LIMIT", "PRECISIONS", "TAPS", "filter_apply", "fit"]

#: The 24 neighbours of a 5x5 filter, (dy, dx) in row-major order without the centre: the order
#: of the coefficients in a record.
TAPS = np.asarray([(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if dy or dx], np.int64)
#: A pixel whose neighbours differ from it by this much or more in the scene mean (64 counts, in
#: 1/64 counts) sits on an edge no small move follows linearly, or beside a defect: left as it is.
FILTER_LIMIT = 64 << 6
#: The coefficients are int8 in units of ``2**-precision``, the finest of these in which every
#: one fits: 1/64 had cost 0.2 % on a shaking pan against 1/256 or 1/512.
PRECISIONS = range(4, 10)
_CLIP = 8 << 6  # residuals the fit leaves out: something moving on its own
_ROW_STEP, _COL_STEP = 2, 7  # the fit's pixels: 24 numbers fit on 1/14 of them as well as on 1/4 (0.05 %)


@numba.njit(cache=True, nogil=True)
def _samples(f: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray, taps: np.ndarray, limit: int,
             clip: int, x: np.ndarray) -> int:  # pragma: no cover
    """The fit's rows into ``x`` (taps + 1 columns, the last the residual ``64 f - m64 - est``)
    at the sampled scene pixels whose neighbours stay within ``limit`` and residual within
    ``clip``; returns how many."""
    h, w = f.shape
    k = taps.shape[0]
    n = 0
    for r in range(2, h - 2, _ROW_STEP):
        for c in range(2, w - 2, _COL_STEP):
            if other[r, c]:
                continue
            mm = np.int64(m64[r, c])
            res = (np.int64(f[r, c]) << 6) - mm - est[r, c]
            if abs(res) >= clip:
                continue
            ok = True
            for t in range(k):
                d = np.int64(m64[r + taps[t, 0], c + taps[t, 1]]) - mm
                if abs(d) >= limit:
                    ok = False
                    break
                x[n, t] = d
            if ok:
                x[n, k] = res
                n += 1
    return n


@numba.njit(cache=True, nogil=True, fastmath=True)
def _normal_equations(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """``X^T X`` and ``X^T y`` over the first ``n`` rows. Every product is an integer below
    2**24 and every sum below 2**53, so each is exact in float64 in any order: ``fastmath`` may
    reorder the sums (and vectorise them) without changing a bit."""
    k = x.shape[1] - 1
    cols = np.ascontiguousarray(x[:n].T)
    g = np.empty((k, k))
    b = np.empty(k)
    for i in range(k):
        for j in range(i, k):
            s = 0.0
            for q in range(n):
                s += cols[i, q] * cols[j, q]
            g[i, j] = s
            g[j, i] = s
        s = 0.0
        for q in range(n):
            s += cols[i, q] * cols[k, q]
        b[i] = s
    return g, b


@numba.njit(cache=True, nogil=True, boundscheck=False)
def filter_apply(f: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray, pred: np.ndarray,
                 coefs: np.ndarray, precision: int, limit: int, measure: bool, p: np.ndarray,
                 m64c: np.ndarray) -> tuple[int, int]:  # pragma: no cover
    """Version 8's filtered scene mean and prediction: at each pixel two or more from the edge,
    not in ``other``, whose 24 neighbours in ``m64`` (``TAPS``) all differ from it by less than
    ``limit``, ``m64c = m64 + (sum(coefs[k] * (m64[r + dy_k, c + dx_k] - m64[r, c])) >> precision)`` and
    ``p = (m64c + est + 32) >> 6``; every other pixel keeps ``m64`` and ``pred``. ``measure``
    (the encoder): also the sums of ``|f - pred|`` and ``|f - p|`` over the scene's pixels on
    every other row and column.

    In float32, which is exact here and vectorises where numba's integers (widened to int64)
    do not: every value is an integer below 2**24 (a count in 1/64 is below 2**22; a term's
    product below 2**12 * 2**7, 24 of them below 2**24), a pixel whose sum could be larger is one
    the limit leaves as it is, and the scaling by ``2**-precision`` is exact. Each row reads
    five row views from column 0, so the indices are never negative and the loop has no
    wraparound branch (4-7 times faster)."""
    h, w = m64.shape
    m64c[:, :] = m64
    p[:, :] = pred
    mf = m64.astype(np.float32)
    k = coefs.astype(np.float32)
    lim = np.float32(limit)
    scale = np.float32(2.0 ** -precision)
    sixty_fourth = np.float32(1.0 / 64.0)
    half = np.float32(32.0)
    moved = np.empty(max(w - 4, 0), np.float32)  # a frame under 5x5 has no pixel two from every edge
    inside = np.empty(max(w - 4, 0), np.bool_)
    for r in range(2, h - 2):
        q0, q1, q2, q3, q4 = mf[r - 2], mf[r - 1], mf[r], mf[r + 1], mf[r + 2]
        for c in range(w - 4):
            mc = q2[c + 2]
            acc = (k[0] * (q0[c] - mc) + k[1] * (q0[c + 1] - mc) + k[2] * (q0[c + 2] - mc)
                   + k[3] * (q0[c + 3] - mc) + k[4] * (q0[c + 4] - mc)
                   + k[5] * (q1[c] - mc) + k[6] * (q1[c + 1] - mc) + k[7] * (q1[c + 2] - mc)
                   + k[8] * (q1[c + 3] - mc) + k[9] * (q1[c + 4] - mc)
                   + k[10] * (q2[c] - mc) + k[11] * (q2[c + 1] - mc)
                   + k[12] * (q2[c + 3] - mc) + k[13] * (q2[c + 4] - mc)
                   + k[14] * (q3[c] - mc) + k[15] * (q3[c + 1] - mc) + k[16] * (q3[c + 2] - mc)
                   + k[17] * (q3[c + 3] - mc) + k[18] * (q3[c + 4] - mc)
                   + k[19] * (q4[c] - mc) + k[20] * (q4[c + 1] - mc) + k[21] * (q4[c + 2] - mc)
                   + k[22] * (q4[c + 3] - mc) + k[23] * (q4[c + 4] - mc))
            hi = max(q0[c], q0[c + 1], q0[c + 2], q0[c + 3], q0[c + 4], q1[c], q1[c + 1], q1[c + 2], q1[c + 3],
                     q1[c + 4], q2[c], q2[c + 1], q2[c + 3], q2[c + 4], q3[c], q3[c + 1], q3[c + 2], q3[c + 3],
                     q3[c + 4], q4[c], q4[c + 1], q4[c + 2], q4[c + 3], q4[c + 4])
            lo = min(q0[c], q0[c + 1], q0[c + 2], q0[c + 3], q0[c + 4], q1[c], q1[c + 1], q1[c + 2], q1[c + 3],
                     q1[c + 4], q2[c], q2[c + 1], q2[c + 3], q2[c + 4], q3[c], q3[c + 1], q3[c + 2], q3[c + 3],
                     q3[c + 4], q4[c], q4[c + 1], q4[c + 2], q4[c + 3], q4[c + 4])
            moved[c] = mc + np.floor(acc * scale)
            inside[c] = (hi - mc < lim) & (mc - lo < lim)
        e, o, mo, po = est[r, 2:w - 2], other[r, 2:w - 2], m64c[r, 2:w - 2], p[r, 2:w - 2]
        for c in range(w - 4):  # few pixels fail: a branch here costs less than selecting every one
            if inside[c] and not o[c]:
                m = moved[c]
                mo[c] = np.int32(m)
                po[c] = np.int32(np.floor((m + np.float32(e[c]) + half) * sixty_fourth))
    before = 0
    after = 0
    if measure:
        for r in range(0, h, 2):
            for c in range(0, w, 2):
                if not other[r, c]:
                    before += abs(np.int64(f[r, c]) - pred[r, c])
                    after += abs(np.int64(f[r, c]) - p[r, c])
    return before, after


def fit(f: np.ndarray, pred: np.ndarray, m64: np.ndarray, est: np.ndarray,
        other: np.ndarray) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, int, int] | None:
    """The encoder's side: ``(coefficients as int8, their precision, prediction, scene mean, cost
    before, cost after)`` with the filter fitted to ``f`` by least squares and applied, each cost the sum of
    ``|f - p|`` on every other row and column (``pred``'s, the filtered one's); ``None`` where the
    frame is too small or too flat to fit 24 numbers."""
    h, w = f.shape
    if h < 5 or w < 5:
        return None
    rows = ((h - 4 + _ROW_STEP - 1) // _ROW_STEP) * ((w - 4 + _COL_STEP - 1) // _COL_STEP)
    x = np.empty((rows, TAPS.shape[0] + 1))
    n = _samples(f, m64, est, other, TAPS, FILTER_LIMIT, _CLIP, x)
    if n < 4 * TAPS.shape[0]:
        return None
    g, b = _normal_equations(x, n)
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
    coefs = np.clip(np.rint(c * 2.0 ** precision), -127, 127).astype(np.int8)
    if not coefs.any():
        return None
    p, m64c = np.empty_like(pred), np.empty_like(m64)
    before, after = filter_apply(f, m64, est, other, pred, coefs, precision, FILTER_LIMIT, True, p, m64c)
    return coefs, precision, p, m64c, before, after
