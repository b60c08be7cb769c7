"""Issue 36: ``upload`` and ``gc`` trusted recorded flags. An upload copied whatever bytes were
on disk (a rotted file went up as the verified one), and gc deleted a whole local folder on the
manifest's "upload complete" with no store to ask, or on object sizes alone."""

from __future__ import annotations

import pytest

from thermcap.api.jobs.retention import gc_sessions
from thermcap.archive.archiver import archive_session
from thermcap.archive.blobs import BlobStore, upload_archive
from thermcap.archive.manifest import load_manifest, save_manifest
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exceptions import ThermcapError


@pytest.fixture
def root(tmp_path):
    r = tmp_path / "root"
    Recorder(SimSource(width=64, height=48, frames=12, paced=False, start_time_ns=1_700_000_000_000_000_000),
             r, session_id="s", analysis=False).run()
    archive_session(r / "sessions" / "s", ["png16"])
    return r


@pytest.fixture
def store(tmp_path):
    from obstore.store import LocalStore

    (tmp_path / "bucket").mkdir()
    return BlobStore(LocalStore(str(tmp_path / "bucket")), kind="local-bucket")


def _gc(root, store):
    return gc_sessions(root, keep_days=0, max_bytes=None, require_upload=True, dry_run=False, store=store)


def test_upload_refuses_a_file_that_no_longer_hashes_as_verified(root, store):
    session = root / "sessions" / "s"
    z = next((session / "archive" / "png16").glob("*.zip"))
    data = bytearray(z.read_bytes())
    data[len(data) // 2] ^= 4
    z.write_bytes(bytes(data))
    with pytest.raises(ThermcapError, match="damaged copy"):
        upload_archive(store, root, session)
    assert not (load_manifest(session).get("upload") or {}).get("complete")


def test_upload_refuses_an_object_of_the_same_size_with_other_bytes(root, store):
    session = root / "sessions" / "s"
    z = next((session / "archive" / "png16").glob("*.zip"))
    key = z.resolve().relative_to(root.resolve()).as_posix()
    bad = bytearray(z.read_bytes())
    bad[10] ^= 1
    store.put_bytes(key, bytes(bad))
    with pytest.raises(ThermcapError, match="other bytes"):
        upload_archive(store, root, session)


def test_gc_without_a_store_never_deletes_on_the_recorded_upload(root, store):
    session = root / "sessions" / "s"
    upload_archive(store, root, session)
    res = gc_sessions(root, keep_days=0, max_bytes=None, require_upload=True, dry_run=False, store=None)
    assert not res.deleted and session.is_dir()
    assert "no store is configured" in res.decisions[0].why_kept


def test_gc_keeps_the_folder_when_an_object_was_rewritten(root, store, tmp_path):
    session = root / "sessions" / "s"
    keys = upload_archive(store, root, session)
    zkey = next(k for k in keys if k.endswith(".zip"))
    obj = tmp_path / "bucket" / zkey
    data = bytearray(obj.read_bytes())
    data[20] ^= 1
    store.put_bytes(zkey, bytes(data))  # same size, other bytes
    res = _gc(root, store)
    assert not res.deleted and session.is_dir(), res.to_dict()


def test_gc_keeps_the_folder_when_scrub_found_an_object_damaged(root, store):
    session = root / "sessions" / "s"
    keys = upload_archive(store, root, session)
    m = load_manifest(session)
    m["upload"]["damaged"] = {keys[0]: "sha256 differs from the manifest"}
    save_manifest(session, m)
    res = _gc(root, store)
    assert not res.deleted and session.is_dir()


def test_gc_keeps_a_format_archived_after_the_upload(root, store):
    session = root / "sessions" / "s"
    upload_archive(store, root, session)
    archive_session(session, ["hdf5"])  # not in the bucket
    res = _gc(root, store)
    assert not res.deleted and session.is_dir()
    assert "never uploaded" in res.decisions[0].why_kept


def test_gc_deletes_the_folder_when_the_bucket_covers_it(root, store):
    session = root / "sessions" / "s"
    upload_archive(store, root, session)
    res = _gc(root, store)
    assert [d.session for d in res.deleted] == [str(session)] and not session.exists()
