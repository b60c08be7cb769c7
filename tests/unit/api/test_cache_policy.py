"""Issue 65, defects 9 and 10: one cache policy. Temperature products were sent `public,
immutable` and changed after `thermcap radiometry` (a proxy and a browser kept the old °C for a
year); frames and Zarr chunks behind a token were `public`, so a shared cache answered them to
anyone without one. Counts and archive files never change: immutable, `private` behind tokens.
Anything a model version changes is revalidated every time."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings

TOKEN = "cache-policy-token-0123456789"
FOREVER = ("max-age=31536000", "immutable")


@pytest.fixture(scope="module", params=["open", "tokens"])
def served(request, root):
    tokens = {TOKEN: frozenset({"read", "write"})} if request.param == "tokens" else {}
    with TestClient(create_app(Settings(root=root, tokens=tokens, rescan_interval_s=0))) as c:
        c.headers["Authorization"] = f"Bearer {TOKEN}"
        yield request.param, c


def _cache(c, url: str) -> list[str]:
    r = c.get(url)
    assert r.status_code == 200, (url, r.status_code, r.text[:200])
    return [part.strip() for part in r.headers["cache-control"].split(",")]


@pytest.mark.parametrize("fmt", ["raw", "png16", "tiff"])
def test_counts_are_immutable_and_private_behind_a_token(served, fmt):
    mode, c = served
    got = _cache(c, f"/api/v1/sessions/s-archived/frames/3?format={fmt}")
    assert all(p in got for p in FOREVER), got
    assert ("private" if mode == "tokens" else "public") in got and ("public" in got) == (mode == "open"), got


@pytest.mark.parametrize("fmt", ["celsius-tiff", "preview"])
def test_temperature_products_are_revalidated(served, fmt):
    mode, c = served
    got = _cache(c, f"/api/v1/sessions/s-archived/frames/3?format={fmt}")
    assert "no-cache" in got and not any(p in got for p in FOREVER), got
    assert ("private" in got) == (mode == "tokens"), got


def test_zarr_counts_and_temperatures(served):
    mode, c = served
    counts = _cache(c, "/api/v1/sessions/s-archived/zarr/counts/3.0.0")
    temps = _cache(c, "/api/v1/sessions/s-archived/zarr/temperature/3.0.0")
    meta = _cache(c, "/api/v1/sessions/s-archived/zarr/.zmetadata")
    assert all(p in counts for p in FOREVER), counts
    assert "no-cache" in temps and "no-cache" in meta, (temps, meta)
    # format 3: a shard's frames move with the server's shard size and the session's length
    shard = _cache(c, "/api/v1/sessions/s-archived/zarr/counts/c/0/0/0")
    meta3 = _cache(c, "/api/v1/sessions/s-archived/zarr/zarr.json")
    assert "no-cache" in shard and "no-cache" in meta3 and not any(p in shard for p in FOREVER), shard
    for got in (counts, temps, meta, shard, meta3):
        assert ("private" in got) == (mode == "tokens") and ("public" in got) != (mode == "tokens"), got
