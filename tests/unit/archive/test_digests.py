"""The archive's proofs name their hash. New archives take BLAKE3; an archive written with
sha256 (before BLAKE3 was the default, or with ``--digest sha256``) is verified, scrubbed,
repaired, grown by a format and served by the hash its records name, never taken for damaged
because the default changed."""

from __future__ import annotations

import hashlib

import pytest
from blake3 import blake3
from click.testing import CliRunner
from fastapi.testclient import TestClient

from tests.support.archive_sessions import flip_in_image_entry
from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.archive.archiver import archive_session
from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.manifest import archived_files, frame_proof, load_manifest
from thermcap.archive.scrub import scrub_session
from thermcap.archive.verify import verify_session
from thermcap.recorder.storage.digest import frame_bytes
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta


def _file_records(m):
    return [*(r for e in m["formats"].values() for r in e.get("files", [])), m["extras"], m["summary"]]


def test_blake3_is_the_default_and_every_record_names_its_hash(session):
    frames = [f.pixels.copy() for f in iter_session_frames(session)]
    m = archive_session(session, ["png16", "tiff-lzw"])
    assert set(m["frames"]) >= {"blake3", "sidecar_blake3"} and "sha256" not in m["frames"]
    assert m["frames"]["blake3"] == [blake3(frame_bytes(f)).hexdigest() for f in frames]
    for rec in _file_records(m):
        assert "blake3" in rec and "sha256" not in rec, rec
    adir = session / "archive"
    for f in archived_files(m):  # what upload, gc and scrub go by: the hash the record names
        assert f.digest == "blake3" and blake3((adir / f.rel).read_bytes()).hexdigest() == f.hex
    assert "by the manifest's blake3" in m["formats"]["png16"]["verification"] \
        or "xxh3-128 taken on the same read as the manifest's blake3" in m["formats"]["png16"]["verification"]


def test_an_archive_made_with_sha256_is_checked_repaired_and_grown_by_sha256(session):
    frames = [f.pixels.copy() for f in iter_session_frames(session)]
    m = archive_session(session, ["png16"], digest="sha256")
    assert m["frames"]["sha256"] == [hashlib.sha256(frame_bytes(f)).hexdigest() for f in frames]
    assert all("sha256" in rec and "blake3" not in rec for rec in _file_records(m))
    assert all(c.ok for c in verify_session(session).values())

    # a format added later with the default: the frames' sha256 stay what every copy is compared
    # with (not taken again from a source that may have rotted); its own files are BLAKE3's
    m = archive_session(session, ["tiff-lzw"])
    assert "blake3" not in m["frames"] and len(m["frames"]["sha256"]) == len(frames)
    assert "by the manifest's sha256" in m["formats"]["tiff-lzw"]["verification"]
    assert all("blake3" in r for r in m["formats"]["tiff-lzw"]["files"])
    assert all("sha256" in r for r in m["formats"]["png16"]["files"])
    assert all(c.ok for c in verify_session(session).values())

    # damage png16: found by its own hash, repaired from tiff-lzw, then whole again
    flip_in_image_entry(next((session / "archive" / "png16").glob("*.zip")))
    bad = verify_session(session)["png16"]
    assert not bad.ok and any("sha256 differs" in p for p in bad.problems), bad.problems
    report = scrub_session(session, repair=True)
    assert report.repaired == 1, report.to_dict()
    assert all(c.ok for c in verify_session(session).values())

    # the evidence --delete-source re-checks is each record's own hash
    m = archive_session(session, ["png16", "tiff-lzw"], delete_source=True)
    assert m["source"]["deleted"]
    assert all(c.ok for c in verify_session(session).values())
    assert [f.pixels.tobytes() for f in iter_session_frames(session)] == [f.tobytes() for f in frames]


def test_a_sha256_archive_is_served_as_it_was(session, tmp_path):
    """An index of a sha256 archive: the frames file's digest columns keep their hash's name,
    frames are proved against it on every path, and the file list names it."""
    root = tmp_path / "root"
    (root / "sessions").mkdir(parents=True)
    d = root / "sessions" / session.name
    session.rename(d)
    sid = read_session_meta(d).get("session_id", d.name)
    frames = [f.pixels.copy() for f in iter_session_frames(d)]
    archive_session(d, ["png16", "tiff-lzw"], digest="sha256", delete_source=True)
    m = load_manifest(d)
    proof = frame_proof(m["frames"])
    assert proof.name == "sha256"
    # the png16 copy rots: every frame must come from tiff-lzw, proved by the manifest's sha256
    flip_in_image_entry(next((d / "archive" / "png16").glob("*.zip")))
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        for n in (0, 3):
            r = c.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw", "palette": "gray"})
            assert r.status_code == 200 and r.content == frames[n].astype("<u2").tobytes()
            fast = c.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw"})
            assert fast.content == r.content and fast.headers["etag"] == r.headers["etag"]
        files = {a["format"]: a["files"] for a in c.get(f"/api/v1/sessions/{sid}").json()["archives"]}
        rec = files["tiff-lzw"][0]
        assert rec["sha256"] and "blake3" not in rec
        body = c.get(rec["url"])
        assert body.status_code == 200 and hashlib.sha256(body.content).hexdigest() == rec["sha256"]
        assert body.headers["etag"] == f'"{rec["sha256"]}"'
        damage = c.get("/healthz").json()
    assert damage["status"] == "degraded"  # the rotten png16 frame was reported, not served


def test_an_unknown_digest_is_refused_before_any_work(session):
    with pytest.raises(ArchiveError, match="md5"):
        archive_session(session, ["png16"], digest="md5")
    assert not (session / "archive").exists()
    from thermcap.cli import cli

    out = CliRunner().invoke(cli, ["archive", str(session), "--digest", "md5"])
    assert out.exit_code == 2 and "md5" in out.output and not (session / "archive").exists()
