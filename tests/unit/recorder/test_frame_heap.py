"""glibc keeps frame-sized blocks in the heap once ``keep_frame_blocks`` ran: a fresh process's
frame-sized temporaries had been page-faulted again on every frame (tpred's encoder at 10-11 ms a
frame against 7.1-7.6). Counted in page faults, not timed: each case in a fresh interpreter."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import pytest

from thermcap.recorder.frame_heap import FRAME_HEAP_ENV

pytestmark = pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                                reason="the bounds are glibc's; other allocators are left alone")

_PROBE = """
import json, resource, sys
import numpy as np
set_by = None
if sys.argv[1] == "keep":
    from thermcap.recorder.frame_heap import keep_frame_blocks
    set_by = keep_frame_blocks()
elif sys.argv[1] == "encoder":
    from thermcap.archive.codecs.tpred.codec import TemporalEncoder
    TemporalEncoder()
def frame_work():  # what a numpy step on a 640x512 frame makes: int64 and int32 temporaries
    x = np.ones((512, 640), np.int64)
    return int(((x * 3) + x).astype(np.int32)[0, 0])
frame_work()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    frame_work()
print(json.dumps({"set": set_by, "faults": resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before}))
"""


def _run(script: str, *args: str, **env: str) -> dict:
    """``script`` in a fresh interpreter, without the bounds in its environment unless ``env`` sets them."""
    clean = {k: v for k, v in os.environ.items() if k not in FRAME_HEAP_ENV}
    out = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, check=True,
                         env={**clean, **env})
    return json.loads(out.stdout)


def _probe(mode: str, **env: str) -> dict:
    return _run(_PROBE, mode, **env)


def test_frame_sized_temporaries_stop_faulting_once_the_bounds_are_set():
    plain = _probe("none")
    kept = _probe("keep")
    assert kept["set"] is True
    assert plain["faults"] > 10_000  # 50 frames' temporaries, each page-faulted again (about 110,000)
    assert kept["faults"] < plain["faults"] / 20
    assert _probe("encoder")["faults"] < plain["faults"] / 20  # tpred's encoder sets them itself


def test_bounds_the_environment_sets_are_left_as_they_are():
    assert _probe("keep", MALLOC_MMAP_THRESHOLD_="131072")["set"] is False


_NUMPY_PROBE = """
import json, sys
try:  # numpy 2, then numpy 1 (the project takes numpy >= 1.26)
    from numpy._core.multiarray import _set_madvise_hugepage
except ImportError:
    from numpy.core.multiarray import _set_madvise_hugepage
if sys.argv[1] == "keep":
    from thermcap.recorder.frame_heap import keep_frame_blocks
    keep_frame_blocks()
elif sys.argv[1] == "archive":
    from thermcap.archive.archiver import archive_session
    archive_session(sys.argv[2], ["png16"])
advised = _set_madvise_hugepage(True)  # returns what it was
print(json.dumps({"advised": advised}))
"""


def _numpy_probe(mode: str, *args: str, **env: str) -> dict:
    return _run(_NUMPY_PROBE, mode, *args, **env)


def test_numpy_huge_page_advice_is_turned_off_for_batch_sized_temporaries(session):
    """With the advice, each fault in a short-lived array of 4 MB or more zeroed 2 MB (and the
    kernel compacted memory first where huge pages were short): the archiver's system CPU fell
    by a fifth without it. Its state is read back, not timed."""
    assert _numpy_probe("none")["advised"] is True  # numpy's default on Linux
    assert _numpy_probe("keep")["advised"] is False
    assert _numpy_probe("archive", str(session))["advised"] is False  # the archiver's copies, written and read back


def test_numpy_huge_page_advice_the_environment_sets_is_left_as_it_is():
    assert _numpy_probe("keep", NUMPY_MADVISE_HUGEPAGE="1")["advised"] is True
