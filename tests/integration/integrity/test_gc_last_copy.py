"""Defect 9: gc could delete the last good copy (partial archives counted as verified, extras
ignored, no lock, whole folders removed in local mode)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import thermcap.archive.archiver as archiver
from tests.conftest import run_cli
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.lock import lock_session
from thermcap.recorder.storage.reader import iter_session_frames


def _session(root, sid="s"):
    Recorder(SimSource(width=64, height=48, frames=30, paced=False, start_time_ns=1_700_000_000_000_000_000),
             root, session_id=sid, analysis=False).run()
    return root / "sessions" / sid


def _gc(root, *extra):
    r = run_cli("gc", "--root", str(root), "--keep-days", "0", "--json", *extra)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_an_archive_killed_after_two_of_four_formats_does_not_qualify(tmp_path, monkeypatch):
    session = _session(tmp_path)
    formats = ["png16", "tiff-lzw", "hdf5", "jxl"]
    monkeypatch.setattr(archiver, "_archive_locked", _two_then_die(archiver._archive_locked))
    with pytest.raises(KeyboardInterrupt):
        archive_session(session, formats)
    res = _gc(tmp_path)
    assert res["deleted"] == []
    assert "not verified" in res["decisions"][0]["why_kept"]
    assert list(session.glob("*.mcap"))
    assert (session / "archive" / "png16").is_dir()


def _two_then_die(real):
    """The archiver killed after its first two formats: those verified, the run recorded all four
    as requested (it saves the manifest after each format), the rest never happened."""
    def run(session_dir, formats, *a, **kw):
        real(session_dir, formats[:2], *a, **kw)
        from thermcap.archive.manifest import load_manifest, save_manifest

        m = load_manifest(session_dir)  # the archiver's own save: both copies, each with its checksum
        m["requested_formats"] = sorted(formats)
        save_manifest(session_dir, m)
        raise KeyboardInterrupt
    return run


def test_local_gc_deletes_only_the_source_and_the_archive_keeps_serving(tmp_path):
    session = _session(tmp_path)
    truth = [np.array(f.pixels) for f in iter_session_frames(session)]
    archive_session(session, ["png16", "hdf5"])
    dry = _gc(tmp_path, "--dry-run")
    assert dry["decisions"][0]["action"] == "delete-source"
    assert any("png16" in r for r in dry["decisions"][0]["relies_on"])
    assert any("extras" in r for r in dry["decisions"][0]["relies_on"])
    assert list(session.glob("*.mcap"))  # a dry run deletes nothing
    res = _gc(tmp_path)
    assert res["deleted"] == [str(session)]
    assert not list(session.glob("*.mcap"))
    assert (session / "archive" / "png16").is_dir()
    after = [np.array(f.pixels) for f in iter_session_frames(session)]
    assert len(after) == len(truth)
    assert all(np.array_equal(a, b) for a, b in zip(after, truth, strict=True))
    again = _gc(tmp_path)  # nothing else covers the archive: it is the last copy
    assert again["deleted"] == []
    assert (session / "archive" / "png16").is_dir()


def test_gc_keeps_a_session_whose_extras_are_missing(tmp_path):
    session = _session(tmp_path)
    archive_session(session, ["png16"])
    (session / "archive" / "extras.mcap").unlink()
    res = _gc(tmp_path)
    assert res["deleted"] == []
    assert "extras" in res["decisions"][0]["why_kept"]
    assert list(session.glob("*.mcap"))


def test_gc_keeps_a_session_whose_archive_file_was_damaged(tmp_path):
    session = _session(tmp_path)
    archive_session(session, ["png16"])
    z = session / "archive" / "png16" / "0000.zip"
    data = bytearray(z.read_bytes())
    data[len(data) // 2] ^= 1
    z.write_bytes(bytes(data))
    res = _gc(tmp_path)
    assert res["deleted"] == []
    assert list(session.glob("*.mcap"))


def test_gc_never_touches_a_session_someone_holds(tmp_path):
    session = _session(tmp_path)
    archive_session(session, ["png16"])
    lock = lock_session(session, "recorder")
    try:
        res = _gc(tmp_path)
    finally:
        lock.release()
    assert res["deleted"] == []
    assert "recorder" in res["decisions"][0]["why_kept"]
    assert list(session.glob("*.mcap"))
