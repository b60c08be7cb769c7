"""Issue 36: authentication fails closed, bodies are bounded, health says only up/degraded
without a token. An empty or comment-only tokens file had switched authentication off (the
catalog and POST /api/v1/index answered 200 with no token); POST /login read a 1 GiB body into
memory before checking anything; /healthz named damaged sessions and files to anyone."""

from __future__ import annotations

import socket

import pytest
from fastapi.testclient import TestClient

from thermcap.api.app import create_app
from thermcap.api.settings import Settings

TOKEN = "0123456789abcdef"


@pytest.mark.parametrize("text", ["", "\n\n", "# tokens go here\n", " ; ;\n"])
def test_a_tokens_file_that_yields_no_token_is_an_error(tmp_path, monkeypatch, text):
    f = tmp_path / "tokens"
    f.write_text(text)
    monkeypatch.delenv("THERMCAP_TOKENS", raising=False)
    monkeypatch.setenv("THERMCAP_TOKENS_FILE", str(f))
    with pytest.raises(ValueError, match="holds no token"):
        Settings(root=tmp_path)


def test_a_comment_only_tokens_variable_is_an_error(tmp_path, monkeypatch):
    monkeypatch.delenv("THERMCAP_TOKENS_FILE", raising=False)
    monkeypatch.setenv("THERMCAP_TOKENS", "# none yet")
    with pytest.raises(ValueError, match="holds no token"):
        Settings(root=tmp_path)


def test_serve_refuses_an_empty_tokens_file(tmp_path):
    from tests.conftest import run_cli

    f = tmp_path / "tokens"
    f.write_text("# nobody\n")
    r = run_cli("serve", "--root", str(tmp_path), "--host", "0.0.0.0", "--port", "1",
                env={"THERMCAP_TOKENS_FILE": str(f)})
    assert r.returncode != 0
    assert "holds no token" in r.stderr and "Traceback" not in r.stderr


@pytest.fixture
def client(tmp_path):
    with TestClient(create_app(Settings(root=tmp_path, tokens={TOKEN: frozenset({"read", "write"})}),
                               index_on_start=False)) as c:
        yield c


def test_health_without_a_token_says_only_the_state(client):
    from thermcap.api.reading.frames import Damage

    client.app.state.frames.damage.report(Damage("s", 3, "png16:0000.zip", "sha256 differs"))
    body = client.get("/healthz").json()
    assert body == {"status": "degraded"}
    full = client.get("/healthz", headers={"Authorization": f"Bearer {TOKEN}"}).json()
    assert full["status"] == "degraded" and full["damaged_copies_seen"] == 1


def test_a_large_body_is_refused_before_it_is_read(client):
    r = client.post("/login", content=b"token=" + b"x" * (2 << 20),
                    headers={"content-type": "application/x-www-form-urlencoded"})
    assert r.status_code == 413


def test_a_chunked_body_past_the_limit_is_refused(client):
    def gen():
        for _ in range(40):
            yield b"x" * (64 << 10)

    r = client.post("/login", content=gen(), headers={"content-type": "application/x-www-form-urlencoded"})
    assert r.status_code == 413


def test_a_malformed_content_length_is_400(client):
    # the test client recomputes Content-Length; send raw bytes over a real socket instead
    import threading

    import uvicorn

    from tests.conftest import free_port

    port = free_port()
    server = uvicorn.Server(uvicorn.Config(client.app, host="127.0.0.1", port=port, log_level="error"))
    t = threading.Thread(target=server.run, daemon=True)
    t.start()
    try:
        from tests.conftest import wait_for

        assert wait_for(lambda: server.started, timeout=30)
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(b"POST /login HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: abc\r\n\r\n")
            head = s.recv(200)
        assert head.startswith(b"HTTP/1.1 400"), head
    finally:
        server.should_exit = True
        t.join(10)


@pytest.mark.parametrize("text", ["", "   "])
def test_a_tokens_variable_set_but_empty_is_an_error(tmp_path, monkeypatch, text):
    """Issue 65, defect 17: `THERMCAP_TOKENS=''` (compose substituting an unset variable) served
    with no authentication, while `';'` was refused. Set means meant: it must hold a token."""
    monkeypatch.delenv("THERMCAP_TOKENS_FILE", raising=False)
    monkeypatch.setenv("THERMCAP_TOKENS", text)
    with pytest.raises(ValueError, match="holds no token"):
        Settings(root=tmp_path)


def test_the_example_placeholder_is_not_a_token(tmp_path, monkeypatch):
    """Issue 65, defect 17: `.env.example`'s placeholder was accepted as a real token."""
    from pathlib import Path

    example = (Path(__file__).resolve().parents[3] / ".env.example").read_text()
    (line,) = [v for v in example.splitlines() if v.startswith("THERMCAP_TOKENS=")]
    monkeypatch.delenv("THERMCAP_TOKENS_FILE", raising=False)
    monkeypatch.setenv("THERMCAP_TOKENS", line.partition("=")[2])
    with pytest.raises(ValueError, match="placeholder"):
        Settings(root=tmp_path)


@pytest.mark.parametrize("headers", [
    {"Origin": "http://127.0.0.1:9999"},  # another port on the same host: same-site, not same-origin
    {"Origin": "null"},  # a sandboxed frame or a file:// page
    {"Referer": "http://evil.example/page"},
    {},  # a cookie-borne write that says nowhere where it comes from
])
def test_a_cross_site_write_with_the_cookie_is_refused(client, headers):
    """A page on another origin can make the browser POST (text/plain needs no preflight) and the
    browser attaches the SameSite=Strict cookie whenever the sites match, as every 127.0.0.1 port
    does: a write carried by the cookie must come from this origin."""
    client.cookies.set("thermcap_token", TOKEN)
    r = client.post("/api/v1/index", content=b"x", headers={"content-type": "text/plain", **headers})
    assert r.status_code == 403 and "origin" in r.json()["error"].lower()
    own = client.post("/api/v1/index", headers={"Origin": "http://testserver"})
    assert own.status_code != 403
    bearer = client.post("/api/v1/index", headers={"Authorization": f"Bearer {TOKEN}", **headers})
    assert bearer.status_code != 403  # a script's bearer token is not something a page can attach
    assert client.get("/api/v1/sessions", headers=headers).status_code == 200  # reads are not writes
