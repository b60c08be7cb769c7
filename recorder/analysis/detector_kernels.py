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

import contextlib
import fcntl
import importlib.util
import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.analysis.child_env import child_env

__all__ = ["available", "box_mean", "cached", "cell_mean_max", "grid_excess", "mend_bad_pixels", "opening",
           "region_facts", "state", "warm", "warm_in_background", "window_components"]

_usable: bool | None = None  # None until the kernels were tried once in this process
_jit: Any = None  # detector_jit, imported on the first kernel asked for
#: the kernels this module calls (the helpers they call are compiled into them, not cached apart)
_ENTRY_POINTS = ("_cell_mean_max", "_grid_excess", "_opening", "_box_mean", "_mend", "_region_facts",
                 "_window_components")
_warming: threading.Thread | None = None  # warm_in_background's thread while it loads or compiles
#: held by the process compiling the kernels into the cache (``main``), until it exits
_COMPILE_LOCK = Path(tempfile.gettempdir()) / "thermcap-detector-kernels.lock"


def available() -> bool:
    """Whether the compiled passes run here. Tried once, on tiny arrays: a kernel numba cannot
    compile on this machine means the numpy path, never a detector (or a recording) that fails.
    While :func:`warm_in_background` is still loading them, False without waiting: the numpy
    path answers the same, to the bit."""
    global _usable
    if _warming is not None:
        return False
    if _usable is None:
        _usable = _load()
    return _usable


def state() -> str:
    """What the detector runs on now: ``"compiled"``, ``"numpy"``, ``"warming"`` (numpy while
    the kernels load or compile beside it) or ``"untried"``."""
    if _warming is not None:
        return "warming"
    return {None: "untried", True: "compiled", False: "numpy"}[_usable]


def warm_in_background() -> None:
    """Make the compiled passes ready without making a recording wait for a compile: loaded
    now where numba's cache holds them (a fraction of a second, before the first frame), else
    compiled beside the recording while the detector answers on its numpy path (the same
    answers, to the bit) until they run.

    The compile is a process of its own, at a lower priority, that outlives a recording shorter
    than the compile, so the cache is filled once whatever happens to the recording; this
    process then loads them from the cache in a thread. Compiling in a thread here held this
    interpreter's lock for seconds beside the detector, and a recording that ended first took
    the unfinished compile with it (a first boot, a new container: every short recording
    compiled again)."""
    global _usable, _warming
    if _usable is not None or _warming is not None:
        return
    try:
        has_numba = importlib.util.find_spec("numba") is not None
    except (ImportError, ValueError):
        has_numba = False
    if not has_numba:  # the base install: numpy it is, and no compile process
        _usable = False
        return
    if cached():
        _usable = _load()
        return

    def load() -> None:
        global _usable, _warming
        try:
            ok = _compiled_elsewhere() and _load()
        except Exception:
            ok = False
        _usable, _warming = ok, None

    _warming = threading.Thread(target=load, name="thermcap-detector-kernels", daemon=True)
    _warming.start()


def cached() -> bool:
    """Whether numba's cache holds every kernel for this source (its index, stamped with the
    source file's time), read without compiling, and no compile process is still adding to it
    (a second recording started while the first one's compile runs). numba has no public call
    for this; a numba whose internals differ answers False, which costs a compile process,
    never a wrong answer."""
    if _compiling_now():
        return False
    try:
        from numba.core.registry import CPUDispatcher

        from thermcap.recorder.analysis import detector_jit
    except Exception:
        return False
    try:
        kernels: list[Any] = [getattr(detector_jit, name) for name in _ENTRY_POINTS]
        return all(isinstance(k, CPUDispatcher) and getattr(k, "_cache")._cache_file._load_index()  # noqa: B009
                   for k in kernels)
    except Exception:
        return False


def _compiling_now() -> bool:
    """Whether a compile process (``main``) holds the lock: it holds it until it exits."""
    try:
        fd = os.open(_COMPILE_LOCK, os.O_RDONLY | os.O_CREAT, 0o644)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)  # and with it our lock
    return False


def _compiled_elsewhere() -> bool:
    """Load-or-compile the kernels into numba's cache in a process of their own (this module's
    ``main``); True once they are there."""
    try:
        proc = subprocess.Popen([sys.executable, "-m", __name__], stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                                env=child_env())
    except OSError:
        return False
    return proc.wait() == 0


def _load() -> bool:
    global _jit
    try:
        from thermcap.recorder.analysis import detector_jit
    except Exception:  # the base install (or a numba that cannot load): the detector's numpy path runs
        return False
    _jit = detector_jit
    return _try_kernels()


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
    # one signature a frame type: numba compiles an F-ordered grid (a transposed opening) apart
    labels, starts, win, lab, box, area = _jit._window_components(
        src, np.ascontiguousarray(opened), np.ascontiguousarray(boxes, dtype=np.intp), f, h, w, np.float32(scale),
        np.float32(offset), np.float32(thr), min_area)
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
        # a frame in the detector process is a read-only view of its shared slot, which numba
        # compiles apart from a writable array: both, or the first real frame compiles again
        frozen = np.zeros((8, 8), np.uint16)
        frozen.flags.writeable = False
        cell_mean_max(frozen, 4)
        for src in (np.zeros((8, 8), np.uint16), frozen, np.zeros((8, 8), np.float32)):
            window_components(src, np.zeros((2, 2), np.float32), np.array([[0, 2, 0, 2]]), 4, np.float32(1.0),
                              np.float32(0.0), 5.0, 4)
    except Exception:
        return False
    return True


def warm() -> None:
    """Load (or, on a machine whose cache has not seen them, compile) the kernels now and wait
    for them: ``python -m thermcap.kernels`` and the benches, which want the compiled passes
    from their first frame. A recording uses :func:`warm_in_background` instead."""
    thread = _warming
    if thread is not None:
        thread.join()
    available()


def main() -> int:
    """``python -m thermcap.recorder.analysis.detector_kernels``: load or compile the kernels
    into numba's cache on CPU time the recording leaves; exit 0 when they run."""
    with contextlib.suppress(AttributeError, OSError):  # Linux: only CPU time nobody else wants
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    with contextlib.suppress(OSError):
        os.nice(19)
    # one compile at a time: a second waits, then loads what the first put in the cache
    fd = os.open(_COMPILE_LOCK, os.O_RDONLY | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX)
    return 0 if _load() else 1


if __name__ == "__main__":
    sys.exit(main())
