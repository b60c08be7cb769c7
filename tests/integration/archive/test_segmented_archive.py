"""A session archived segment by segment (each segment's task on its own) and finalized once
gives the archive the single-pass archiver gives: the same files byte for byte (one per
segment), the same HDF5 chunks (copied, not encoded again), the same manifest, extras and
summary, and it verifies. A rerun of a finished segment does nothing. A lost worker's half part
is replaced. A part damaged after its task is not taken into the archive, and finalizing before
every segment is done is refused by name."""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest

from thermcap.archive.archiver import archive_session
from thermcap.archive.exceptions import ArchiveError, VerificationError
from thermcap.archive.frame_summary import load_summary
from thermcap.archive.manifest import load_manifest
from thermcap.archive.segmented import PARTS, archive_segment, finalize_session, plan_segments
from thermcap.archive.verify import verify_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy

FORMATS = ["png16", "tiff-lzw", "hdf5"]


def _session(root, sid="s"):
    Recorder(SimSource(width=128, height=96, fps=30, frames=75, paced=False, seed=6), root, session_id=sid,
             policy=SegmentPolicy(max_duration_s=0.6), analysis=False).run()
    return root / "sessions" / sid


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    base = tmp_path_factory.mktemp("seg")
    one = _session(base / "a")
    shutil.copytree(base / "a", base / "b")
    two = base / "b" / "sessions" / "s"
    archive_session(one, FORMATS)
    plan = plan_segments(two)
    assert len(plan) >= 3
    for name, first in reversed(plan):  # in any order, as workers finish
        archive_segment(two, name, first, FORMATS)
    finalize_session(two, FORMATS)
    return one, two


def test_the_same_archive_as_the_single_pass(both):
    one, two = both
    m1, m2 = load_manifest(one), load_manifest(two)
    assert m1["frames"] == m2["frames"] and m1["source"]["frames"] == m2["source"]["frames"] == 75
    for fid in ("png16", "tiff-lzw"):
        assert [(f["path"], f["blake3"]) for f in m1["formats"][fid]["files"]] == \
            [(f["path"], f["blake3"]) for f in m2["formats"][fid]["files"]]
    with h5py.File(one / "archive/hdf5/s.h5") as a, h5py.File(two / "archive/hdf5/s.h5") as b:
        assert a["frames"].shape == b["frames"].shape
        for k in range(a["frames"].shape[0]):
            assert a["frames"].id.read_direct_chunk((k, 0, 0)) == b["frames"].id.read_direct_chunk((k, 0, 0))
        assert np.array_equal(a["timestamps_ns"][...], b["timestamps_ns"][...])
        assert list(a["metadata"][...]) == list(b["metadata"][...])
        assert "temperature_lut" in b or "scale_factor" in b["frames"].attrs  # the netCDF description
    s1, s2 = (load_summary((d / "archive/summary.npz").read_bytes()) for d in (one, two))
    assert np.array_equal(s1.band_crc32, s2.band_crc32) and np.array_equal(s1.sum, s2.sum)
    assert m2["extras"]["verified"] and m1["extras"]["topics"] == m2["extras"]["topics"]
    assert all(c.ok for c in verify_session(two, FORMATS).values())
    assert not (two / "archive" / PARTS).exists()


def test_a_finished_segment_is_not_done_twice_and_a_lost_workers_part_is_replaced(tmp_path):
    d = _session(tmp_path)
    name, first = plan_segments(d)[1]
    part = archive_segment(d, name, first, ["png16"])
    stamp = (d / "archive" / PARTS / name / "part.json").stat().st_mtime_ns
    again = archive_segment(d, name, first, ["png16"])
    assert again == part and (d / "archive" / PARTS / name / "part.json").stat().st_mtime_ns == stamp
    lost = d / "archive" / PARTS / (plan_segments(d)[0][0] + ".partial")
    lost.mkdir()
    (lost / "junk").write_bytes(b"half")
    with pytest.raises(ArchiveError, match=plan_segments(d)[0][0]):
        finalize_session(d, ["png16"])  # segment 0 has no part yet: refused, by name
    archive_segment(d, *plan_segments(d)[0], ["png16"])
    assert not lost.exists()
    for name, first in plan_segments(d)[2:]:
        archive_segment(d, name, first, ["png16"])
    assert load_manifest(finalize_session(d, ["png16"]) and d)["formats"]["png16"]["verified"]


def test_a_part_damaged_after_its_task_is_not_taken(tmp_path):
    d = _session(tmp_path)
    plan = plan_segments(d)
    for name, first in plan:
        archive_segment(d, name, first, ["png16"])
    victim = next((d / "archive" / PARTS / plan[1][0] / "png16").glob("*.zip"))
    data = bytearray(victim.read_bytes())
    data[len(data) // 2] ^= 0x40
    victim.write_bytes(bytes(data))
    with pytest.raises(VerificationError):
        finalize_session(d, ["png16"])
    assert not (d / "archive" / "png16").exists()  # never took the final name
    assert not load_manifest(d)["formats"]["png16"]["verified"]
    assert not (d / "archive" / PARTS / plan[1][0]).exists()  # the void part goes; its task runs again
    archive_segment(d, *plan[1], ["png16"])
    assert finalize_session(d, ["png16"])["formats"]["png16"]["verified"]
