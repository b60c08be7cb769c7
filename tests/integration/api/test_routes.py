"""The API over real HTTP on 127.0.0.1: catalog, frames bit-exact, Range/ETag, export, errors."""

from __future__ import annotations

import io
import zipfile

import httpx
import imagecodecs
import numpy as np
import pytest
import tifffile
from mcap.reader import make_reader

from tests.support.api_data import H, W
from thermcap.recorder.icd.topics import decode_image
from thermcap.recorder.storage.reader import iter_session_frames


@pytest.fixture(scope="module")
def client(server):
    with httpx.Client(base_url=server.url, timeout=30) as c:
        yield c


@pytest.fixture(scope="module")
def source(data_root):
    return {sid: list(iter_session_frames(data_root / "sessions" / sid))
            for sid in ("s-archived", "s-crossover", "s-mcap-only")}


def test_health_and_ready(client):
    health = client.get("/healthz").json()
    assert health["status"] == "ok"
    assert health["damaged_copies_seen"] == 0
    assert client.get("/readyz").json()["sessions"] == 3


def test_sessions_list_filters_and_cursor(client):
    items = client.get("/api/v1/sessions").json()["items"]
    assert [s["id"] for s in items] == ["s-mcap-only", "s-crossover", "s-archived"]  # newest first
    assert items[0]["start"].endswith("Z")
    assert len(items[0]["start"].split(".")[1]) == 10  # ns + Z
    assert next(s["id"] for s in client.get("/api/v1/sessions",
                                            params={"sort": "start"}).json()["items"]) == "s-archived"
    crossover = client.get("/api/v1/sessions", params={"max_grade": 0.3}).json()["items"]
    assert [s["id"] for s in crossover] == ["s-crossover"]
    assert [s["id"] for s in client.get("/api/v1/sessions",
                                        params={"sensor": "OTHERCAM"}).json()["items"]] == ["s-mcap-only"]
    assert [s["id"] for s in client.get("/api/v1/sessions",
                                        params={"slew_to_cue": False}).json()["items"]] == ["s-crossover"]
    r = client.get("/api/v1/sessions", params={"start": "2027-01-15T08:00:00Z", "end": "2027-01-15T08:10:00Z"})
    assert r.status_code == 200
    seen, cursor = [], None
    while True:
        page = client.get("/api/v1/sessions", params={"limit": 1, **({"cursor": cursor} if cursor else {})}).json()
        seen += [s["id"] for s in page["items"]]
        cursor = page["next_cursor"]
        if not cursor:
            break
    assert seen == ["s-mcap-only", "s-crossover", "s-archived"]


def test_page_size_is_capped(client):
    r = client.get("/api/v1/sessions/s-crossover/frames", params={"limit": 100000})
    assert r.status_code == 200
    assert len(r.json()["items"]) == 120  # cap is 1000 > 120 frames


def test_session_detail_has_archives_and_coverage(client):
    d = client.get("/api/v1/sessions/s-archived").json()
    assert d["frames"] == 60
    assert d["width"] == W
    assert d["height"] == H
    fmts = {a["format"]: a for a in d["archives"]}
    assert set(fmts) == {"png16", "hdf5", "jxl"}
    assert all(a["verified"] for a in fmts.values())
    assert fmts["png16"]["files"][0]["url"].endswith("/archives/png16/0000.zip")
    assert len(d["coverage"]) == 1
    assert d["gaps"] == []
    assert [s["name"] for s in d["segments"]] == ["0000.mcap", "0001.mcap"]


def test_frame_list_filters(client):
    low = client.get("/api/v1/sessions/s-crossover/frames", params={"max_grade": 0.3}).json()["items"]
    assert low
    assert all(f["thermal_contrast_grade"] <= 0.3 for f in low)
    assert 15 < len(low) < 120
    page = client.get("/api/v1/sessions/s-archived/frames", params={"limit": 25}).json()
    assert len(page["items"]) == 25
    assert page["next_cursor"]
    nxt = client.get("/api/v1/sessions/s-archived/frames", params={"limit": 25, "cursor": page["next_cursor"]}).json()
    assert nxt["items"][0]["index"] == 25


@pytest.mark.parametrize("sid", ["s-archived", "s-mcap-only"])
def test_frames_are_bit_exact_in_every_format(client, source, sid):
    for n in (0, 17, len(source[sid]) - 1):
        exp = source[sid][n].pixels
        raw = client.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "raw"})
        assert raw.headers["content-type"] == "application/octet-stream"
        assert np.array_equal(np.frombuffer(raw.content, "<u2").reshape(H, W), exp)
        png = client.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "png16"})
        assert png.headers["content-type"] == "image/png"
        dec = imagecodecs.png_decode(png.content)
        assert dec.dtype == np.uint16
        assert np.array_equal(dec, exp)
        tif = client.get(f"/api/v1/sessions/{sid}/frames/{n}", params={"format": "tiff"})
        assert np.array_equal(tifffile.imread(io.BytesIO(tif.content)), exp)


def test_png16_of_an_archived_session_is_the_archived_file(client, data_root):
    body = client.get("/api/v1/sessions/s-archived/frames/3", params={"format": "png16"}).content
    with zipfile.ZipFile(data_root / "sessions" / "s-archived" / "archive" / "png16" / "0000.zip") as zf:
        pngs = [n for n in zf.namelist() if n.endswith(".png")]
        assert body == zf.read(pngs[3])


def test_celsius_tiff_and_temperature_use_the_model(client, source):
    exp = source["s-archived"][5].pixels
    t = tifffile.imread(io.BytesIO(client.get("/api/v1/sessions/s-archived/frames/5",
                                              params={"format": "celsius-tiff"}).content))
    assert t.dtype == np.float32
    bad = np.isnan(t)  # the session's bad pixels have no temperature (issue 37)
    assert 0 < bad.sum() < 100
    assert np.allclose(t[~bad], (exp * 0.036 - 40)[~bad], atol=1e-4)
    p = client.get("/api/v1/sessions/s-archived/frames/5/temperature", params={"x": 10, "y": 20}).json()
    assert p["counts"] == int(exp[20, 10])
    assert p["celsius"] == pytest.approx(exp[20, 10] * 0.036 - 40, abs=1e-3)


@pytest.mark.parametrize("palette", ["ironbow", "gray", "turbo"])
def test_preview_is_8_bit_colour(client, palette):
    r = client.get("/api/v1/sessions/s-archived/frames/0",
                   params={"format": "preview", "palette": palette, "min": 0, "max": 50})
    img = imagecodecs.png_decode(r.content)
    assert img.dtype == np.uint8
    assert img.shape[0] == H and img.shape[1] > W and img.shape[2] == 3  # the picture, then its colour bar
    picture = img[:, :W]
    assert (palette == "gray") == bool(np.all(picture[..., 0] == picture[..., 1]))


def test_metadata_is_the_sidecar(client, source):
    for sid in ("s-archived", "s-mcap-only"):
        assert client.get(f"/api/v1/sessions/{sid}/frames/4/metadata").json() == source[sid][4].sidecar_dict()


def test_archive_download_range_etag_cors(client, data_root):
    path = data_root / "sessions" / "s-archived" / "archive" / "png16" / "0001.zip"
    whole = path.read_bytes()
    url = "/api/v1/sessions/s-archived/archives/png16/0001.zip"
    r = client.get(url, headers={"Origin": "https://app.foxglove.dev"})
    assert r.status_code == 200
    assert r.content == whole
    assert r.headers["accept-ranges"] == "bytes"
    assert r.headers["content-length"] == str(len(whole))
    etag = r.headers["etag"]
    assert etag.startswith('"')
    assert len(etag) == 66
    exposed = r.headers["access-control-expose-headers"].lower()
    assert "content-range" in exposed
    assert "etag" in exposed
    assert "accept-ranges" in exposed
    r = client.get(url, headers={"Range": "bytes=100-199"})
    assert r.status_code == 206
    assert r.content == whole[100:200]
    assert r.headers["content-range"] == f"bytes 100-199/{len(whole)}"
    r = client.get(url, headers={"Range": "bytes=-50"})
    assert r.status_code == 206
    assert r.content == whole[-50:]
    r = client.get(url, headers={"Range": f"bytes={len(whole) - 10}-"})
    assert r.content == whole[-10:]
    r = client.get(url, headers={"Range": f"bytes={len(whole)}-"})
    assert r.status_code == 416
    assert r.headers["content-range"] == f"bytes */{len(whole)}"
    assert client.get(url, headers={"If-None-Match": etag}).status_code == 304
    assert client.head(url).headers["content-length"] == str(len(whole))
    listing = client.get("/api/v1/sessions/s-archived/archives/png16").json()
    assert [f["path"] for f in listing["files"]] == ["0000.zip", "0001.zip"]


def test_export_mcap_range_and_topics(client, source):
    frames = source["s-archived"]
    t_start, t_end = frames[10].log_time, frames[40].log_time
    from thermcap.recorder.icd.names import iso_utc

    r = client.get("/api/v1/sessions/s-archived/export.mcap", params={"start": iso_utc(t_start), "end": iso_utc(t_end)})
    assert r.status_code == 200
    reader = make_reader(io.BytesIO(r.content))
    summary = reader.get_summary()
    assert summary.chunk_indexes
    assert summary.statistics.message_count > 0
    imgs = [(m.log_time, decode_image(m.data)[1]) for _, _, m in reader.iter_messages(topics=["/thermal/image"])]
    assert [t for t, _ in imgs] == [f.log_time for f in frames[10:40]]
    assert all(np.array_equal(px, f.pixels) for (_, px), f in zip(imgs, frames[10:40], strict=True))
    whole = make_reader(io.BytesIO(client.get("/api/v1/sessions/s-archived/export.mcap").content))
    assert sum(1 for _ in whole.iter_messages(topics=["/thermal/image"])) == 60
    only = make_reader(io.BytesIO(client.get("/api/v1/sessions/s-archived/export.mcap",
                                             params={"topics": "/thermal/metadata"}).content))
    assert {c.topic for c in only.get_summary().channels.values()} == {"/thermal/metadata"}


@pytest.mark.parametrize("path,status", [
    ("/api/v1/sessions/nope", 404),
    ("/api/v1/sessions/s-archived/frames/60", 404),
    ("/api/v1/sessions/s-archived/frames/-1", 404),
    ("/api/v1/sessions/s-archived/frames/x", 422),
    ("/api/v1/sessions/s-archived/frames/0?format=gif", 422),
    ("/api/v1/sessions/s-archived/frames/0?format=preview&min=50&max=10", 400),
    ("/api/v1/sessions/s-archived/frames/0/temperature?x=9999&y=0", 400),
    ("/api/v1/sessions?start=yesterday", 400),
    ("/api/v1/sessions?cursor=@@@", 400),
    ("/api/v1/sessions?limit=0", 400),
    ("/api/v1/sessions/s-archived/archives/tiff-lzw", 404),
    ("/api/v1/sessions/s-archived/export.mcap?start=2027-01-01T00:00:00Z&end=2026-01-01T00:00:00Z", 400),
])
def test_bad_requests_get_json_4xx(client, path, status):
    r = client.get(path)
    assert r.status_code == status, r.text
    assert "error" in r.json()


@pytest.mark.parametrize("path", [
    "/api/v1/sessions/..%2F..%2Fetc/frames/0",
    "/api/v1/sessions/%2Fetc%2Fpasswd",
    "/api/v1/sessions/s-archived/archives/png16/..%2Fmanifest.json",
    "/api/v1/sessions/s-archived/archives/png16/%2Fetc%2Fpasswd",
    "/api/v1/sessions/s-archived/archives/..%2F..%2Fsession.json/x",
    "/api/v1/sessions/s-archived/archives/png16/..",
])
def test_paths_never_escape_the_root(client, path):
    r = client.get(path)
    assert r.status_code in (400, 404)
    assert b"root:" not in r.content
    assert b"session_id" not in r.content


def test_symlink_planted_in_an_archive_is_not_served(client, data_root):
    link = data_root / "sessions" / "s-archived" / "archive" / "png16" / "evil.zip"
    link.symlink_to("/etc/passwd")
    try:
        assert client.get("/api/v1/sessions/s-archived/archives/png16/evil.zip").status_code == 404
    finally:
        link.unlink()


def test_metrics_count_requests(client):
    client.get("/healthz")
    text = client.get("/metrics").text
    assert 'thermcap_http_requests_total{method="GET",route="/healthz",status="200"}' in text


def test_browser_pages_are_served(client):
    assert "thermcap sessions" in client.get("/").text
    assert "contrast grade over the session" in client.get("/ui/sessions/s-archived").text
    t = client.get("/api/v1/sessions/s-crossover/timeline", params={"bins": 10}).json()
    assert len(t["bins"]) == 10
    assert min(b["min"] for b in t["bins"]) < 0.3


def test_the_histogram_the_workbench_draws_leaves_bad_pixels_out(client, source, data_root):
    """Issue 37: the UI's histogram (the workbench asks this route) had spanned -40..550 °C, the
    simulator's dead and hot pixels; the session's listed pixels are in no bin and no edge."""
    from thermcap.recorder.radiometry.session import read_bad_pixel_map

    listed = read_bad_pixel_map(data_root / "sessions" / "s-archived")
    assert listed is not None and listed.any()
    exp = source["s-archived"][5].pixels
    good = exp[~listed].astype(np.float64) * 0.036 - 40
    h = client.get("/api/v1/sessions/s-archived/frames/5/histogram", params={"bins": 16}).json()
    assert h["pixels"] == exp.size - int(listed.sum())
    assert h["edges_c"][0] == pytest.approx(good.min(), abs=1e-3)
    assert h["edges_c"][-1] == pytest.approx(good.max(), abs=1e-3)
    assert sum(h["counts"]) == h["pixels"]
