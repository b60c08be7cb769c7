"""``/docs`` works with no network: the page names only thermcap's own asset URLs, and they serve."""

from __future__ import annotations

import re

from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings


def test_swagger_ui_needs_no_cdn(tmp_path):
    with TestClient(create_app(Settings(root=tmp_path))) as client:
        page = client.get("/docs")
        assert page.status_code == 200
        urls = re.findall(r"""(?:src|href)=['"]([^'"]+)['"]""", page.text) + re.findall(r"url: '([^']+)'", page.text)
        assert urls and all(u.startswith("/") for u in urls), urls  # nothing from another host
        for u in urls:
            r = client.get(u)
            assert r.status_code == 200 and len(r.content) > 0, u
        assert "SwaggerUIBundle" in client.get("/docs/assets/swagger-ui-bundle.js").text
        assert client.get("/docs/assets/..%2Fsettings.py").status_code == 404
