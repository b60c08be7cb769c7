"""Issue 36: the recorder's control endpoint, tried as an adversary would. It ran without a token
and without a warning; nothing checked Origin or Host (a web page's no-preflight POST, or a DNS
name rebound to 127.0.0.1, reached it); ``Content-Length: abc`` or ``-1`` and JSON nested 50,000
deep gave tracebacks or hung a handler; clients that hung up flooded the log with BrokenPipe
tracebacks; ``ctl status`` with no or a wrong token ended in ``KeyError``; ``ctl`` sent the token
to whatever URL a file in ROOT/run/ named."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from urllib.parse import urlsplit

import httpx
import pytest

from tests.conftest import run_cli, wait_for

TOKEN = "guard-test-token-0123456789"


@pytest.fixture
def recorder(tmp_path):
    env = {**os.environ, "THERMCAP_CONTROL_TOKEN": TOKEN}
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--root", str(tmp_path), "--session", "g",
                             "--width", "64", "--height", "48", "--control", "--no-analysis"],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    address = tmp_path / "run" / "g.control.json"
    assert wait_for(address.is_file, 60), proc.stderr.read() if proc.poll() is not None else "no control file"
    url = json.loads(address.read_text())["url"]
    yield proc, url, tmp_path
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=60)


def _raw(url: str, request: bytes) -> bytes:
    u = urlsplit(url)
    with socket.create_connection((u.hostname, u.port), timeout=20) as s:
        s.sendall(request)
        out = b""
        while chunk := s.recv(65536):
            out += chunk
        return out


def test_foreign_origin_and_host_are_refused(recorder):
    _, url, _ = recorder
    auth = {"Authorization": f"Bearer {TOKEN}"}
    with httpx.Client(base_url=url, timeout=10) as c:
        assert c.post("/pause", headers={**auth, "Origin": "http://evil.example"}).status_code == 403
        assert c.post("/pause", headers={"Content-Type": "text/plain", "Origin": "http://evil.example"},
                      content=b"x").status_code == 403
        assert c.get("/status", headers={**auth, "Host": f"rebound.example:{urlsplit(url).port}"}).status_code == 403
        assert c.get("/healthz", headers={"Host": "rebound.example"}).status_code == 403
        status = c.get("/status", headers=auth)
        assert status.status_code == 200 and status.json()["paused"] is False  # nothing got through
        assert c.get("/status", headers={**auth, "Origin": url}).status_code == 200


@pytest.mark.parametrize("length", [b"abc", b"-1"])
def test_a_malformed_content_length_is_400(recorder, length):
    _, url, _ = recorder
    host = urlsplit(url).netloc.encode()
    head = _raw(url, b"POST /mark HTTP/1.1\r\nHost: " + host + b"\r\nAuthorization: Bearer " + TOKEN.encode()
                + b"\r\nContent-Length: " + length + b"\r\nConnection: close\r\n\r\n")
    assert head.startswith(b"HTTP/1.0 400") or head.startswith(b"HTTP/1.1 400"), head[:100]


def test_deep_json_and_large_bodies_are_refused(recorder):
    _, url, _ = recorder
    auth = {"Authorization": f"Bearer {TOKEN}"}
    with httpx.Client(base_url=url, timeout=20) as c:
        deep = "[" * 50_000 + "]" * 50_000
        assert c.post("/mark", headers=auth, content=deep[:16_000]).status_code == 400
        assert c.post("/mark", headers=auth, content=b"{" * (1 << 20)).status_code == 413
        assert c.post("/mark", headers=auth, json={"note": "still answers"}).status_code == 202


def test_clients_that_hang_up_leave_no_tracebacks(recorder):
    proc, url, _ = recorder
    u = urlsplit(url)
    for _ in range(30):
        with socket.create_connection((u.hostname, u.port), timeout=10) as s:
            s.sendall(f"GET /metrics HTTP/1.1\r\nHost: {u.netloc}\r\nAuthorization: Bearer {TOKEN}\r\n\r\n".encode())
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")  # RST
    with httpx.Client(base_url=url, timeout=10) as c:
        assert c.get("/status", headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 200
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert "Traceback" not in err and "BrokenPipe" not in err and "ConnectionReset" not in err, err[-2000:]


@pytest.mark.parametrize("token", [None, "wrong-token-0123456789"])
def test_ctl_status_without_the_token_says_so(recorder, token):
    _, _, root = recorder
    r = run_cli("ctl", "status", "--root", str(root), env={"THERMCAP_CONTROL_TOKEN": token or ""})
    assert r.returncode == 1
    assert "401" in r.stderr and "token" in r.stderr and "Traceback" not in r.stderr


def test_ctl_sends_the_token_only_to_this_machine(recorder, tmp_path):
    _, _, root = recorder
    doc = json.loads((root / "run" / "g.control.json").read_text())
    (root / "run" / "g.control.json").write_text(json.dumps({**doc, "url": "http://203.0.113.9:7800"}))
    r = run_cli("ctl", "status", "--root", str(root), env={"THERMCAP_CONTROL_TOKEN": TOKEN})
    assert r.returncode == 1 and "off this machine" in r.stderr
