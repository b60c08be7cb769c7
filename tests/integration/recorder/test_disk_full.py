"""Issue 36: a recording that fills the disk. The summary counted frames as written that never
reached a closed chunk (146 reported, 120 recoverable), zero-byte ``*.tmp`` files stayed behind,
and the stop lost events.json. Now the count is what is durably on disk, the loss is named, the
end-of-run files are written from a reserve kept for them, and nothing half-written is left.
A real full filesystem: a 4 MiB tmpfs (needs root, as CI and this workplace have)."""

from __future__ import annotations

import json
import os
import subprocess

import pytest

from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames
from thermcap.recorder.storage.recover import recover_path
from thermcap.recorder.storage.segments import SegmentPolicy


@pytest.fixture
def small_disk(tmp_path):
    mnt = tmp_path / "disk"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here ({r.stderr.strip()}); run as root")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_full_disk_counts_only_what_is_on_disk(small_disk):
    res = Recorder(SimSource(width=160, height=128, frames=2000, paced=False, seed=3), small_disk, session_id="f",
                   analysis=False, policy=SegmentPolicy(max_duration_s=0.5)).run()
    assert res.error and "No space left" in res.error
    session = small_disk / "sessions" / "f"
    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] == "failed" and meta["frames_written"] == res.frames_written
    assert json.loads((session / "events.json").read_text())["session_id"] == "f"
    assert not [p.name for p in session.iterdir() if p.name.endswith(".tmp")]
    assert not (session / ".reserve").exists()
    recover_path(session)
    kept = list(iter_session_frames(session))
    assert len(kept) == res.frames_written, (len(kept), res.frames_written)
    if res.frames_written < res.frames_captured - res.frames_dropped:
        assert "never reached a closed chunk" in res.error
    os.sync()


def test_the_bag_metadata_leaves_nothing_half_written_on_a_full_disk(small_disk):
    """metadata.yaml is derived data written through a temporary file; a full disk raises, and
    the temporary file (created before the write failed) must not stay beside the session."""
    from thermcap.recorder.storage.rosbag2 import BAG_METADATA, write_bag_metadata

    res = Recorder(SimSource(width=64, height=48, frames=10, paced=False, seed=3), small_disk, session_id="m",
                   analysis=False).run()
    assert res.ok
    session = small_disk / "sessions" / "m"
    before = (session / BAG_METADATA).read_bytes()
    with open(small_disk / "filler", "wb", buffering=0) as f, pytest.raises(OSError):  # the rest of the disk
        while True:
            f.write(b"\0" * 65536)
    with pytest.raises(OSError):
        write_bag_metadata(session)
    assert not [p.name for p in session.iterdir() if p.name.endswith(".tmp")]
    assert (session / BAG_METADATA).read_bytes() == before  # the old file stays whole


def _fill(disk) -> None:
    with open(disk / "filler", "wb", buffering=0) as f, pytest.raises(OSError):  # the rest of the disk
        while True:
            f.write(b"\0" * 65536)


@pytest.mark.parametrize("what", ["foxglove layout", "summary.json", "summary.csv"])
def test_the_files_an_export_rewrites_leave_nothing_half_written_on_a_full_disk(small_disk, what):
    """The export's summary and the session's Foxglove layout were written to a .tmp and renamed,
    but a write that failed left the .tmp behind (as metadata.yaml's had). Every rewrite in place
    now goes through one helper (``recorder.storage.atomic``): on a full disk it raises, the old
    file stays whole, and nothing else is left."""
    from thermcap.recorder.exports.files import _write_summary
    from thermcap.recorder.storage.foxglove_layout import FOXGLOVE_LAYOUT, write_layout

    out = small_disk / "out"
    out.mkdir()
    stats = [{"frame": i, "mean_c": 20.0 + i, "max_c": 30.0 + i} for i in range(2000)]  # larger than what is left

    def write() -> None:
        if what == "foxglove layout":
            write_layout(out, {None: (0, 10_000_000_000)})
        else:
            _write_summary(out, what.split(".")[1], stats, {"session_id": "s"})

    write()
    target = out / (FOXGLOVE_LAYOUT if what == "foxglove layout" else what)
    before = target.read_bytes()
    _fill(small_disk)
    with pytest.raises(OSError):
        write()
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]
    assert target.read_bytes() == before
