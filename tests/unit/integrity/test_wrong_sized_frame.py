"""Issue 36: a frame of another size crashed ``archive`` with a traceback (a ValueError from the
frame summary) and left ``extras.mcap.partial`` behind."""

from __future__ import annotations

import shutil

import pytest

from tests.conftest import run_cli
from thermcap.archive.archiver import archive_session
from thermcap.archive.exceptions import ArchiveError
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource


@pytest.fixture
def mixed(tmp_path):
    for sid, w, t in (("a", 32, 0), ("b", 40, 10**9)):
        Recorder(SimSource(width=w, height=24, frames=10, paced=False, start_time_ns=1_800_000_000_000_000_000 + t),
                 tmp_path, session_id=sid, analysis=False).run()
    session = tmp_path / "sessions" / "a"
    shutil.copy(tmp_path / "sessions" / "b" / "0000.mcap", session / "0001.mcap")
    return session


def test_a_frame_of_another_size_is_refused_by_name(mixed):
    before = sorted(p.name for p in mixed.iterdir())
    with pytest.raises(ArchiveError, match=r"frame 10 \(0001.mcap\) is 40x24"):
        archive_session(mixed, ["png16", "tiff-lzw", "hdf5"])
    left = sorted(p.name for p in (mixed / "archive").iterdir()) if (mixed / "archive").is_dir() else []
    assert not [n for n in left if n.endswith(".partial")], left
    assert [n for n in sorted(p.name for p in mixed.iterdir()) if n != "archive"] == \
        [n for n in before if n != "archive"]


def test_the_cli_says_so_without_a_traceback(mixed):
    r = run_cli("archive", str(mixed))
    assert r.returncode != 0 and "is 40x24" in r.stderr and "Traceback" not in r.stderr


def test_partials_of_a_killed_force_run_go_when_it_is_redone(session):
    """Issue 36: png16.partial and tiff-lzw.partial stayed after a killed ``--force`` run was redone."""
    archive_session(session, ["png16", "tiff-lzw"])
    for fid in ("png16", "tiff-lzw"):  # what a run killed half way through --force leaves
        (session / "archive" / f"{fid}.partial").mkdir()
        (session / "archive" / f"{fid}.partial" / "0000.zip").write_bytes(b"half")
    (session / "archive" / "extras.mcap.partial").write_bytes(b"half")
    archive_session(session, ["png16", "tiff-lzw"])
    assert not list((session / "archive").glob("*.partial"))
