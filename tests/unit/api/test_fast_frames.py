"""The lean frame path gives exactly what the full route gives. The full route is reached with
the same request plus a parameter png16 and raw ignore, so every answer is compared with it:
the bytes, the ETag, a 304, HEAD. A token that does not pass, an Origin header or a damaged copy
go to the full application, which says 401 or serves another verified copy."""

from __future__ import annotations

import hashlib

import imagecodecs
import numpy as np
import pytest
from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.recorder.storage.reader import iter_session_frames

SID = "s-archived"


def _full(client, n, fmt, **headers):
    return client.get(f"/api/v1/sessions/{SID}/frames/{n}", params={"format": fmt, "palette": "gray"},
                      headers=headers)


@pytest.mark.parametrize("fmt", ["png16", "raw"])
def test_the_same_answer_as_the_route(client, root, fmt):
    fast = client.app.state.fast_frames
    before = fast.served
    frames = [f.pixels for f in iter_session_frames(root / "sessions" / SID)]
    for n in (0, 7, len(frames) - 1):
        a = client.get(f"/api/v1/sessions/{SID}/frames/{n}", params={"format": fmt})
        b = _full(client, n, fmt)
        assert a.status_code == b.status_code == 200
        assert a.content == b.content and a.headers["etag"] == b.headers["etag"]
        for h in ("content-type", "cache-control", "x-width", "x-height", "x-dtype"):
            assert a.headers.get(h) == b.headers.get(h), h
        if fmt == "raw":
            assert np.array_equal(np.frombuffer(a.content, "<u2").reshape(frames[n].shape), frames[n])
        again = client.get(f"/api/v1/sessions/{SID}/frames/{n}", params={"format": fmt},
                           headers={"If-None-Match": a.headers["etag"]})
        assert again.status_code == 304 and again.content == b""
        head = client.head(f"/api/v1/sessions/{SID}/frames/{n}", params={"format": fmt})
        assert head.status_code == 200 and head.content == b"" and head.headers["etag"] == a.headers["etag"]
    assert fast.served >= before + 9  # answered here, not by the route
    if fmt == "raw":  # proved against the frame summary's band CRC-32s (the archive has one)
        assert fast.raw_checked["crc32"] >= 3


def test_raw_counts_that_fail_the_band_checksums_are_not_served(client, root, monkeypatch):
    """A decoder bug (here: one count off in the PNG's decode) is caught by the summary's band
    CRC-32s: the frame comes from the next copy that proves itself, bit-exact."""
    import thermcap.api.fast_frames as ff

    frames = [f.pixels for f in iter_session_frames(root / "sessions" / SID)]
    real = ff.decode_up_png

    def off_by_one(data):
        px = real(data)
        if px is not None:
            px = px.copy()
            px[px.shape[0] - 1, 0] ^= 1
        return px

    monkeypatch.setattr(ff, "decode_up_png", off_by_one)
    fast = client.app.state.fast_frames
    before = dict(fast.raw_from)
    r = client.get(f"/api/v1/sessions/{SID}/frames/5", params={"format": "raw"})
    assert r.status_code == 200
    assert np.array_equal(np.frombuffer(r.content, "<u2").reshape(frames[5].shape), frames[5])
    assert fast.raw_from["png-up"] == before.get("png-up", 0)  # the wrong counts were not served


def test_a_frame_out_of_range_or_an_unknown_session_is_the_routes_404(client):
    assert client.get(f"/api/v1/sessions/{SID}/frames/99999").status_code == 404
    assert client.get("/api/v1/sessions/nope/frames/0").status_code == 404


def test_tokens_cors_and_damage_go_to_the_full_application(tmp_path):
    from tests.support.api_data import make_root

    root = make_root(tmp_path)
    settings = Settings(root=root, tokens={"r" * 32: frozenset({"read"}), "w" * 32: frozenset({"write"})},
                        rescan_interval_s=0)
    with TestClient(create_app(settings)) as c:
        fast = c.app.state.fast_frames
        assert c.get(f"/api/v1/sessions/{SID}/frames/1").status_code == 401
        assert c.get(f"/api/v1/sessions/{SID}/frames/1",
                     headers={"Authorization": "Bearer " + "w" * 32}).status_code == 403
        ok = c.get(f"/api/v1/sessions/{SID}/frames/1", headers={"Authorization": "Bearer " + "r" * 32})
        assert ok.status_code == 200 and fast.served == 1
        cors = c.get(f"/api/v1/sessions/{SID}/frames/1",
                     headers={"Authorization": "Bearer " + "r" * 32, "Origin": "http://example.org"})
        assert cors.status_code == 200 and cors.headers.get("access-control-allow-origin") and fast.served == 1
        zip_path = next((root / "sessions" / SID / "archive" / "png16").glob("*.zip"))
        data = bytearray(zip_path.read_bytes())
        want = hashlib.sha256(ok.content).hexdigest()
        at = bytes(data).find(ok.content[100:140])
        data[at] ^= 0xFF  # frame 1's PNG, in the archive on disk
        zip_path.write_bytes(bytes(data))
        served = fast.served
        raw = c.get(f"/api/v1/sessions/{SID}/frames/1", params={"format": "raw"},
                    headers={"Authorization": "Bearer " + "r" * 32})
        assert raw.status_code == 200 and fast.served == served  # the full path: another verified copy
        png = c.get(f"/api/v1/sessions/{SID}/frames/1", headers={"Authorization": "Bearer " + "r" * 32})
        assert png.status_code == 200 and fast.served == served  # re-encoded from a verified copy
        assert np.array_equal(imagecodecs.png_decode(png.content), np.frombuffer(raw.content, "<u2").reshape(
            int(raw.headers["x-height"]), int(raw.headers["x-width"])))
        assert hashlib.sha256(ok.content).hexdigest() == want
        assert c.get("/healthz").json() == {"status": "degraded"}  # what and where only with a token
        assert c.get("/healthz", headers={"Authorization": "Bearer " + "r" * 32}).json()["damaged_copies_seen"] >= 1


def test_raw_from_thermcaps_own_png_then_the_strips_then_libpng(tmp_path, monkeypatch):
    """Raw counts come from the PNG's IDAT where thermcap wrote it (rows filtered Up). A PNG
    libpng wrote (as thermcap did before it wrote its own; its filters vary by row) falls to
    the tiff-lzw strips, and a damaged strip to libpng: each answer proved by its sha256."""
    import tifffile

    from thermcap.archive.archiver import archive_session
    from thermcap.archive.codecs import Png16
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource

    for sid, writer in (("ours", "up-libdeflate"), ("libpng", "libpng")):
        Recorder(SimSource(width=160, height=150, frames=12, paced=False, seed=8), tmp_path, session_id=sid,
                 analysis=False).run()
        with monkeypatch.context() as m:
            m.setattr(Png16.__init__, "__defaults__", (4, writer))  # the archive's png16 writer
            archive_session(tmp_path / "sessions" / sid, ["png16", "tiff-lzw"], delete_source=False)
    frames = [f.pixels.copy() for f in iter_session_frames(tmp_path / "sessions" / "ours")]
    tif = next((tmp_path / "sessions" / "libpng" / "archive" / "tiff-lzw").glob("*.tif"))
    with tifffile.TiffFile(tif) as t:
        off, n = t.pages[3].dataoffsets[1], t.pages[3].databytecounts[1]
    data = bytearray(tif.read_bytes())
    data[off + n // 2] ^= 0x5A  # frame 3's second strip
    tif.write_bytes(bytes(data))
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as c:
        fast = c.app.state.fast_frames
        for sid in ("ours", "libpng"):
            for k, want in enumerate(frames):
                r = c.get(f"/api/v1/sessions/{sid}/frames/{k}", params={"format": "raw"})
                assert r.status_code == 200
                assert np.array_equal(np.frombuffer(r.content, "<u2").reshape(want.shape), want), (sid, k)
        assert fast.served == 2 * len(frames)  # frame 3 too: libpng's decode of its PNG proved itself
        assert fast.raw_from == {"png-up": len(frames), "strips": len(frames) - 1, "libpng": 1}


def test_a_rewritten_copy_of_the_same_size_is_read_afresh():
    """scrub --repair may rewrite a ZIP at its old size; the manifest's sha256 tells the copies
    apart, so offsets read from the old one are never used for the new one."""
    from thermcap.archive.reading.zip_directory import ZipIndexCache

    def reader(data):
        return lambda a, b: data[a:b]

    import io
    import zipfile

    def zip_bytes(names):
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
            for n in names:
                zf.writestr(n + ".png", b"x" * 10)
                zf.writestr(n + ".json", b"{}")
        return buf.getvalue()

    a, b = zip_bytes(["aa"]), zip_bytes(["bb"])
    assert len(a) == len(b)
    cache = ZipIndexCache()
    first = cache.get("k.zip", len(a), reader(a), "sha-a")
    second = cache.get("k.zip", len(b), reader(b), "sha-b")
    assert first is not second and cache.get("k.zip", len(a), reader(a), "sha-a") is first


def test_raw_counts_of_a_session_not_archived_come_from_its_segment_as_the_route_gives_them(client, root):
    """No png16 copy: the counts come from the MCAP segment through the application's own chunk
    cache. The first frame of a chunk is read on a thread, its neighbours in place; either way
    the answer is the route's, byte for byte, ETag, 304 and HEAD included. A PNG of such a
    session (made on request) stays with the route."""
    sid = "s-mcap-only"
    fast = client.app.state.fast_frames
    frames = [f.pixels.copy() for f in iter_session_frames(root / "sessions" / sid)]
    served, from_mcap = fast.served, fast.raw_from["mcap"]
    for n in (0, 1, 2, len(frames) - 1):
        a = client.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw"})
        b = client.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw", "palette": "gray"})
        assert a.status_code == b.status_code == 200
        assert a.content == b.content and a.headers["etag"] == b.headers["etag"]
        for h in ("content-type", "cache-control", "x-width", "x-height", "x-dtype", "content-length"):
            assert a.headers.get(h) == b.headers.get(h), h
        assert np.array_equal(np.frombuffer(a.content, "<u2").reshape(frames[n].shape), frames[n])
        again = client.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw"},
                           headers={"If-None-Match": a.headers["etag"]})
        assert again.status_code == 304 and again.content == b""
        head = client.head(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw"})
        assert head.status_code == 200 and head.content == b"" and head.headers["etag"] == a.headers["etag"]
    assert fast.served == served + 12 and fast.raw_from["mcap"] == from_mcap + 12
    png = client.get(f"/api/v1/sessions/{sid}/frames/3")
    assert png.status_code == 200 and fast.served == served + 12
    assert np.array_equal(imagecodecs.png_decode(png.content), frames[3])


def test_a_damaged_segment_chunk_goes_to_the_full_application(tmp_path):
    """A chunk that fails its CRC is never served from here: the route answers, as it always did
    (and counts the damage)."""
    from tests.support.api_data import make_root
    from thermcap.recorder.storage.chunks import SegmentIndex

    root = make_root(tmp_path)
    sid = "s-mcap-only"
    seg = sorted((root / "sessions" / sid).glob("*.mcap"))[0]
    index = SegmentIndex.load(seg)
    assert index is not None
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        fast = c.app.state.fast_frames
        data = bytearray(seg.read_bytes())  # damaged after it was indexed, before any frame was read
        data[int(index.offsets[0]) + int(index.lengths[0]) // 2] ^= 0xFF  # inside the first chunk's records
        seg.write_bytes(bytes(data))
        r = c.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "raw"})
        route = c.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "raw", "palette": "gray"})
        assert fast.served == 0  # not from here
        assert r.status_code == route.status_code != 200 and r.json() == route.json()
        assert c.get("/healthz").json()["damaged_copies_seen"] >= 1


def test_a_session_whose_segments_were_deleted_once_archived_is_served_by_the_route(tmp_path):
    """No png16 copy and no segment left (archived as hdf5, source deleted): the index still
    names each frame's segment, but the counts come from the route's other copies."""
    from thermcap.archive.archiver import archive_session
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource

    Recorder(SimSource(width=96, height=64, frames=8, paced=False, seed=9), tmp_path, session_id="gone",
             analysis=False).run()
    frames = [f.pixels.copy() for f in iter_session_frames(tmp_path / "sessions" / "gone")]
    archive_session(tmp_path / "sessions" / "gone", ["hdf5"], delete_source=True)
    assert not list((tmp_path / "sessions" / "gone").glob("*.mcap"))
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as c:
        r = c.get("/api/v1/sessions/gone/frames/5", params={"format": "raw"})
        assert r.status_code == 200 and c.app.state.fast_frames.served == 0
        assert np.array_equal(np.frombuffer(r.content, "<u2").reshape(frames[5].shape), frames[5])
