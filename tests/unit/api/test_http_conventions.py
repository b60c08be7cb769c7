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


@pytest.fixture(scope="module")
def guarded(client):
    """The same data root served with a token, for what an unauthenticated client meets."""
    root = client.app.state.settings.root
    with TestClient(create_app(Settings(root=root, tokens={"conv-token-0123456789": frozenset({"read"})}))) as c:
        yield c


PROBLEM_KEYS = {"type", "title", "status", "detail"}


def _is_problem(r, status):
    assert r.status_code == status, (r.status_code, r.text)
    assert r.headers["content-type"].startswith("application/problem+json"), r.headers["content-type"]
    body = r.json()
    assert set(body) >= PROBLEM_KEYS and body["status"] == status and isinstance(body["detail"], str), body
    return body


def test_every_error_is_one_problem_shape(client, guarded):
    """RFC 9457 problem+json for every error, whoever raised it: a route, FastAPI's validation,
    Starlette's router, a middleware (there were two shapes, ``{"error"}`` and ``{"detail"}``)."""
    _is_problem(client.get("/no/such/route"), 404)
    assert "zz" in _is_problem(client.get("/api/v1/sessions/zz"), 404)["detail"]
    body = _is_problem(client.get("/api/v1/sessions?limit=abc"), 422)
    assert body["problems"][0]["where"] == "query.limit"
    _is_problem(client.post("/api/v1/sessions"), 405)
    _is_problem(client.get("/api/v1/sessions/s-archived/frames/9999"), 404)
    _is_problem(guarded.get("/api/v1/sessions"), 401)
    _is_problem(client.post("/api/v1/index", content=b"x" * (2 << 20), headers={"content-type": "text/plain"}), 413)


def test_allow_says_head_where_get_is(client):
    r = client.post("/api/v1/sessions")
    assert r.status_code == 405
    assert {m.strip() for m in r.headers["allow"].split(",")} == {"GET", "HEAD"}


def test_head_answers_as_the_get_would(client):
    for path in ("/api/v1/sessions", "/api/v1/sessions/s-archived"):
        get, head = client.get(path, headers={"Accept-Encoding": "identity"}), \
            client.head(path, headers={"Accept-Encoding": "identity"})
        assert head.content == b""
        assert head.headers["content-length"] == get.headers["content-length"] == str(len(get.content)), path
        assert head.headers["etag"] == get.headers["etag"], path


def test_an_unauthenticated_browser_can_read_why(guarded):
    r = guarded.get("/api/v1/sessions", headers={"Origin": "http://analysis.example"})
    assert r.status_code == 401 and r.headers.get("access-control-allow-origin") in ("*", "http://analysis.example")


def test_a_clamped_page_says_so(client):
    r = client.get("/api/v1/sessions", params={"limit": 5000})
    assert r.status_code == 200
    assert r.headers["x-limit-clamped"] == "1000"
    assert "x-limit-clamped" not in client.get("/api/v1/sessions", params={"limit": 10}).headers
