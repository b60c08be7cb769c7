"""glibc's allocator, told to keep frame-sized blocks in the heap.

glibc serves a block above 128 KB from fresh mmap pages and returns it to the system when it is
freed, until a large free raises that bound (and trims the heap's top above twice it). Code that
makes a few frame-sized temporaries a frame (numpy steps on 640x512 int32 and int64 frames, 1.3
and 2.6 MB) then page-faults and zeroes each again on every frame in a fresh process:

- the detector's child: 1.05 ms a flat 640x512 frame, against 0.49 once the bound is above its
  working set (it gets the bounds in its environment, ``FRAME_HEAP_ENV``, before any allocation);
- tpred's encoder, two sequences on two threads in a new interpreter: 10.1-11.1 ms a frame and
  thread, against 7.1-7.6 with the bounds set (``keep_frame_blocks``, called by its encoder and
  decoder): 125-143 fps against 159-166 on this 2-core machine.

The cost is memory kept rather than returned: free blocks up to ``TRIM_BYTES`` at the top of each
heap stay with the process.

numpy, for its part, advises the kernel to back every array of 4 MB or more with huge pages
(``madvise(MADV_HUGEPAGE)``). For arrays that live a few milliseconds (libtiff's 25 decoded
pages at a time, a batch of frames) that costs more than it saves: each fault in such a region
zeroes 2 MB, and where free huge pages are short the kernel compacts memory first, on the
faulting thread. The archiver with the advice took 0.45-0.87 s of system CPU a 600-frame run and
16.9-18.0 ms a frame in all; without it 0.30-0.36 s and 15.7-16.7 ms (2026-12-06, same sitting).
``keep_frame_blocks`` turns that advice off too, unless ``NUMPY_MADVISE_HUGEPAGE`` is set.
"""

from __future__ import annotations

import ctypes
import importlib
import os
import threading

__all__ = ["FRAME_HEAP_ENV", "MMAP_BYTES", "TRIM_BYTES", "keep_frame_blocks"]

MMAP_BYTES = 32 * 1024 * 1024  # blocks below it come from the heap: a 1920x1080 int64 frame is 16.6 MB
TRIM_BYTES = 128 * 1024 * 1024  # free memory a heap keeps at its top before giving it back
_GLIBC_ENV = {"MALLOC_MMAP_THRESHOLD_": str(MMAP_BYTES), "MALLOC_TRIM_THRESHOLD_": str(TRIM_BYTES)}
_NUMPY_ENV = "NUMPY_MADVISE_HUGEPAGE"
#: the same for a child interpreter, read by glibc and numpy at its start
FRAME_HEAP_ENV = {**_GLIBC_ENV, _NUMPY_ENV: "0"}

_M_TRIM_THRESHOLD = -1  # glibc's <malloc.h>
_M_MMAP_THRESHOLD = -3
_done: bool | None = None
_lock = threading.Lock()


def keep_frame_blocks() -> bool:
    """Set the bounds in this process, once; True where glibc took them. Elsewhere (musl, macOS)
    nothing happens: their allocators are not glibc's. An environment that already sets either
    bound is left as it is: whoever set it knew what they wanted. numpy's huge-page advice is
    turned off on the same terms (see the module's docstring)."""
    global _done
    with _lock:
        if _done is None:
            if _NUMPY_ENV not in os.environ:
                _no_huge_page_advice()
            _done = not any(k in os.environ for k in _GLIBC_ENV) and _mallopt()
        return _done


def _no_huge_page_advice() -> None:
    # numpy 2's home for it, then numpy 1's; a numpy without it gives no advice to turn off
    for name in ("numpy._core.multiarray", "numpy.core.multiarray"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        set_advice = getattr(module, "_set_madvise_hugepage", None)
        if set_advice is not None:
            set_advice(False)
        return


def _mallopt() -> bool:
    try:  # the C library this process already runs on (finding it by name would run ldconfig)
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_BYTES)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_BYTES))
