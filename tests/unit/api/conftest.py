"""A data root of real recorded and archived sessions (tests.support.api_data) and an in-process
client of the API over it, for each test module of this folder."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from tests.support.api_data import make_root
from thermcap.api.app import create_app
from thermcap.api.settings import Settings


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_root(tmp_path_factory.mktemp("api"))


@pytest.fixture(scope="module")
def client(root):
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        yield c
