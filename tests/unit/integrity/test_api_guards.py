"""Defects 10-12: 500s on bad input, routes open when tokens are set, grade filters that mislead.
In-process (FastAPI TestClient) over real recorded and archived sessions."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest
from fastapi.testclient import TestClient

from tests.support.api_data import make_root
from thermcap.api.app import create_app
from thermcap.api.settings import Settings, _parse_tokens
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.raw import RawSource

READ, WRITE = "integrity-read-token", "integrity-write-token"


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    r = make_root(tmp_path_factory.mktemp("guards"))
    # A uniform scene: the detector runs and finds nothing, so no frame has anything to grade.
    flat = np.full((5, 48, 64), 2000, "<u2").tobytes()
    src = RawSource("flat", width=64, height=48, fps=10, stream=__import__("io").BytesIO(flat))
    Recorder(src, r, session_id="s-no-targets", analysis=True).run()
    return r


@pytest.fixture(scope="module")
def open_client(root):
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        yield c


@pytest.fixture(scope="module")
def locked_client(root):
    tokens = _parse_tokens(f"{READ}=read;{WRITE}=read,write")
    with TestClient(create_app(Settings(root=root, tokens=tokens, rescan_interval_s=0))) as c:
        yield c


def _b64(v) -> str:
    return base64.urlsafe_b64encode(json.dumps(v).encode()).decode().rstrip("=")


@pytest.mark.parametrize("value", [[None, None], ["x"], [{"a": 1}], [1.5, "x"], ["x", 1], [2**70, "a"], [True, "a"]])
@pytest.mark.parametrize("path", ["/api/v1/sessions", "/api/v1/sessions/s-archived/frames"])
def test_malformed_cursors_are_400(open_client, path, value):
    r = open_client.get(path, params={"cursor": _b64(value)})
    assert r.status_code == 400, r.text
    assert "cursor" in r.json()["error"]


def test_a_range_with_thousands_of_digits_is_416(open_client):
    url = "/api/v1/sessions/s-archived/archives/png16/0000.zip"
    r = open_client.get(url, headers={"Range": "bytes=" + "9" * 5000 + "-"})
    assert r.status_code == 416
    r = open_client.get(url, headers={"Range": "bytes=0-" + "9" * 5000})
    assert r.status_code == 416


@pytest.mark.parametrize("path", ["/", "/docs", "/docs/assets/swagger-ui-bundle.js", "/openapi.json",
                                  "/static/common.js",
                                  "/ui/sessions/s-archived", "/api/v1/sessions", "/metrics"])
def test_tokens_guard_every_page_and_document(locked_client, path):
    r = locked_client.get(path, follow_redirects=False)
    assert r.status_code in (401, 303), (path, r.status_code)
    r = locked_client.get(path, headers={"Authorization": f"Bearer {READ}"})
    assert r.status_code == 200, path


def test_health_checks_stay_open(locked_client):
    assert locked_client.get("/healthz").status_code == 200
    assert locked_client.get("/readyz").status_code == 200


def test_a_browser_signs_in_once_by_form_and_the_cookie_opens_the_pages(root):
    tokens = _parse_tokens(f"{READ}=read")
    with TestClient(create_app(Settings(root=root, tokens=tokens, rescan_interval_s=0))) as c:
        r = c.get("/", headers={"Accept": "text/html"}, follow_redirects=False)
        assert r.status_code == 303
        assert r.headers["location"] == "/login"
        assert c.post("/login", data={"token": "not-the-token-at-all"}, follow_redirects=False).status_code == 401
        r = c.post("/login", data={"token": READ}, follow_redirects=False)
        assert r.status_code == 303
        assert "httponly" in r.headers["set-cookie"].lower()
        assert c.get("/").status_code == 200
        assert c.get("/api/v1/sessions").status_code == 200


def test_the_docs_token_example_is_accepted():
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[3] / "docs" / "how-to" / "retrieving.md").read_text()
    example = re.search(r'THERMCAP_TOKENS="([^"]+)"', page)[1]
    assert _parse_tokens(example)


def test_a_short_token_is_refused_for_its_length_not_its_scopes():
    with pytest.raises(ValueError) as exc:
        _parse_tokens("tokA=read;long-enough-token=read,write")
    assert "characters" in str(exc.value)
    assert "scope" not in str(exc.value)
    assert "tokA" not in str(exc.value)  # never echo a secret


def test_frames_with_nothing_to_grade_are_not_crossovers(open_client):
    """Defect 12: no-target frames counted as grade 0.0, so max_grade=0.3 found them."""
    ids = [s["id"] for s in open_client.get("/api/v1/sessions", params={"max_grade": 0.3}).json()["items"]]
    assert "s-no-targets" not in ids
    frames = open_client.get("/api/v1/sessions/s-no-targets/frames", params={"max_grade": 0.3}).json()["items"]
    assert frames == []
    all_frames = open_client.get("/api/v1/sessions/s-no-targets/frames").json()["items"]
    assert len(all_frames) == 5
    assert {f["thermal_contrast_grade"] for f in all_frames} == {None}
