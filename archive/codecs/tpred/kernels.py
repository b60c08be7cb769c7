"""tpred version 4's per-pixel steps, each one pass over the frame, compiled by numba (nogil).

Versions 1-3 run the same arithmetic as a dozen numpy calls a step, each a pass over the frame
and each holding the GIL between calls, which kept the encoder near 60 frames a second on one
core. These loops do exactly what ``archive.codecs.tpred.codec``'s docstring specifies for version 4 (a
first v4 written by numpy steps decoded bit-exact through them, and the block-mode passes serve
version 3 too, whose golden records still decode); integer arithmetic throughout, except
float64 divisions whose results are exact on every machine.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

__all__ = ["apply_modes", "block_choices", "block_sads", "column_medians", "count_runs", "learn_and_push",
           "line_shift_costs", "merge_residuals", "motion_sums", "predict", "residual_costs", "row_costs",
           "sampled_lines", "shift_costs", "split_residuals", "subpel_apply", "subpel_costs", "subpel_sums", "trim"]

_CLIP = 512  # the pattern's clip, 8 counts in 1/64 counts (archive.codecs.tpred.codec._Pattern.CLIP)
_HALF = 32
_SCALE = 6


@numba.njit(cache=True, nogil=True)
def predict(s: np.ndarray, n: np.ndarray, r0: int, c0: int, last: np.ndarray, dx: int, dy: int, est: np.ndarray,
            prev: np.ndarray, defects: np.ndarray, p: np.ndarray, m64: np.ndarray,
            other: np.ndarray) -> None:  # pragma: no cover
    """The scene mean ``m64`` (``S / N`` truncated, or ``last`` moved where no frame saw the
    point), the prediction ``p`` (``(m64 + est + 32) >> 6``, or a defect's own previous value)
    and ``other`` (unseen or defect), where ``S`` and ``N`` are the window's canvases ``s`` and
    ``n`` from row ``r0`` and column ``c0``. The main pass has no branch, so it vectorises; the
    unseen points and the defects (few) are patched after. The canvases come whole with the
    frame's offset, not as the frame's slice of them: numba compiles a 2-D slice for any strides,
    and a pass over its rows then went a pixel at a time (0.92 against 0.35 ms a 640x512 frame);
    ``s[r0 + r, c0:c0 + w]`` is a contiguous row."""
    h, w = p.shape
    unseen = 0
    for r in range(h):
        sr, nr = s[r0 + r, c0:c0 + w], n[r0 + r, c0:c0 + w]
        er, pr, mr, orow = est[r], p[r], m64[r], other[r]
        for c in range(w):
            nn = nr[c]
            m = np.int32(sr[c] / max(nn, 1))  # |S| < 2**31: the quotient fits, truncated as int64's would be
            mr[c] = m
            # (m + est + 32) >> 6 in float64, exact: AVX2 converts float64 to int32 and has no
            # arithmetic shift of 64-bit lanes, so int64 steps here ran a pixel at a time
            pr[c] = np.int32(np.floor((np.float64(m) + np.float64(er[c]) + _HALF) * (1.0 / (1 << _SCALE))))
            orow[c] = nn == 0
            unseen += nn == 0
    if unseen:
        for r in range(h):
            rr = min(max(r - dy, 0), h - 1)
            for c in range(w):
                if n[r0 + r, c0 + c] == 0:
                    moved = np.int64(last[rr, min(max(c - dx, 0), w - 1)])
                    m64[r, c] = moved
                    p[r, c] = (moved + est[r, c] + _HALF) >> _SCALE
    for i in range(defects.size):
        r = defects[i] // w
        c = defects[i] % w
        p[r, c] = prev[r, c]
        other[r, c] = True


@numba.njit(cache=True, nogil=True, inline="always")
def _terms(up: np.ndarray, row: np.ndarray, down: np.ndarray, c: int) -> tuple[Any, Any, Any, Any]:  # pragma: no cover
    """Version 6's terms of the scene mean at column ``c`` of ``row`` (not on the frame's edge),
    in float32: the mean, its central differences halved and its four-neighbour Laplacian
    quartered (floor each, the integer shift's rounding). Exact wherever a term can count: a
    mean in 1/64 counts is within 2**22 (plus the pattern's 8 counts), so a difference, its
    half and a Laplacian's numerator below 2**24 are integers float32 holds; only a numerator
    past 2**24 (a saturated pixel among zeros) can round, and its quarter is then 2**22, far
    beyond the limit every use compares it with. Float32 vectorises eight pixels at a time where
    numba's int64 (and AVX2's lack of an arithmetic shift of 64-bit lanes) did not."""
    mm = np.float32(row[c])
    left, right = np.float32(row[c - 1]), np.float32(row[c + 1])
    u, d = np.float32(up[c]), np.float32(down[c])
    gx = np.floor((right - left) * np.float32(0.5))
    gy = np.floor((d - u) * np.float32(0.5))
    lap = np.floor((np.float32(4) * mm - left - right - u - d) * np.float32(0.25))
    return mm, gx, gy, lap


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def subpel_sums(f: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray, limit: int,
                clip: int) -> np.ndarray:  # pragma: no cover
    """The encoder's least-squares sums for version 6's correction, on every other row and
    column (a quarter of the pixels fit three numbers as well as all of them): over the scene's
    pixels whose three terms stay within ``limit`` and whose residual ``64 f - m64 - est`` within
    ``clip``, the normal equations' matrix (3x3) and right-hand side (the fourth column).
    Exact: the terms and the residual are float32 integers (``_terms``), each product of two
    kept ones is below 2**24 (limit 2**12, clip 2**9), and every sum an integer below 2**53 in
    float64, the same in any order (``reassoc``). Branch-free."""
    h, w = f.shape
    xx = xy = xl = yy = yl = ll = xr = yr = lr = np.float64(0)
    lim, cap = np.float32(limit), np.float32(clip)
    for r in range(1, h - 1, 2):
        up, row, down, fr, er, o = m64[r - 1], m64[r], m64[r + 1], f[r], est[r], other[r]
        for c in range(1, w - 1, 2):
            mm, gx, gy, lap = _terms(up, row, down, c)
            res = np.float32(fr[c] << _SCALE) - mm - np.float32(er[c])
            keep = np.float32(not o[c] and abs(gx) < lim and abs(gy) < lim and abs(lap) < lim and abs(res) < cap)
            gx *= keep
            gy *= keep
            lap *= keep
            xx += np.float64(gx * gx)
            xy += np.float64(gx * gy)
            xl += np.float64(gx * lap)
            yy += np.float64(gy * gy)
            yl += np.float64(gy * lap)
            ll += np.float64(lap * lap)
            xr += np.float64(gx * res)
            yr += np.float64(gy * res)
            lr += np.float64(lap * res)
    out = np.empty((3, 4))
    out[0, 0], out[0, 1], out[0, 2], out[0, 3] = xx, xy, xl, xr
    out[1, 0], out[1, 1], out[1, 2], out[1, 3] = xy, yy, yl, yr
    out[2, 0], out[2, 1], out[2, 2], out[2, 3] = xl, yl, ll, lr
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _corrected_mean(up: np.ndarray, row: np.ndarray, down: np.ndarray, c: int, fx: Any, fy: Any, fl: Any,
                    lim: Any) -> Any:  # pragma: no cover
    """Version 6's corrected scene mean at column ``c`` of ``row`` (not on the frame's edge), in
    float32: ``mm + ((sx gx + sy gy + sl lap) >> 4)`` where the three terms (``_terms``) stay
    within the limit, else ``mm``. Exact: a kept correction's sum is below 2**18, and its
    division by 16 and ``floor`` are the integer shift."""
    mm, gx, gy, lap = _terms(up, row, down, c)
    ok = abs(gx) < lim and abs(gy) < lim and abs(lap) < lim
    return mm + (np.floor((fx * gx + fy * gy + fl * lap) * np.float32(1 / 16)) if ok else np.float32(0))


@numba.njit(cache=True, nogil=True, inline="always")
def _predicted(m: Any, e: Any) -> Any:  # pragma: no cover
    """``(m + e + 32) >> 6`` for a float32 mean ``m`` (exact, as in ``_corrected_mean``)."""
    return np.int32(np.floor((m + np.float32(e) + np.float32(_HALF)) * np.float32(1 / 64)))


@numba.njit(cache=True, nogil=True)
def subpel_costs(f: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray, pred: np.ndarray, sx: int,
                 sy: int, sl: int, limit: int) -> tuple[Any, Any]:  # pragma: no cover
    """``subpel_apply``'s two costs without the corrected frame: the prediction is worked out
    only on the rows the costs read (every other one), half the pass, and written nowhere. The
    encoder measures the correction on every shaking frame and version 8's filters then replace
    it on most of them; it writes the whole corrected frame only where the record keeps it. A
    row at a time, every column (which vectorises, where every other column did not), then
    ``row_costs`` on its even columns."""
    h, w = m64.shape
    before = np.int64(0)
    after = np.int64(0)
    fx, fy, fl, lim = np.float32(sx), np.float32(sy), np.float32(sl), np.float32(limit)
    made = np.empty(w, pred.dtype)
    for r in range(0, h, 2):
        fr, given, o = f[r], pred[r], other[r]
        if r == 0 or r == h - 1:  # the frame's edge has no terms: it keeps pred
            b, a = row_costs(fr, given, given, o)
        else:
            up, row, down, er = m64[r - 1], m64[r], m64[r + 1], est[r]
            made[0] = given[0]
            made[w - 1] = given[w - 1]
            for c in range(1, w - 1):
                made[c] = _predicted(_corrected_mean(up, row, down, c, fx, fy, fl, lim), er[c])
            b, a = row_costs(fr, given, made, o)
        before += b
        after += a
    return before, after


@numba.njit(cache=True, nogil=True)
def subpel_apply(f: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray, pred: np.ndarray, sx: int,
                 sy: int, sl: int, limit: int, measure: bool, p: np.ndarray,
                 m64c: np.ndarray) -> tuple[int, int]:  # pragma: no cover
    """Version 6's corrected scene mean and prediction: at the scene's pixels whose three terms
    stay within ``limit``, ``m64c = m64 + ((sx gx + sy gy + sl lap) >> 4)`` (``m64`` elsewhere)
    and ``p = (m64c + est + 32) >> 6``; the other pixels keep ``pred`` (``p`` may be ``pred``).
    ``measure`` (the encoder): also the sums of ``|f - pred|`` and ``|f - p|`` over the scene's
    pixels on every other row and column. The frame's edge has no terms, so it keeps ``pred``
    and ``m64`` as they are; the inside is one branch-free pass in float32
    (``_corrected_mean``), which vectorises."""
    h, w = m64.shape
    fx, fy, fl, lim = np.float32(sx), np.float32(sy), np.float32(sl), np.float32(limit)
    means = np.empty(w, np.float32)
    for r in range(h):
        row, given, mo, po = m64[r], pred[r], m64c[r], p[r]
        if r == 0 or r == h - 1:
            for c in range(w):
                mo[c] = row[c]
                po[c] = given[c]
            continue
        up, down, er, o = m64[r - 1], m64[r + 1], est[r], other[r]
        # three passes over the row, each with few arrays: one pass that read six rows and wrote
        # two needed more runtime checks that they do not overlap than the vectoriser makes
        means[0], means[w - 1] = row[0], row[w - 1]
        for c in range(1, w - 1):
            means[c] = _corrected_mean(up, row, down, c, fx, fy, fl, lim)
        for c in range(w):
            mo[c] = np.int32(means[c])
        po[0], po[w - 1] = given[0], given[w - 1]
        for c in range(1, w - 1):
            po[c] = given[c] if o[c] else _predicted(means[c], er[c])
    return residual_costs(f, pred, p, other) if measure else (0, 0)


@numba.njit(cache=True, nogil=True, inline="always")
def row_costs(fr: np.ndarray, given: np.ndarray, made: np.ndarray,
              o: np.ndarray) -> tuple[Any, Any]:  # pragma: no cover
    """One row's share of ``residual_costs``: ``|f - pred|`` and ``|f - p|`` summed over the
    scene's pixels in every other column. Without a branch (the pixels in ``o`` count naught),
    so it vectorises: 0.08 against 0.20 ms a 640x512 frame with one."""
    before = 0
    after = 0
    for c in range(0, fr.shape[0], 2):
        scene = np.int64(not o[c])
        before += abs(np.int64(fr[c]) - given[c]) * scene
        after += abs(np.int64(fr[c]) - made[c]) * scene
    return before, after


@numba.njit(cache=True, nogil=True)
def residual_costs(f: np.ndarray, pred: np.ndarray, p: np.ndarray,
                   other: np.ndarray) -> tuple[int, int]:  # pragma: no cover
    """The encoder's measure of a correction: the sums of ``|f - pred|`` and ``|f - p|`` over the
    scene's pixels (not in ``other``) on every other row and column."""
    before = 0
    after = 0
    for r in range(0, f.shape[0], 2):
        b, a = row_costs(f[r], pred[r], p[r], other[r])
        before += b
        after += a
    return before, after


@numba.njit(cache=True, nogil=True)
def split_residuals(f: np.ndarray, p: np.ndarray, other: np.ndarray, scene: np.ndarray,
                    rest: np.ndarray) -> tuple[int, int, int, int]:  # pragma: no cover
    """``f - p`` in raster order, the scene's pixels into ``scene`` and the others into ``rest``;
    returns both counts and the residuals' least and greatest value. In int32 (a count less a
    prediction within 2**17 of the counts' range). A row's residuals and its count of others are
    two passes that vectorise; a row with none (most of a still view) goes to ``scene`` whole,
    and a row whose others lie at its ends (the edge a pan uncovers, every row of a moving view)
    in three copies. Only a row with others inside it is sorted a pixel at a time: 0.45 -> 0.21 ms
    a 640x512 frame, against a branch a pixel on every row (2026-12-07)."""
    h, w = f.shape
    i0 = 0
    i1 = 0
    lo = np.int32(2**31 - 1)
    hi = np.int32(-2**31)
    row = np.empty(w, np.int32)
    for r in range(h):
        fr, pr, orow = f[r], p[r], other[r]
        for c in range(w):
            v = np.int32(np.int32(fr[c]) - pr[c])
            row[c] = v
            lo = min(lo, v)
            hi = max(hi, v)
        n_other = np.int32(0)
        for c in range(w):
            n_other = np.int32(n_other + np.int32(orow[c]))
        if n_other == 0:
            scene[i0:i0 + w] = row
            i0 += w
            continue
        lead = 0
        while lead < w and orow[lead]:
            lead += 1
        trail = 0
        while trail < w - lead and orow[w - 1 - trail]:
            trail += 1
        if lead + trail == n_other:
            rest[i1:i1 + lead] = row[:lead]
            i1 += lead
            inner = w - lead - trail
            scene[i0:i0 + inner] = row[lead:w - trail]
            i0 += inner
            rest[i1:i1 + trail] = row[w - trail:]
            i1 += trail
        else:
            for c in range(w):
                if orow[c]:
                    rest[i1] = row[c]
                    i1 += 1
                else:
                    scene[i0] = row[c]
                    i0 += 1
    return i0, i1, int(lo), int(hi)


@numba.njit(cache=True, nogil=True)
def merge_residuals(p: np.ndarray, other: np.ndarray, scene: np.ndarray, rest: np.ndarray,
                    f: np.ndarray) -> int:  # pragma: no cover
    """The decoder's side of ``split_residuals``: ``f = p + residual``. Returns 0, or -1 if the
    streams do not hold one value a pixel, -2 if a pixel leaves uint16."""
    h, w = p.shape
    i0 = 0
    i1 = 0
    for r in range(h):
        for c in range(w):
            if other[r, c]:
                if i1 >= rest.size:
                    return -1
                v = p[r, c] + np.int64(rest[i1])
                i1 += 1
            else:
                if i0 >= scene.size:
                    return -1
                v = p[r, c] + np.int64(scene[i0])
                i0 += 1
            if v < 0 or v > 65535:
                return -2
            f[r, c] = v
    if i0 != scene.size or i1 != rest.size:
        return -1
    return 0


@numba.njit(cache=True, nogil=True)
def learn_and_push(f: np.ndarray, m64: np.ndarray, other: np.ndarray, defect: np.ndarray, pixsum: np.ndarray,
                   colsum: np.ndarray, colcnt: np.ndarray, n: int, shrink: int, est: np.ndarray,
                   wsum: np.ndarray, wcount: np.ndarray, r0: int, c0: int, weight: np.ndarray, use_weight: bool,
                   kept: np.ndarray) -> None:  # pragma: no cover
    """The pattern learns frame ``f``'s residual against the scene (``n`` frames learned, this
    one included) and ``est`` becomes the new estimate; then ``64 f - est`` (0 at a defect)
    goes into ``kept`` and onto the window's canvases ``wsum``/``wcount`` from row ``r0`` and
    column ``c0`` (whole, as ``predict`` takes them). Branch-free passes (the masks select), so
    they vectorise."""
    h, w = f.shape
    for r in range(h):
        fr, mr, orow, sums = f[r], m64[r], other[r], pixsum[r]
        for c in range(w):
            keep = not orow[c]
            e = (np.int64(fr[c]) << _SCALE) - mr[c]
            e = min(max(e, -_CLIP), _CLIP) if keep else np.int64(0)
            sums[c] += e
            colsum[c] += e
            colcnt[c] += keep
    col = np.zeros(w, np.int64)
    col_f = np.zeros(w)  # col and n * col in float64 (exact), so the pixel pass converts int32 alone
    col_n = np.zeros(w)
    for c in range(w):
        if colcnt[c] > 0:
            col[c] = (colsum[c] + colcnt[c] // 2) // colcnt[c]
        col_f[c] = np.float64(col[c])
        col_n[c] = np.float64(n * col[c])
    # floor division by n + shrink, in float64: exact while |numerator| < 2**53 (a quotient that
    # is not an integer is at least 1/div from one, beyond float64's rounding there), and a
    # pipelined division where an int64 one takes ~40 cycles a pixel. The estimate fits int32
    # (the pattern's array), and AVX2 converts float64 to int32 eight lanes at a time, not int64
    div = np.float64(n + shrink)
    for r in range(h):
        fr, sums, er, kr, dr, wr = f[r], pixsum[r], est[r], kept[r], defect[r], weight[r]
        ws, wc = wsum[r0 + r, c0:c0 + w], wcount[r0 + r, c0:c0 + w]
        for c in range(w):
            x = np.int32(np.floor((np.float64(sums[c]) - col_n[c]) / div) + col_f[c])
            er[c] = x
            v = np.int32(0) if dr[c] else np.int32((fr[c] << _SCALE) - x)
            kr[c] = v
            ws[c] += v
            wc[c] += wr[c] if use_weight else 1


@numba.njit(cache=True, nogil=True)
def trim(wsum: np.ndarray, wcount: np.ndarray, r0: int, c0: int, old: np.ndarray, weight: np.ndarray,
         use_weight: bool) -> None:  # pragma: no cover
    """A frame leaves the window: its values and counts off the canvases from row ``r0`` and
    column ``c0`` (whole, as ``predict`` takes them)."""
    h, w = old.shape
    for r in range(h):
        ws, wc, orow, wr = wsum[r0 + r, c0:c0 + w], wcount[r0 + r, c0:c0 + w], old[r], weight[r]
        for c in range(w):
            ws[c] -= orow[c]
            wc[c] -= wr[c] if use_weight else 1


@numba.njit(cache=True, nogil=True)
def count_runs(f: np.ndarray, last: np.ndarray, run: np.ndarray) -> None:  # pragma: no cover
    """Each pixel's run of frames unchanged, in place: one more where ``f`` equals ``last``
    (held at 255), else naught. One pass, where numpy's four took 0.27 ms a 640x512 frame."""
    h, w = f.shape
    for r in range(h):
        fr, lr, rr = f[r], last[r], run[r]
        for c in range(w):
            rr[c] = (min(rr[c], 254) + 1) * (fr[c] == lr[c])


@numba.njit(cache=True, nogil=True)
def sampled_lines(f: np.ndarray, axis: int, step: int, other: int) -> np.ndarray:  # pragma: no cover
    """Every ``step``-th line of ``f`` across ``axis`` (1: rows, each along the columns; 0:
    columns, each along the rows), the lines taken ``other`` lines back (wrapping), as one
    contiguous array a line a row: ``np.roll(f, other, 1 - axis)`` transposed for ``axis`` 0 and
    sampled, without the roll, the transpose or numpy's strided gather (0.1-0.6 ms)."""
    h, w = f.shape
    if axis == 1:
        out = np.empty(((h + step - 1) // step, w), f.dtype)
        for i in range(out.shape[0]):
            out[i] = f[(i * step - other) % h]
    else:
        out = np.empty(((w + step - 1) // step, h), f.dtype)
        cols = np.empty(out.shape[0], np.int64)  # the columns taken, worked out once, not a division a pixel
        for i in range(out.shape[0]):
            cols[i] = (i * step - other) % w
        for y in range(h):
            row = f[y]
            for i in range(out.shape[0]):
                out[i, y] = row[cols[i]]
    return out


@numba.njit(cache=True, nogil=True)
def motion_sums(f: np.ndarray, prev: np.ndarray, dx: int, dy: int, step: int,
                clip: int) -> tuple[int, int]:  # pragma: no cover
    """The motion search's last check (encoder only), on every ``step``-th row and column: the
    sum of ``min(|f - prev|, clip)`` as it stands and with ``prev`` moved by ``(dx, dy)`` (edge
    replicated). One pass, where numpy's fancy indexing and temporaries took 0.2 ms."""
    h, w = f.shape
    still = moved = 0
    for r in range(0, h, step):
        fr, pr, qr = f[r], prev[r], prev[min(max(r - dy, 0), h - 1)]
        for c in range(0, w, step):
            v = np.int64(fr[c])
            still += min(abs(v - pr[c]), clip)
            moved += min(abs(v - qr[min(max(c - dx, 0), w - 1)]), clip)
    return still, moved


@numba.njit(cache=True, nogil=True)
def column_medians(x: np.ndarray) -> np.ndarray:  # pragma: no cover
    """``np.median(x, axis=0)`` of an integer array, the same float64 numbers: the middle value,
    or the two middle values' mean (exact: their sum is an integer below 2**53). Each column's
    middle value is found by bisection on the values, every column at once: each step counts,
    a row at a time, the values at or below each column's midpoint, a pass over contiguous
    columns that vectorises where a selection a column branches on every value (a count's 16
    steps for uint16 counts)."""
    rows, n = x.shape
    out = np.empty(n)
    if rows == 0 or n == 0:
        out[:] = np.nan
        return out
    k = (rows - 1) // 2  # the k-th smallest (from 0), and the next one up where rows is even
    least, most = np.int64(x.min()), np.int64(x.max())
    lo = np.full(n, least, np.int64)
    hi = np.full(n, most, np.int64)
    mid = np.empty(n, x.dtype)  # between two of x's values: x's type holds it, and compares lane by lane
    count = np.empty(n, np.int32)
    span = most - least
    while span > 0:  # each step halves every column's interval [lo, hi], which holds the k-th
        for c in range(n):
            mid[c] = lo[c] + (hi[c] - lo[c]) // 2
        count[:] = 0
        for r in range(rows):
            xr = x[r]
            for c in range(n):
                count[c] += np.int32(xr[c] <= mid[c])
        for c in range(n):
            if count[c] > k:
                hi[c] = mid[c]
            else:
                lo[c] = mid[c] + 1
        span //= 2
    if rows % 2:
        for c in range(n):
            out[c] = lo[c]
        return out
    # the next value up: the k-th itself where more than k + 1 values are at or below it,
    # else the least value above it
    count[:] = 0
    above = np.full(n, most, np.int64)
    for r in range(rows):
        for c in range(n):
            v = np.int64(x[r, c])
            count[c] += np.int64(v <= lo[c])
            if v > lo[c]:
                above[c] = min(above[c], v)
    for c in range(n):
        high = lo[c] if count[c] > k + 1 else above[c]
        out[c] = (lo[c] + high) / 2
    return out


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def line_shift_costs(x: np.ndarray, y: np.ndarray, shifts: np.ndarray, clip: int) -> np.ndarray:  # pragma: no cover
    """``shift_costs`` for integer lines, the same float64 means: each term (a count's difference,
    at most ``clip``) and a line's sum of them are exact in float32 while a line holds fewer than
    2**24 / ``clip`` pixels, so the terms vectorise eight at a time and add in any order; the lines'
    sums add in float64."""
    rows, n = x.shape
    out = np.empty(shifts.size)
    cap = np.float32(clip)
    for k in range(shifts.size):
        s = shifts[k]
        first, stop = max(s, 0), n + min(s, 0)
        total = np.float64(0)
        for r in range(rows):
            xr, yr = x[r], y[r]
            line = np.float32(0)
            for c in range(first, stop):
                line += min(abs(np.float32(xr[c]) - np.float32(yr[c - s])), cap)
            total += np.float64(line)
        out[k] = total / (rows * (n - abs(s)))
    return out


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def shift_costs(x: np.ndarray, y: np.ndarray, shifts: np.ndarray, clip: float) -> np.ndarray:  # pragma: no cover
    """For each shift ``s`` of ``y`` along the last axis, the mean of ``min(|x - y moved|, clip)``
    over the overlap (the motion search's measure; encoder only). Every term is an integer or a
    half (a median), so every sum is exact and any order of adding gives the same totals: the
    loops add in the order that vectorises."""
    rows, n = x.shape
    out = np.empty(shifts.size)
    for k in range(shifts.size):
        s = shifts[k]
        total = 0.0
        for r in range(rows):
            if s >= 0:
                for c in range(s, n):
                    total += min(abs(x[r, c] - y[r, c - s]), clip)
            else:
                for c in range(0, n + s):
                    total += min(abs(x[r, c] - y[r, c - s]), clip)
        out[k] = total / (rows * (n - abs(s)))
    return out


@numba.njit(cache=True, nogil=True)
def block_sads(f: np.ndarray, pred: np.ndarray, hb: int, wb: int, block: int) -> np.ndarray:  # pragma: no cover
    """Each block's residual on every other row and column, each clipped at 20 (encoder only)."""
    h, w = f.shape
    sad = np.zeros(hb * wb, np.int64)
    for r in range(0, h, 2):
        bi = r // block
        for c in range(0, w, 2):
            sad[bi * wb + c // block] += min(abs(np.int64(f[r, c]) - pred[r, c]), 20)
    return sad


@numba.njit(cache=True, nogil=True, inline="always")
def _block_cost(f: np.ndarray, ref: np.ndarray, r0: int, c0: int, vx: int, vy: int, block: int,
                acc: np.ndarray) -> Any:  # pragma: no cover
    """The sum over a block of ``min(|f - ref moved by (vx, vy)|, 20)`` where the block and its
    moved copy lie inside the frame: no clamping, and in float32 (each term an integer up to 20,
    the sum up to 5,120: exact in any order, which ``reassoc`` lets the sum take), so each row's
    16 pixels vectorise."""
    cap = np.float32(20)
    acc[:] = 0  # a column's sum each: the rows add lane by lane, and one sum at the end
    for i in range(block):
        fr, qr = f[r0 + i, c0:c0 + block], ref[r0 + i - vy, c0 - vx:c0 - vx + block]
        for j in range(block):
            acc[j] += min(abs(np.float32(fr[j]) - np.float32(qr[j])), cap)
    return np.int64(acc.sum())


@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def block_choices(f: np.ndarray, pred: np.ndarray, prev: np.ndarray, cand: np.ndarray, wb: int, block: int,
                  vectors: np.ndarray) -> np.ndarray:  # pragma: no cover
    """For each candidate block, the first vector (1-based) whose moved previous frame beats the
    scene by more than ``2 * block`` (0: none does); pixels of a partial block repeat the
    frame's last row or column, the moved frame is edge replicated (encoder only). A block whose
    pixels and moved pixels all lie inside the frame takes ``_block_cost``, the same sums without
    the clamping (0.34-0.92 ms a frame on the pans before)."""
    h, w = f.shape
    choice = np.zeros(cand.size, np.uint8)
    acc = np.empty(block, np.float32)
    for n in range(cand.size):
        r0 = (cand[n] // wb) * block
        c0 = (cand[n] % wb) * block
        whole = r0 + block <= h and c0 + block <= w
        if whole:
            best = _block_cost(f, pred, r0, c0, 0, 0, block, acc)
        else:
            best = 0
            for i in range(block):
                xr = min(r0 + i, h - 1)
                for j in range(block):
                    xc = min(c0 + j, w - 1)
                    best += min(abs(np.int64(f[xr, xc]) - pred[xr, xc]), 20)
        for k in range(vectors.shape[0]):
            vx = vectors[k, 0]
            vy = vectors[k, 1]
            if whole and r0 - vy >= 0 and r0 + block - vy <= h and c0 - vx >= 0 and c0 + block - vx <= w:
                cost = 2 * block + _block_cost(f, prev, r0, c0, vx, vy, block, acc)
            else:
                cost = 2 * block
                for i in range(block):
                    xr = min(r0 + i, h - 1)
                    qr = min(max(r0 + i - vy, 0), h - 1)
                    for j in range(block):
                        xc = min(c0 + j, w - 1)
                        qc = min(max(c0 + j - vx, 0), w - 1)
                        cost += min(abs(np.int64(f[xr, xc]) - prev[qr, qc]), 20)
            if cost < best:
                best = cost
                choice[n] = k + 1
    return choice


@numba.njit(cache=True, nogil=True)
def apply_modes(modes: np.ndarray, pred: np.ndarray, prev: np.ndarray, other: np.ndarray, block: int,
                vectors: np.ndarray) -> None:  # pragma: no cover
    """Each block with mode ``k`` predicted by ``prev`` moved by ``vectors[k - 1]`` (edge
    replicated) and marked in ``other``, in the block's pixels inside the frame."""
    h, w = pred.shape
    for bi in range(modes.shape[0]):
        for bj in range(modes.shape[1]):
            k = modes[bi, bj]
            if k == 0:
                continue
            vx = vectors[k - 1, 0]
            vy = vectors[k - 1, 1]
            for r in range(bi * block, min(bi * block + block, h)):
                rr = min(max(r - vy, 0), h - 1)
                for c in range(bj * block, min(bj * block + block, w)):
                    pred[r, c] = prev[rr, min(max(c - vx, 0), w - 1)]
                    other[r, c] = True
