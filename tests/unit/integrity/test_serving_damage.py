"""Defect 8: the API served damaged bytes as good. One flipped bit in a png16 ZIP entry."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames


def _flip_entry(path, n: int) -> None:
    """Flip one bit in the middle of image entry n of a stored ZIP."""
    with zipfile.ZipFile(path) as zf:
        info = [i for i in zf.infolist() if i.filename.endswith(".png")][n]
    data = bytearray(path.read_bytes())
    with open(path, "rb") as f:
        f.seek(info.header_offset + 26)
        name_len, extra_len = np.frombuffer(f.read(4), "<u2")
    start = info.header_offset + 30 + int(name_len) + int(extra_len)
    data[start + info.file_size // 2] ^= 0x10
    path.write_bytes(bytes(data))


@pytest.fixture
def root(tmp_path):
    Recorder(SimSource(width=96, height=64, frames=20, paced=False, start_time_ns=1_800_000_000_000_000_000),
             tmp_path, session_id="s", analysis=False).run()
    return tmp_path


@pytest.mark.parametrize("keep_source", [True, False])
def test_a_damaged_png_entry_is_never_served_and_another_copy_is(root, keep_source):
    session = root / "sessions" / "s"
    truth = [np.array(f.pixels) for f in iter_session_frames(session)]
    archive_session(session, ["png16", "hdf5"], delete_source=not keep_source)
    zpath = session / "archive" / "png16" / "0000.zip"
    _flip_entry(zpath, 3)
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        for fmt in ("png16", "raw", "tiff", "preview"):
            r = c.get("/api/v1/sessions/s/frames/3", params={"format": fmt})
            assert r.status_code == 200, (fmt, r.text)
        raw = c.get("/api/v1/sessions/s/frames/3", params={"format": "raw"}).content
        assert raw == truth[3].astype("<u2").tobytes()
        png = c.get("/api/v1/sessions/s/frames/3", params={"format": "png16"}).content
        import imagecodecs

        assert np.array_equal(imagecodecs.png_decode(png), truth[3])
        health = c.get("/healthz").json()
        assert health["status"] == "degraded"
        assert health["damaged_copies_seen"] >= 1
        assert "png16" in health["recent"][0]["copy"]
        metrics = c.get("/metrics").text
        assert 'thermcap_damaged_copies_total{copy="png16"}' in metrics
        # the damaged file itself is not sent under the manifest's ETag
        r = c.get("/api/v1/sessions/s/archives/png16/0000.zip")
        assert r.status_code == 503
        r = c.get("/api/v1/sessions/s/archives/hdf5/s.h5")
        assert r.status_code == 200


def test_when_every_copy_is_damaged_the_answer_is_503_not_bad_bytes(root):
    session = root / "sessions" / "s"
    archive_session(session, ["png16"], delete_source=True)
    _flip_entry(session / "archive" / "png16" / "0000.zip", 2)
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        for fmt in ("png16", "raw"):
            r = c.get("/api/v1/sessions/s/frames/2", params={"format": fmt})
            assert r.status_code == 503
            # the answer names the damaged copy and what is wrong with it, not only the deleted source
            assert "png16:0000.zip" in r.json()["error"], r.json()
        assert c.get("/api/v1/sessions/s/frames/1", params={"format": "raw"}).status_code == 200


def test_a_damaged_sidecar_entry_is_never_served_and_another_copy_is(root):
    session = root / "sessions" / "s"
    truth = [f.sidecar_dict() for f in iter_session_frames(session)]
    archive_session(session, ["png16", "hdf5"], delete_source=True)
    zpath = session / "archive" / "png16" / "0000.zip"
    with zipfile.ZipFile(zpath) as zf:
        info = [i for i in zf.infolist() if i.filename.endswith(".json")][4]
    data = bytearray(zpath.read_bytes())
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    at = data.index(b'"frame_index"', start)  # change a key the sidecar must keep
    data[at + 2] ^= 0x01
    zpath.write_bytes(bytes(data))
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        r = c.get("/api/v1/sessions/s/frames/4/metadata")
        assert r.status_code == 200
        assert r.json() == truth[4]
        assert c.get("/healthz").json()["damaged_copies_seen"] >= 1


def test_a_copy_scrub_marked_damaged_still_serves_its_intact_entries(root):
    """A damaged part hides only itself. With the source gone and png16 the only copy, scrub marks
    png16 damaged for one bad entry; the other frames are still in intact entries of that copy,
    and each is checked against the manifest's hash before it goes out: served, bit-exact. The
    damaged frame alone answers 503. (Before, the whole copy was hidden: every frame 503.)"""
    from thermcap.archive.manifest import load_manifest
    from thermcap.archive.scrub import scrub_session

    session = root / "sessions" / "s"
    truth = [np.array(f.pixels) for f in iter_session_frames(session)]
    archive_session(session, ["png16"], delete_source=True)
    _flip_entry(session / "archive" / "png16" / "0000.zip", 2)
    scrub_session(session)
    assert load_manifest(session)["formats"]["png16"].get("damaged"), "scrub marked the copy"
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        assert c.get("/api/v1/sessions/s/frames/2", params={"format": "raw"}).status_code == 503
        for i in (0, 1, 3, 19):
            r = c.get(f"/api/v1/sessions/s/frames/{i}", params={"format": "raw"})
            assert r.status_code == 200, (i, r.text)
            assert r.content == truth[i].astype("<u2").tobytes()
