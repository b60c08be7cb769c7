"""The detector's compiled passes themselves (numba, no GIL): ``detector_kernels`` holds their
callers and says why each exists.

A module of its own so that importing the detector does not import numba: the recording
process hands its frames to a child process and runs no kernel, and numba's import (0.2-0.45 s)
was part of every ``thermcap record``'s start. ``detector_kernels`` imports this module the
first time a kernel is asked for.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__: list[str] = []


@njit(nogil=True, cache=True)
def _cell_mean_max(padded):  # uint16 [h, w], whole 4x4 cells -> (float32 mean, uint16 max) [h/4, w/4]
    # A cell row's four rows in one contiguous pass (vectorised), then each cell's four
    # columns: 25% less than a pass a row (0.15 against 0.11 ms a 640x512 frame, Zen 4)
    h, w = padded.shape
    ch, cw = h // 4, w // 4
    mean = np.empty((ch, cw), np.float32)
    cmax = np.empty((ch, cw), padded.dtype)
    col_sum = np.empty(w, np.uint32)
    col_max = np.empty(w, padded.dtype)
    s4 = col_sum.reshape(cw, 4)
    m4 = col_max.reshape(cw, 4)
    scale = np.float32(1.0 / 16)
    for cy in range(ch):
        r0, r1, r2, r3 = padded[cy * 4], padded[cy * 4 + 1], padded[cy * 4 + 2], padded[cy * 4 + 3]
        for x in range(w):
            a, b, c, d = r0[x], r1[x], r2[x], r3[x]
            col_sum[x] = np.uint32(a) + np.uint32(b) + np.uint32(c) + np.uint32(d)
            col_max[x] = max(max(a, b), max(c, d))
        mrow, xrow = mean[cy], cmax[cy]
        for cx in range(cw):
            mrow[cx] = np.float32(s4[cx, 0] + s4[cx, 1] + s4[cx, 2] + s4[cx, 3]) * scale
            xrow[cx] = max(max(m4[cx, 0], m4[cx, 1]), max(m4[cx, 2], m4[cx, 3]))
    return mean, cmax

@njit(nogil=True, cache=True)
def _grid_excess(opened, mean, cmax, scale, offset, thr):
    # detector._affine32 of the three grids (the same float32 multiply, then add), each
    # cell's excess over the background and whether it stands thr above it, in one pass:
    # five numpy operations and a count on counts took 55 us of a 640x512 frame
    h, w = opened.shape
    opened_t = np.empty((h, w), np.float32)
    mean_t = np.empty((h, w), np.float32)
    cmax_t = np.empty((h, w), np.float32)
    excess = np.empty((h, w), np.float32)
    cells = np.empty((h, w), np.bool_)
    n = 0
    for y in range(h):
        for x in range(w):
            o = np.float32(opened[y, x]) * scale + offset
            c = np.float32(cmax[y, x]) * scale + offset
            e = c - o
            opened_t[y, x] = o
            mean_t[y, x] = np.float32(mean[y, x]) * scale + offset
            cmax_t[y, x] = c
            excess[y, x] = e
            hit = e >= thr
            cells[y, x] = hit
            n += hit
    return opened_t, mean_t, cmax_t, excess, cells, n

@njit(nogil=True, cache=True, inline="always")
def _extreme(x, y, take_max):  # the max (or min) of two values; a loop's take_max is hoisted out of it
    return max(x, y) if take_max else min(x, y)

@njit(nogil=True, cache=True)
def _extreme_down(a, k, take_max):  # float32 [h, w] -> the max (or min) over k rows, edges repeated
    # van Herk / Gil-Werman: blocks of k padded rows, the running extreme forward within each
    # block (g) and backward (b); the window of k rows from padded row i is op(b[i], g[i + k - 1]).
    # Three comparisons a value whatever k, each a pass over whole rows (vectorised).
    h, w = a.shape
    r = k // 2
    n = h + k - 1
    g = np.empty((n, w), np.float32)
    b = np.empty((n, w), np.float32)
    for j in range(n):
        src, gj = a[min(max(j - r, 0), h - 1)], g[j]
        if j % k == 0:
            for x in range(w):
                gj[x] = src[x]
        else:
            gp = g[j - 1]
            for x in range(w):
                gj[x] = _extreme(gp[x], src[x], take_max)
    for j in range(n - 1, -1, -1):
        src, bj = a[min(max(j - r, 0), h - 1)], b[j]
        if j == n - 1 or (j + 1) % k == 0:
            for x in range(w):
                bj[x] = src[x]
        else:
            bn = b[j + 1]
            for x in range(w):
                bj[x] = _extreme(bn[x], src[x], take_max)
    out = np.empty((h, w), np.float32)
    for i in range(h):
        bi, gi, oi = b[i], g[i + k - 1], out[i]
        for x in range(w):
            oi[x] = _extreme(bi[x], gi[x], take_max)
    return out

@njit(nogil=True, cache=True)
def _opening(a, k):  # float32 [h, w] with no NaN -> the k x k minimum filter, then the maximum filter
    # each separable: the rows' pass, then the columns' as rows of the transpose (and back)
    m = _extreme_down(a, k, False)
    t = np.ascontiguousarray(m.T)
    t = _extreme_down(_extreme_down(t, k, False), k, True)
    return _extreme_down(np.ascontiguousarray(t.T), k, True)

@njit(nogil=True, cache=True)
def _box_mean(a, size):  # float32 [h, w] -> float32: scipy's uniform_filter(size, mode="nearest")
    # scipy's own arithmetic, line by line: a running sum in float64 over the edge-extended
    # line, each output that sum / size cast to float32, axis 0 first into a float32 array.
    # The columns' lines run side by side here (one float64 sum per column) so the loops are
    # contiguous; each column's sum still takes the same values in the same order.
    h, w = a.shape
    s1 = size // 2
    s2 = size - s1 - 1
    n = np.float64(size)
    mid = np.empty((h, w), np.float32)
    col = np.zeros(w, np.float64)
    for k in range(-s1, s2 + 1):
        row = a[min(max(k, 0), h - 1)]
        for x in range(w):
            col[x] += np.float64(row[x])
    for x in range(w):
        mid[0, x] = np.float32(col[x] / n)
    for y in range(1, h):
        add = a[min(y + s2, h - 1)]
        sub = a[max(y - s1 - 1, 0)]
        for x in range(w):
            col[x] += np.float64(add[x]) - np.float64(sub[x])
            mid[y, x] = np.float32(col[x] / n)
    out = np.empty((h, w), np.float32)
    for y in range(h):
        line = mid[y]
        t = 0.0
        for k in range(-s1, s2 + 1):
            t += np.float64(line[min(max(k, 0), w - 1)])
        out[y, 0] = np.float32(t / n)
        for x in range(1, w):
            t += np.float64(line[min(x + s2, w - 1)]) - np.float64(line[max(x - s1 - 1, 0)])
            out[y, x] = np.float32(t / n)
    return out

@njit(nogil=True, cache=True)
def _mend(temps, bad, coords, out):  # float32 [h, w], bad map [h, w], (y, x) [n, 2], a copy to mend
    # detector._fix_bad_pixels's arithmetic: each listed pixel becomes np.median of its good
    # 3x3 neighbours in the frame as it came (float32: the middle one, or the float32 sum of
    # the two middle ones halved; NaN if any is NaN), and stays as it is with none
    h, w = temps.shape
    buf = np.empty(9, temps.dtype)
    half = temps.dtype.type(2.0)
    for i in range(coords.shape[0]):
        y, x = coords[i, 0], coords[i, 1]
        n = 0
        nan = False
        for yy in range(max(0, y - 1), min(h, y + 2)):
            for xx in range(max(0, x - 1), min(w, x + 2)):
                if not bad[yy, xx]:
                    v = temps[yy, xx]
                    nan = nan or v != v
                    buf[n] = v
                    n += 1
        if n == 0:
            continue
        if nan:
            out[y, x] = np.nan
            continue
        for a in range(1, n):  # at most nine values: an insertion sort
            v = buf[a]
            b = a - 1
            while b >= 0 and buf[b] > v:
                buf[b + 1] = buf[b]
                b -= 1
            buf[b + 1] = v
        out[y, x] = buf[n // 2] if n % 2 else (buf[n // 2 - 1] + buf[n // 2]) / half

@njit(nogil=True, cache=True)
def _find(parent, i):
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        parent[i], i = root, parent[i]
    return root

@njit(nogil=True, cache=True, inline="always")
def _number(parent, final, p, n):
    """The final label of provisional label ``p``: its root's, or the next one (``n + 1``)
    when the root has none yet, which numbers the components in the raster order of their
    first pixel, as ``ndimage.label`` does. Returns (label, labels so far, whether new)."""
    root = _find(parent, p)
    k = final[root]
    if k != 0:
        return k, n, False
    final[root] = n + 1
    return n + 1, n + 1, True

@njit(nogil=True, cache=True)
def _region_facts(cells, excess, cmax):
    h, w = cells.shape
    prov = np.zeros((h, w), np.int32)  # provisional labels, 0: not a candidate
    # a cell takes a new label only when none of its earlier 8-neighbours is a candidate, so
    # no two new-label cells touch: at most one per 2x2 block
    parent = np.zeros(((h + 1) // 2) * ((w + 1) // 2) + 1, np.int32)
    n_prov = 0
    for y in range(h):
        for x in range(w):
            if not cells[y, x]:
                continue
            lab = 0
            for dy, dx in ((-1, -1), (-1, 0), (-1, 1), (0, -1)):  # 8-connected, already visited
                yy, xx = y + dy, x + dx
                if yy < 0 or xx < 0 or xx >= w:
                    continue
                other = prov[yy, xx]
                if other == 0:
                    continue
                if lab == 0:
                    lab = _find(parent, other)
                else:
                    a, b = _find(parent, lab), _find(parent, other)
                    if a != b:
                        if a < b:
                            parent[b] = a
                            lab = a
                        else:
                            parent[a] = b
                            lab = b
            if lab == 0:
                n_prov += 1
                parent[n_prov] = n_prov
                lab = n_prov
            prov[y, x] = lab
    final = np.zeros(n_prov + 1, np.int32)  # root -> label, numbered in raster order
    n = 0
    y0 = np.empty(n_prov, np.intp)
    y1 = np.empty(n_prov, np.intp)
    x0 = np.empty(n_prov, np.intp)
    x1 = np.empty(n_prov, np.intp)
    top_excess = np.empty(n_prov, excess.dtype)
    top_cmax = np.empty(n_prov, cmax.dtype)
    for y in range(h):
        for x in range(w):
            p = prov[y, x]
            if p == 0:
                continue
            k, n, new = _number(parent, final, p, n)
            if new:
                y0[k - 1], y1[k - 1], x0[k - 1], x1[k - 1] = y, y + 1, x, x + 1
                top_excess[k - 1], top_cmax[k - 1] = excess[y, x], cmax[y, x]
                continue
            i = k - 1
            y1[i] = y + 1  # rows only grow in a raster scan
            if x < x0[i]:
                x0[i] = x
            if x + 1 > x1[i]:
                x1[i] = x + 1
            if excess[y, x] > top_excess[i]:
                top_excess[i] = excess[y, x]
            if cmax[y, x] > top_cmax[i]:
                top_cmax[i] = cmax[y, x]
    return n, y0[:n], y1[:n], x0[:n], x1[:n], top_excess[:n], top_cmax[:n]


@njit(nogil=True, cache=True)
def _window_components(src, opened, boxes, f, h, w, scale, offset, thr, min_area):
    """Each window (a region's box in cells, clipped to the frame): its candidate pixels
    (``float32(src) * scale + offset - opened >= thr``, float32 throughout, as the detector's
    numpy path computes them), their 4-connected components numbered as ``ndimage.label``
    numbers them, and the components of at least ``min_area`` pixels with their boxes."""
    nw = boxes.shape[0]
    starts = np.zeros(nw + 1, np.intp)  # each window's labels, flat, one after another
    for i in range(nw):
        cy0, cy1, cx0, cx1 = boxes[i, 0], boxes[i, 1], boxes[i, 2], boxes[i, 3]
        starts[i + 1] = starts[i] + (min(h, cy1 * f) - cy0 * f) * (min(w, cx1 * f) - cx0 * f)
    labels = np.zeros(starts[nw], np.int32)
    cap = starts[nw] // 2 + nw + 1  # a window labels at most half its pixels, rounded up (a checkerboard)
    parent = np.zeros(cap, np.int32)
    final = np.zeros(cap, np.int32)
    out_win = np.empty(cap, np.intp)
    out_lab = np.empty(cap, np.int32)
    out_box = np.empty((cap, 4), np.intp)  # window-relative y0, y1, x0, x1
    out_area = np.empty(cap, np.intp)
    kept = 0
    for i in range(nw):
        cy0, cy1, cx0, cx1 = boxes[i, 0], boxes[i, 1], boxes[i, 2], boxes[i, 3]
        y0, x0 = cy0 * f, cx0 * f
        wh, ww = min(h, cy1 * f) - y0, min(w, cx1 * f) - x0
        base = starts[i]
        n_prov = 0
        for y in range(wh):
            for x in range(ww):
                v = np.float32(src[y0 + y, x0 + x]) * scale + offset
                if not (v - opened[cy0 + y // f, cx0 + x // f] >= thr):
                    continue
                up = labels[base + (y - 1) * ww + x] if y > 0 else 0
                left = labels[base + y * ww + x - 1] if x > 0 else 0
                if up == 0 and left == 0:
                    n_prov += 1
                    parent[n_prov] = n_prov
                    lab = n_prov
                elif up == 0 or left == 0:
                    lab = _find(parent, up + left)
                else:
                    a, b = _find(parent, up), _find(parent, left)
                    lab = min(a, b)
                    parent[max(a, b)] = lab
                labels[base + y * ww + x] = lab
        # second pass: final labels in raster order of each component's first pixel
        for k in range(n_prov + 1):
            final[k] = 0
        n = 0
        first = kept
        for y in range(wh):
            for x in range(ww):
                p = labels[base + y * ww + x]
                if p == 0:
                    continue
                k, n, new = _number(parent, final, p, n)
                if new:
                    j = first + k - 1
                    out_win[j], out_lab[j], out_area[j] = i, k, 0
                    out_box[j, 0], out_box[j, 1], out_box[j, 2], out_box[j, 3] = y, y + 1, x, x + 1
                j = first + k - 1
                labels[base + y * ww + x] = k
                out_area[j] += 1
                out_box[j, 1] = y + 1
                if x < out_box[j, 2]:
                    out_box[j, 2] = x
                if x + 1 > out_box[j, 3]:
                    out_box[j, 3] = x + 1
        # keep those of at least min_area, in label order
        for k in range(n):
            j = first + k
            if out_area[j] >= min_area:
                out_win[kept], out_lab[kept], out_area[kept] = out_win[j], out_lab[j], out_area[j]
                for c in range(4):
                    out_box[kept, c] = out_box[j, c]
                kept += 1
    return labels, starts, out_win[:kept], out_lab[:kept], out_box[:kept], out_area[:kept]
