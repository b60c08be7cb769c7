"""Issue 36, critical: ``archive --delete-source`` deleted the only good source when the archive
copy it trusted was bad. The manifest's ``verified: true`` is a flag written earlier; what the
deletion relies on is re-checked at that moment (file hashes against the manifest; a copy scrub
marked ``damaged`` is not verified). Three ways in, each of which ended with the source deleted,
exit 0 and "png16 verified", after which ``verify`` failed and nothing could rebuild it."""

from __future__ import annotations

import json

import pytest

from tests.support.archive_sessions import flip_in_image_entry
from thermcap.archive.archiver import archive_session
from thermcap.archive.manifest import load_manifest, save_manifest
from thermcap.archive.scrub import scrub_session
from thermcap.archive.verify import verify_session
from thermcap.recorder.storage.reader import iter_session_frames, session_segments


def _flip(session):
    flip_in_image_entry(next((session / "archive" / "png16").glob("*.zip")))


def _remove(session):
    next((session / "archive" / "png16").glob("*.zip")).unlink()


def _scrub_marked(session):
    zpath = next((session / "archive" / "png16").glob("*.zip"))
    good = zpath.read_bytes()
    _flip(session)
    found = scrub_session(session, repair=False).findings
    assert found and found[0].copy == "png16"
    zpath.write_bytes(good)
    # the bytes are put right again behind scrub's back: only the mark says damaged now; the
    # archiver must still not count a copy marked damaged as verified without checking it anew
    m = load_manifest(session)
    assert m["formats"]["png16"].get("damaged")


DAMAGE = {"flipped": _flip, "removed": _remove, "marked damaged": _scrub_marked}


@pytest.mark.parametrize("damage", DAMAGE)
def test_delete_source_rechecks_the_copies_it_relies_on(session, damage):
    truth = [(f.log_time, bytes(f.pixels.tobytes()), f.sidecar) for f in iter_session_frames(session)]
    archive_session(session, ["png16"])
    DAMAGE[damage](session)
    manifest = archive_session(session, ["png16"], delete_source=True)
    # either the source is still there, or every copy it relied on verifies now
    report = verify_session(session)
    assert all(c.ok for c in report.values()), {k: c.problems for k, c in report.items()}
    assert manifest["formats"]["png16"]["verified"] and not manifest["formats"]["png16"].get("damaged")
    assert manifest["source"]["deleted"] and not session_segments(session)
    back = [(f.log_time, bytes(f.pixels.tobytes()), f.sidecar) for f in iter_session_frames(session)]
    assert back == truth


def test_a_damaged_copy_is_rebuilt_not_skipped_without_delete(session):
    archive_session(session, ["png16", "hdf5"])
    _flip(session)
    archive_session(session, ["png16", "hdf5"])  # "re-running finishes the job"
    assert all(c.ok for c in verify_session(session).values())


def test_a_damaged_copy_with_no_source_refuses_and_says_which(session):
    archive_session(session, ["png16", "hdf5"], delete_source=True)
    _flip(session)
    from thermcap.archive.exceptions import ArchiveError

    with pytest.raises(ArchiveError, match="png16"):
        archive_session(session, ["png16"])
    # the damaged copy is marked, so no reader or gc relies on it, and hdf5 still serves every frame
    m = load_manifest(session)
    assert m["formats"]["png16"].get("damaged")
    assert len(list(iter_session_frames(session))) == len(m["frames"]["blake3"])


def test_extras_rechecked_before_delete(session):
    archive_session(session, ["hdf5"])
    extras = session / "archive" / "extras.mcap"
    data = bytearray(extras.read_bytes())
    data[len(data) // 2] ^= 1
    extras.write_bytes(bytes(data))
    archive_session(session, ["hdf5"], delete_source=True)
    assert all(c.ok for c in verify_session(session).values())


def test_manifest_edited_to_verified_is_not_evidence(session):
    """A manifest whose flag says verified for files that never were (hand-edited, or written by
    an older thermcap) is not taken at its word."""
    archive_session(session, ["png16"])
    m = load_manifest(session)
    m["formats"]["png16"]["files"][0]["blake3"] = "0" * 64
    save_manifest(session, m)
    archive_session(session, ["png16"], delete_source=True)
    assert all(c.ok for c in verify_session(session).values())
    assert json.loads((session / "archive" / "manifest.json").read_text())["source"]["deleted"]


def test_frames_stay_served_while_the_source_is_deleted(session):
    """Issue 36: ``archive --delete-source`` left a window of 503s: the index still pointed at the
    segments it deleted until the hook re-indexed after. The index now learns of the archive
    before the source goes (without the hook this test sees 503), so a server that never
    re-indexes meanwhile still serves every frame."""
    from fastapi.testclient import TestClient

    from thermcap.api.app import create_app
    from thermcap.api.indexing import index_session
    from thermcap.api.settings import Settings

    root = session.parent.parent / "root"
    (root / "sessions").mkdir(parents=True)
    moved = root / "sessions" / "s"
    session.rename(moved)
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        n = c.get("/api/v1/sessions/s").json()["frames"]
        engine = c.app.state.engine
        archive_session(moved, ["hdf5"], delete_source=True, before_delete=lambda d: index_session(engine, d))
        assert not session_segments(moved)
        for i in range(n):
            assert c.get(f"/api/v1/sessions/s/frames/{i}", params={"format": "raw"}).status_code == 200, i
