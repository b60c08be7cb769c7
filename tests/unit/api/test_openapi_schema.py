"""The OpenAPI document is what client generators (openapi-generator, openapi-python-client)
build from: every operation needs an ID of its own, or they drop or overwrite one of a pair.
HEAD on frames and archive files was registered with GET on one route, which gave both the
same ID."""

from __future__ import annotations

import warnings
from collections import Counter

from thermcap.api.app import create_app
from thermcap.api.settings import Settings


def test_every_operation_has_an_id_of_its_own(tmp_path):
    app = create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # FastAPI warns on a duplicate and keeps going
        schema = app.openapi()
    ops = [(path, method, op.get("operationId")) for path, item in schema["paths"].items()
           for method, op in item.items()]
    ids = Counter(op_id for _, _, op_id in ops)
    assert all(op_id for _, _, op_id in ops)
    assert [op for op in ops if ids[op[2]] > 1] == []


def test_head_stays_documented_beside_get(tmp_path):
    schema = create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0)).openapi()
    for path in ("/api/v1/sessions/{session_id}/frames/{n}", "/api/v1/sessions/{session_id}/archives/{fmt}/{name}"):
        assert {"get", "head"} <= set(schema["paths"][path]), path
