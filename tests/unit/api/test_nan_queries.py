"""Issue 36: NaN query values gave 500 on profile and histogram and a bare ``NaN`` in isotherm's
JSON. Every API query value is checked: 422 (or 400 for a tool's own syntax), never 500."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings

BAD = [
    ("frames/0/histogram", {"min": "nan"}),
    ("frames/0/histogram", {"max": "inf"}),
    ("frames/0/isotherm", {"above": "nan"}),
    ("frames/0/isotherm", {"below": "-inf"}),
    ("frames/0/profile", {"line": "nan,nan,nan,nan"}),
    ("frames/0/profile", {"line": "0,0,1e300,5"}),
    ("frames/0/measure", {"tool": "spot:nan,3"}),
    ("frames/0/measure", {"tool": "line:0,0,inf,2"}),
    ("frames/0", {"format": "preview", "min": "nan", "max": "40"}),
]


@pytest.fixture(scope="module")
def client(data_root):
    with TestClient(create_app(Settings(root=data_root, tokens={}, rescan_interval_s=0))) as c:
        yield c


@pytest.mark.parametrize(("route", "params"), BAD, ids=[f"{r}?{p}" for r, p in BAD])
def test_a_non_finite_query_value_is_a_client_error(client, route, params):
    r = client.get(f"/api/v1/sessions/s-archived/{route}", params=params)
    assert r.status_code in (400, 422), (r.status_code, r.text[:300])
    json.loads(r.text)  # strict JSON: no bare NaN


def test_search_rejects_nan(client):
    assert client.get("/api/v1/frames", params={"min_target_c": "nan"}).status_code == 422


def test_an_isotherm_answers_strict_json(client):
    r = client.get("/api/v1/sessions/s-archived/frames/0/isotherm", params={"above": "20"})
    assert r.status_code == 200
    json.loads(r.text, parse_constant=lambda c: pytest.fail(f"{c} in the JSON"))
