"""A client generated from the service's own OpenAPI document (openapi-python-client, as an
integrator would make one) lists sessions and fetches a frame with a token, and reads an error
as the document's ``Problem``: the document says what the service does (its security scheme,
its one error shape)."""

from __future__ import annotations

import importlib
import json
import shutil
import subprocess
import sys

import httpx
import numpy as np
import pytest

from tests.support.api_data import H, W, make_root, token_server
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.integration

TOKEN = "generated-client-token-0123456789"
GENERATOR = shutil.which("openapi-python-client")


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    root = make_root(tmp_path_factory.mktemp("gen"))
    s = token_server(root, tmp_path_factory.mktemp("tok"), TOKEN)
    yield root, s
    s.stop()


@pytest.mark.skipif(GENERATOR is None, reason="openapi-python-client is in the test extra")
def test_a_generated_client_works_with_a_token(served, tmp_path, monkeypatch):
    root, server = served
    doc = httpx.get(f"{server.url}/openapi.json", headers={"Authorization": f"Bearer {TOKEN}"}).json()
    assert doc["components"]["securitySchemes"]["bearerAuth"] == {**doc["components"]["securitySchemes"][
        "bearerAuth"], "type": "http", "scheme": "bearer"}
    assert doc["paths"]["/healthz"]["get"]["security"] == []
    spec = tmp_path / "openapi.json"
    spec.write_text(json.dumps(doc))
    out = tmp_path / "thermcap_generated"
    r = subprocess.run([GENERATOR, "generate", "--path", str(spec), "--output-path", str(out), "--meta", "none"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    monkeypatch.syspath_prepend(str(tmp_path))
    client_mod = importlib.import_module("thermcap_generated.client")
    list_sessions = importlib.import_module("thermcap_generated.api.sessions.list_sessions")
    get_frame = importlib.import_module("thermcap_generated.api.frames.get_frame")
    frame_format = importlib.import_module("thermcap_generated.models.get_frame_format").GetFrameFormat

    with client_mod.AuthenticatedClient(base_url=server.url, token=TOKEN) as client:
        listed = list_sessions.sync_detailed(client=client)
        assert listed.status_code == 200
        assert sorted(s["id"] for s in json.loads(listed.content)["items"]) == \
            ["s-archived", "s-crossover", "s-mcap-only"]
        frame = get_frame.sync_detailed("s-archived", 3, client=client, format_=frame_format.RAW)
        assert frame.status_code == 200
        expected = next(f.pixels for f in iter_session_frames(root / "sessions" / "s-archived") if f.index == 3)
        np.testing.assert_array_equal(np.frombuffer(frame.content, "<u2").reshape(H, W), expected)
        missing = list_sessions.sync_detailed(client=client, limit=0)  # an invalid limit: a Problem
        assert missing.status_code == 400 and missing.parsed.status == 400 and "limit" in missing.parsed.detail
    with client_mod.Client(base_url=server.url) as anonymous:
        refused = list_sessions.sync_detailed(client=anonymous)
        assert refused.status_code == 401 and refused.parsed.detail == "a valid bearer token is required"
    sys.modules.pop("thermcap_generated", None)
