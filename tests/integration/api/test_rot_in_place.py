"""Issue 36: an archive file that rots in place (one byte changed, same size, inode and mtime) was
downloaded as 200 with the manifest's sha256 as its ETag: the verified-file cache is keyed on
size, mtime and inode. Every whole-file download is now hashed as it is sent, its last piece
held back: a damaged file never arrives whole, and the damage is reported."""

from __future__ import annotations

import os

import httpx
import pytest
from blake3 import blake3

from tests.conftest import ApiServer
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource


@pytest.fixture
def served(tmp_path):
    Recorder(SimSource(width=96, height=64, frames=20, paced=False, start_time_ns=1_800_000_000_000_000_000),
             tmp_path, session_id="s", analysis=False).run()
    archive_session(tmp_path / "sessions" / "s", ["png16", "hdf5"])
    server = ApiServer(tmp_path)
    yield tmp_path, server
    server.stop()


def _rot_in_place(path):
    st = path.stat()
    with open(path, "r+b") as f:
        f.seek(st.st_size // 2)
        b = f.read(1)
        f.seek(st.st_size // 2)
        f.write(bytes([b[0] ^ 0x10]))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    after = path.stat()
    assert (after.st_size, after.st_mtime_ns, after.st_ino) == (st.st_size, st.st_mtime_ns, st.st_ino)


@pytest.mark.parametrize("fmt", ["png16", "hdf5"])
def test_a_file_rotted_in_place_is_never_served_whole(served, fmt):
    root, server = served
    path = next((root / "sessions" / "s" / "archive" / fmt).iterdir())
    url = f"{server.url}/api/v1/sessions/s/archives/{fmt}/{path.name}"
    good = path.read_bytes()
    with httpx.Client(timeout=30) as c:
        first = c.get(url)
        assert first.status_code == 200 and first.content == good  # now in the verified cache
        _rot_in_place(path)
        try:
            r = c.get(url)
        except httpx.HTTPError:
            pass  # the transfer was cut short: the client knows it is incomplete
        else:
            assert r.status_code != 200 or blake3(r.content).hexdigest() == \
                r.headers["etag"].strip('"'), "damaged bytes arrived whole under the manifest's ETag"
        health = c.get(f"{server.url}/healthz").json()
        assert health["status"] == "degraded"
        again = c.get(url)  # the cache forgot it: refused before any byte goes
        assert again.status_code == 503
