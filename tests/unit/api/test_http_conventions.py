"""HTTP's conventions: gzip for JSON, weak ETags and 304s compared by RFC 9110's weak rule, HEAD
wherever GET is, hand-named operationIds, described tags and the content types really served."""

from __future__ import annotations

import gzip

import pytest
from fastapi.testclient import TestClient

from tests.support.api_data import make_root
from thermcap.api.app import create_app
from thermcap.api.http_conventions import etag_matches
from thermcap.api.settings import Settings


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    root = make_root(tmp_path_factory.mktemp("conv"))
    with TestClient(create_app(Settings(root=root))) as c:
        yield c


@pytest.mark.parametrize("inm,etag,match", [
    ('W/"a"', '"a"', True), ('"a"', 'W/"a"', True), ('W/"a"', 'W/"a"', True), ('"b", W/"a"', '"a"', True),
    ("*", '"x"', True), ('"b"', '"a"', False), (None, '"a"', False), ('W/"ab"', '"a"', False),
])
def test_the_weak_comparison(inm, etag, match):
    assert etag_matches(inm, etag) is match
    assert etag_matches(inm.encode() if inm else None, etag.encode()) is match


def test_json_is_gzipped_when_asked_and_large(client):
    r = client.get("/api/v1/sessions/s-crossover/frames", headers={"Accept-Encoding": "gzip"})
    assert r.status_code == 200 and r.headers["content-encoding"] == "gzip"
    assert int(r.headers["content-length"]) < len(r.content)  # httpx undid the gzip
    assert r.json()["items"][0]["index"] == 0
    plain = client.get("/api/v1/sessions/s-crossover/frames", headers={"Accept-Encoding": "identity"})
    assert "content-encoding" not in plain.headers and plain.json() == r.json()
    small = client.get("/healthz", headers={"Accept-Encoding": "gzip"})
    assert "content-encoding" not in small.headers


def test_json_has_a_weak_etag_and_a_304(client):
    r = client.get("/api/v1/sessions")
    etag = r.headers["etag"]
    assert etag.startswith('W/"')
    assert client.get("/api/v1/sessions", headers={"If-None-Match": etag}).status_code == 304
    assert client.get("/api/v1/sessions", headers={"If-None-Match": etag[2:]}).status_code == 304  # weak rule
    assert client.get("/api/v1/sessions", headers={"If-None-Match": 'W/"other"'}).status_code == 200


def test_a_frame_etag_matches_weakly_too(client):
    r = client.get("/api/v1/sessions/s-archived/frames/0?format=tiff")
    etag = r.headers["etag"]
    assert client.get("/api/v1/sessions/s-archived/frames/0?format=tiff",
                      headers={"If-None-Match": f"W/{etag}"}).status_code == 304


@pytest.mark.parametrize("path", ["/api/v1/sessions", "/api/v1/sessions/s-archived", "/api/v1/jobs", "/metrics",
                                  "/api/v1/sessions/s-archived/events", "/api/v1/sessions/s-archived/zarr/.zgroup"])
def test_head_wherever_get_is(client, path):
    get, head = client.get(path), client.head(path)
    assert head.status_code == get.status_code == 200, path
    assert head.content == b"" and head.headers["content-type"] == get.headers["content-type"]


def test_the_openapi_document_says_what_is_served(client):
    doc = client.get("/openapi.json").json()
    ids = [op["operationId"] for p in doc["paths"].values() for op in p.values()]
    assert len(ids) == len(set(ids))
    assert {"list_sessions", "get_session", "get_frame", "list_jobs", "get_job", "export_mcap",
            "download_archive_file", "get_zarr_key"} <= set(ids)
    assert not [i for i in ids if "_api_v1_" in i]  # none of FastAPI's generated names
    assert all(t.get("description") for t in doc["tags"])
    assert set(doc["paths"]["/metrics"]["get"]["responses"]["200"]["content"]) == {"text/plain; version=0.0.4"}
    download = doc["paths"]["/api/v1/sessions/{session_id}/archives/{fmt}/{name}"]["get"]
    assert set(download["responses"]["200"]["content"]) == {"application/octet-stream"}
    r = client.get("/metrics")
    assert r.headers["content-type"].startswith("text/plain")


def test_gzip_is_undone_exactly(client):
    r = client.get("/api/v1/sessions/s-crossover/frames", headers={"Accept-Encoding": "gzip"})
    raw = client.stream("GET", "/api/v1/sessions/s-crossover/frames", headers={"Accept-Encoding": "gzip"})
    with raw as resp:
        body = b"".join(resp.iter_raw())
    assert gzip.decompress(body) == r.content
