"""Issue 65, defect 2: `gc` deleted the last good copy on a bucket's word. One byte of an
uploaded archive file rotted inside the store (HEAD still answered the same size and ETag; GET
failed on the store's own CRC), and `gc --keep-days 0` deleted the local folder "relying on: 7
objects in the s3 store, sizes and ETags rechecked". The bucket's copy is now read back and
hashed against the manifest before the local one goes, as local copies always were."""

from __future__ import annotations

import json
import uuid

import pytest

from tests.conftest import bucket_env, run_cli
from tests.support.api_data import make_root

pytestmark = pytest.mark.system


def _rot_in_store(store_dir, original: bytes) -> bool:
    """Flip one byte of ``original``'s bytes wherever SeaweedFS keeps them (its volume files; other
    tests of the run may have uploaded the same bytes under other prefixes: every copy rots)."""
    probe = original[len(original) // 2: len(original) // 2 + 64]
    found = False
    for path in store_dir.rglob("*.dat"):
        data = bytearray(path.read_bytes())
        at = data.find(probe)
        while at >= 0:
            data[at + 10] ^= 0x40
            found = True
            at = data.find(probe, at + 1)
        if found:
            path.write_bytes(bytes(data))
    return found


def test_gc_keeps_the_local_copy_when_the_buckets_copy_rotted(tmp_path, seaweedfs):
    root = make_root(tmp_path / "root")
    session = root / "sessions" / "s-archived"
    prefix = f"rot-{uuid.uuid4().hex[:12]}"
    env = bucket_env(seaweedfs, prefix)
    r = run_cli("upload", "s-archived", "--root", str(root), "--json", env=env)
    assert r.returncode == 0, r.stderr
    zips = sorted((session / "archive" / "png16").glob("*.zip"))
    assert zips and _rot_in_store(seaweedfs["dir"], zips[-1].read_bytes()), "the object's bytes were not found"
    r = run_cli("gc", "--root", str(root), "--keep-days", "0", "--json", env=env)
    assert session.is_dir(), (r.stdout, r.stderr)  # the last good copy stays
    out = json.loads(r.stdout)
    (decision,) = [d for d in out["decisions"] if str(d["session"]).endswith("s-archived")]
    assert "no longer hash" in json.dumps(decision) or "cannot be read back" in json.dumps(decision), decision
    assert zips[-1].is_file()


def test_gc_keeps_a_session_whose_documents_changed_since_the_upload(tmp_path, seaweedfs):
    """Issue 65, defect 13: a model version added after `upload` was lost when `gc` deleted the
    local folder (it checked the archive's objects, not the session's own documents): the bucket
    session had no version 1 and gave the recorded model's temperatures."""
    from thermcap.recorder.radiometry import model_from_dict
    from thermcap.recorder.radiometry.params import add_version
    from thermcap.recorder.storage.reader import read_session_meta

    root = make_root(tmp_path / "root")
    session = root / "sessions" / "s-archived"
    env = bucket_env(seaweedfs, f"docs-{uuid.uuid4().hex[:12]}")
    assert run_cli("upload", "s-archived", "--root", str(root), "--json", env=env).returncode == 0
    base = model_from_dict(read_session_meta(session)["radiometric_model"])
    add_version(session, base, {}, who="test", why="a new calibration",
                measured=model_from_dict({**base.to_dict(), "offset_c": -39.0}))
    r = run_cli("gc", "--root", str(root), "--keep-days", "0", "--json", env=env)
    assert session.is_dir(), (r.stdout, r.stderr)
    (decision,) = [d for d in json.loads(r.stdout)["decisions"] if str(d["session"]).endswith("s-archived")]
    assert "radiometry.json" in json.dumps(decision), decision
    # once uploaded again, the bucket holds what the folder holds, and the folder may go
    assert run_cli("upload", "s-archived", "--root", str(root), "--json", env=env).returncode == 0
    r = run_cli("gc", "--root", str(root), "--keep-days", "0", "--json", env=env)
    assert not session.is_dir(), (r.stdout, r.stderr)
