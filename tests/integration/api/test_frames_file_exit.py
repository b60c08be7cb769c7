"""Reading a session's frames file starts no native thread, so nothing of pyarrow's is alive
when the interpreter tears down: its threaded Parquet reader left a thread-pool worker running
into teardown, whose destructor aborted the process after the work was done ("terminate called
without an active exception", exit -6; apache/arrow#34314). `thermcap cut` failed so once in
the CI run's 1,664 tests, once in 40 runs by hand, and a plain read then exit in 10 of 150.
The threads are counted (/proc), which fails on the threaded reader every time, where the abort
itself is a race."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from thermcap.api.reading.frame_columns import FrameColumns

_READ = """
import json, os, sys
import pyarrow, pyarrow.parquet
from thermcap.api.reading.frame_columns import FrameColumns

def threads():
    return sorted(open(f"/proc/self/task/{t}/comm").read().strip() for t in os.listdir("/proc/self/task"))

data = open(sys.argv[1], "rb").read()
before = threads()
cols = FrameColumns.from_parquet("s", data)
print(json.dumps({"before": before, "after": threads(), "frames": len(cols)}))
"""


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads through /proc (Linux)")
def test_reading_a_frames_file_starts_no_thread_that_could_abort_the_exit(tmp_path):
    rows = [{"idx": i, "timestamp_ns": 1_000_000 * i, "segment": f"seg-{i // 500}", "pixel_digest": f"{i:064x}",
             "sidecar_digest": None, "grade": 0.5, "target_count": i % 3, "max_target_temp_c": None,
             "slew_to_cue": False} for i in range(2000)]
    path = tmp_path / "frames.parquet"
    path.write_bytes(FrameColumns.from_rows("s", rows).to_parquet())
    proc = subprocess.run([sys.executable, "-c", _READ, str(path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)
    assert got["frames"] == 2000
    assert got["after"] == got["before"], "the read left threads running into the interpreter's exit"
