"""Defect 10 (the CLI half): a read-only root and a truncated segment give one clean line naming
the file and a non-zero exit, never a traceback, and change nothing."""

from __future__ import annotations

import os
import subprocess

import pytest

from tests.conftest import run_cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource


def _record(root, sid="a"):
    Recorder(SimSource(width=64, height=48, frames=20, paced=False), root, session_id=sid, analysis=False).run()
    return root / "sessions" / sid


@pytest.fixture
def read_only_root(tmp_path):
    src = tmp_path / "rw"
    _record(src)
    ro = tmp_path / "ro"
    ro.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "--bind", str(src), str(ro)], capture_output=True).returncode:
        pytest.skip("cannot bind-mount here (needs root)")
    try:
        if subprocess.run(["mount", "-o", "remount,bind,ro", str(ro)], capture_output=True).returncode:
            pytest.skip("cannot remount read-only here")
        yield ro
    finally:
        subprocess.run(["umount", "-l", str(ro)], capture_output=True)


@pytest.mark.parametrize("args", [["archive", "--all"], ["index"], ["analyze", "a"], ["recover", "{root}"],
                                  ["gc", "--keep-days", "0"]])
def test_a_read_only_root_is_a_clean_error(read_only_root, args):
    before = sorted((p.name, p.stat().st_size) for p in read_only_root.rglob("*"))
    args = [a.format(root=read_only_root) for a in args]
    r = run_cli(*args, *([] if args[0] == "recover" else ["--root", str(read_only_root)]))
    assert "Traceback" not in r.stderr, r.stderr
    if r.returncode != 0:
        assert r.returncode == 1
        assert "read-only" in r.stderr.lower()
        assert str(read_only_root) in r.stderr
    assert sorted((p.name, p.stat().st_size) for p in read_only_root.rglob("*")) == before


def test_archiving_a_truncated_segment_is_a_clean_error(tmp_path):
    session = _record(tmp_path)
    seg = session / "0000.mcap"
    data = seg.read_bytes()
    seg.write_bytes(data[: len(data) - 200])  # a copy cut short: the summary is gone
    r = run_cli("archive", str(session), "--formats", "png16")
    assert r.returncode == 1
    assert "Traceback" not in r.stderr
    assert "0000.mcap" in r.stderr
    assert "recover" in r.stderr
    assert seg.read_bytes() == data[: len(data) - 200]
    assert not (session / "archive" / "png16").exists()
