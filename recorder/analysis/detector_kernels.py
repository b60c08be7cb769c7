"""The detector's whole-grid passes compiled (numba, no GIL), used when numba is installed.

On noise (the worst case a file source can feed the detector) a 640x512 frame cost 1.2 ms, and
most of it was numpy and scipy walking the same arrays again and again: the coarse grid's mean
and maximum in twelve strided whole-array operations (0.3 ms), and the candidate regions'
labels, then their cells sorted by label and reduced for boxes and maxima (0.4 ms, a thousand
regions). Here each is one pass. The answers are the plain paths' to the bit
(``tests/unit/recorder/test_detector_fast_paths.py``): the cell sums of uint16 counts are
integers below 2**24, exact in float32 in any order, and the regions are numbered as
``scipy.ndimage.label`` numbers them (by the raster position of their first cell), and the local
mean is scipy's ``uniform_filter`` in scipy's own order of float64 sums.

numba is in the ``archive`` extra, not the base install, so the detector keeps its numpy path
for a recorder installed without it (``available()`` says which runs). The kernels themselves
are in ``detector_jit``, imported by ``available()``: importing the detector imports no numba.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["available", "box_mean", "cell_mean_max", "grid_excess", "mend_bad_pixels", "opening", "region_facts",
           "warm", "window_components"]

_usable: bool | None = None  # None until the kernels were tried once in this process
_jit: Any = None  # detector_jit, imported on the first kernel asked for


def available() -> bool:
    """Whether the compiled passes run here. Tried once, on tiny arrays: a kernel numba cannot
    compile on this machine means the numpy path, never a detector (or a recording) that fails."""
    global _usable, _jit
    if _usable is None:
        try:
            from thermcap.recorder.analysis import detector_jit
        except Exception:  # the base install (or a numba that cannot load): the detector's numpy path runs
            _usable = False
        else:
            _jit = detector_jit
            _usable = _try_kernels()
    return _usable


def cell_mean_max(padded: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    """Each f x f cell's mean (float32) and maximum of uint16 counts padded to whole cells (f is
    the detector's 4)."""
    assert _jit is not None and padded.dtype == np.uint16 and f == 4
    out: tuple[np.ndarray, np.ndarray] = _jit._cell_mean_max(padded)
    return out


def grid_excess(opened: np.ndarray, mean: np.ndarray, cmax: np.ndarray, scale: np.float32, offset: np.float32,
                thr: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """The coarse grids of counts in temperatures (``scale * grid + offset`` in float32, as
    ``detector._affine32``), the cell maxima's excess over the background, the cells standing
    ``thr`` (in float32, as numpy compares a float32 array with a Python float) above it, and
    how many do: (opened, mean, cmax, excess, cells, count), to the bit."""
    assert _jit is not None
    *grids, n = _jit._grid_excess(np.ascontiguousarray(opened), np.ascontiguousarray(mean), np.ascontiguousarray(cmax),
                             np.float32(scale), np.float32(offset), np.float32(thr))
    opened_t, mean_t, cmax_t, excess, cells = grids
    return opened_t, mean_t, cmax_t, excess, cells, int(n)


def mend_bad_pixels(temps: np.ndarray, bad: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """``detector._fix_bad_pixels``'s mended copy of float32 temperatures, to the bit: each pixel
    of ``coords`` (``np.argwhere(bad)``) the median of its good neighbours. Its loop made a
    frame with a bad-pixel map cost 14% more (12 pixels, a 640x512 frame; ninth sitting)."""
    assert _jit is not None and temps.dtype == np.float32 and temps.ndim == 2
    # the copy is numpy's: a frame-sized block numba allocated and freed page-faulted afresh on
    # every frame in a process without recorder.frame_heap's bounds (2.1 against 1.2 ms a frame)
    out = temps.copy()
    _jit._mend(temps, bad, np.ascontiguousarray(coords, dtype=np.intp), out)
    return out


def opening(mean: np.ndarray, k: int) -> np.ndarray:
    """The background's grey opening of a float32 grid of counts (no NaN): ``detector.
    sliding_extreme``'s minimum then maximum over k x k, edges repeated, to the bit (min and max
    are exact in any order). Three comparisons a cell a pass (van Herk / Gil-Werman) where the
    doubling windows take log2(k) whole-array numpy operations: 0.073 against 0.110 ms on the
    noisy 640x512 frame's 128x160 grid (2026-12-07, Zen 4)."""
    assert _jit is not None and mean.dtype == np.float32 and mean.ndim == 2 and k >= 1
    out: np.ndarray = _jit._opening(np.ascontiguousarray(mean), int(k))
    return out


def box_mean(a: np.ndarray, size: int) -> np.ndarray:
    """``scipy.ndimage.uniform_filter(a, size, mode="nearest")`` of a float32 grid, to the bit
    (the detector's local mean around each coarse cell: 65 us of scipy a noisy 640x512 frame)."""
    assert _jit is not None and a.dtype == np.float32 and a.ndim == 2
    out: np.ndarray = _jit._box_mean(np.ascontiguousarray(a), int(size))
    return out


def region_facts(cells: np.ndarray, excess: np.ndarray, cmax: np.ndarray) -> tuple[int, Any]:
    """The 8-connected regions of ``cells``: (count, (y0, y1, x0, x1, top excess, top cell
    maximum) in label order), as ``ndimage.label`` numbers them. ``excess`` and ``cmax`` must
    hold no NaN (on counts they cannot)."""
    assert _jit is not None
    n, *facts = _jit._region_facts(np.ascontiguousarray(cells), excess, cmax)
    return int(n), facts


def window_components(src: np.ndarray, opened: np.ndarray, boxes: np.ndarray, f: int, scale: np.float32,
                      offset: np.float32, thr: float, min_area: int) -> list[tuple[int, int, int, tuple[slice, slice],
                                                                                    np.ndarray]]:
    """``detector._components`` of the candidate windows of ``boxes`` (cells: y0, y1, x0, x1),
    with each window's candidate mask made on the way: (window y0, x0, area, slice within the
    window, own mask) in window order, then label order. ``src`` is the frame (uint16 counts
    with the model's ``scale``/``offset``, or float32 temperatures with 1 and 0), ``opened`` the
    background grid in temperatures."""
    assert _jit is not None
    h, w = src.shape
    labels, starts, win, lab, box, area = _jit._window_components(
        src, opened, np.ascontiguousarray(boxes, dtype=np.intp), f, h, w, np.float32(scale), np.float32(offset),
        np.float32(thr), min_area)
    out = []
    for i, k, (y0, y1, x0, x1), a in zip(win.tolist(), lab.tolist(), box.tolist(), area.tolist(), strict=True):
        cy0, _, cx0, cx1 = (int(v) for v in boxes[i])
        ww = min(w, cx1 * f) - cx0 * f
        window = labels[starts[i]:starts[i + 1]].reshape(-1, ww)
        sl = (slice(y0, y1), slice(x0, x1))
        out.append((cy0 * f, cx0 * f, a, sl, window[sl] == k))
    return out


def _try_kernels() -> bool:
    try:
        cell_mean_max(np.zeros((4, 4), np.uint16), 4)
        box_mean(np.zeros((2, 2), np.float32), 3)
        opening(np.zeros((2, 2), np.float32), 3)
        grid_excess(np.zeros((2, 2), np.float32), np.zeros((2, 2), np.float32), np.zeros((2, 2), np.uint16),
                    np.float32(1.0), np.float32(0.0), 5.0)
        mend_bad_pixels(np.zeros((2, 2), np.float32), np.eye(2, dtype=bool), np.array([[0, 0]]))
        region_facts(np.ones((2, 2), bool), np.zeros((2, 2), np.float32), np.zeros((2, 2), np.float32))
        for src in (np.zeros((8, 8), np.uint16), np.zeros((8, 8), np.float32)):
            window_components(src, np.zeros((2, 2), np.float32), np.array([[0, 2, 0, 2]]), 4, np.float32(1.0),
                              np.float32(0.0), 5.0, 4)
    except Exception:
        return False
    return True


def warm() -> None:
    """Load (or, on a machine whose cache has not seen them, compile) the kernels now, before
    a recording's first frame: a first call otherwise costs that frame up to a second or two."""
    available()
