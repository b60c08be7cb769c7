"""Issue 65, defect 5: a damaged global heap in an ``hdf5`` archive (the sidecar strings) hung
HDF5's own read for good, inside h5py's global lock, so every HDF5 read of the process waited.
The sidecars are now read from the heap's bytes with every length bounded: a damaged
collection fails (and is reported by the sidecar's hash), the pixels still serve, nothing hangs."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from tests.conftest import run_cli
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource

READ_ALL = """
import sys, thermcap
s = thermcap.open(sys.argv[1])
print("read", sum(1 for i in range(len(s)) if s.counts(i).shape == (32, 48)))
"""


@pytest.fixture(scope="module")
def hdf5_only(tmp_path_factory):
    root = tmp_path_factory.mktemp("root")
    Recorder(SimSource(width=48, height=32, frames=120, paced=False, start_time_ns=1_800_000_000_000_000_000),
             root, session_id="s", analysis=False).run()
    archive_session(root / "sessions" / "s", ["hdf5"], delete_source=True)
    return root


def test_a_damaged_heap_fails_and_never_hangs(hdf5_only, tmp_path):
    h5 = next((hdf5_only / "sessions" / "s" / "archive" / "hdf5").glob("*.h5"))
    good = h5.read_bytes()
    collections = [i for i in range(len(good)) if good.startswith(b"GCOL", i)]
    assert len(collections) >= 3
    for k, at in enumerate(collections):
        root = tmp_path / str(k)
        shutil.copytree(hdf5_only, root)
        path = root / "sessions" / "s" / "archive" / "hdf5" / h5.name
        data = bytearray(good)
        data[at + 16:at + 16 + 4096] = bytes(len(data[at + 16:at + 16 + 4096]))
        path.write_bytes(bytes(data))
        # a hang is a timeout here (minutes, on a loaded machine), not a wait for an event
        r = subprocess.run([sys.executable, "-c", READ_ALL, str(root / "sessions" / "s")], capture_output=True,
                           text=True, timeout=600)
        assert r.returncode == 0 and r.stdout.strip() == "read 120", (at, r.stdout, r.stderr[-500:])
        v = run_cli("verify", str(root / "sessions" / "s"), timeout=600)
        assert v.returncode != 0 and "Traceback" not in v.stderr, v.stderr
