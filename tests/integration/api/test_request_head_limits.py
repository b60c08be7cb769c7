"""Issue 65, defect 12: a request's head had no limit in size or time. 20 unauthenticated
connections each sending a 16 MiB header line took the server from 449 to 822 MB, and 400
half-sent requests stayed open. The head is now bounded before the app sees it: 431 past 64 KiB,
408 when it does not arrive in time; the server's memory stays where it was."""

from __future__ import annotations

import socket
from pathlib import Path

import httpx
import pytest

from tests.conftest import ApiServer, wait_for

pytestmark = pytest.mark.integration


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


@pytest.fixture
def server(tmp_path):
    s = ApiServer(tmp_path, env={"THERMCAP_HEAD_TIMEOUT_S": "2"})
    yield s
    s.stop()


def _answer(sock: socket.socket) -> bytes:
    sock.settimeout(60)
    out = b""
    try:
        while chunk := sock.recv(65536):
            out += chunk
    except (ConnectionResetError, BrokenPipeError):
        pass
    return out


def test_a_huge_header_line_is_refused_without_growing_the_server(server):
    before = _rss_kib(server.proc.pid)
    answers = []
    for _ in range(10):
        with socket.create_connection(("127.0.0.1", server.port)) as sock:
            sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Big: ")
            try:
                for _ in range(16 * 16):  # up to 16 MiB, a 64 KiB piece at a time
                    sock.sendall(b"a" * 65536)
            except (BrokenPipeError, ConnectionResetError):
                pass  # refused and closed mid-way: what is wanted
            answers.append(_answer(sock))
    assert all(a.startswith(b"HTTP/1.1 431") or a == b"" for a in answers), answers[:2]
    assert any(a.startswith(b"HTTP/1.1 431") for a in answers)
    assert _rss_kib(server.proc.pid) - before < 32 * 1024  # not 16 MiB a connection
    assert httpx.get(f"{server.url}/healthz", timeout=30).status_code == 200


def test_a_head_that_never_ends_is_closed(server):
    socks = []
    for _ in range(20):
        s = socket.create_connection(("127.0.0.1", server.port))
        s.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: a")  # and nothing more
        socks.append(s)
    silent = socket.create_connection(("127.0.0.1", server.port))  # sends nothing at all
    try:
        for s in [*socks, silent]:
            assert _answer(s).startswith(b"HTTP/1.1 408")  # the server closes each, after its timeout
        # an ordinary request, and one kept alive across two, are untouched
        with httpx.Client(base_url=server.url, timeout=30) as c:
            assert c.get("/healthz").status_code == 200
            assert c.get("/healthz", headers={"X-Fine": "b" * 8000}).status_code == 200
    finally:
        for s in [*socks, silent]:
            s.close()
    assert wait_for(lambda: httpx.get(f"{server.url}/healthz", timeout=30).status_code == 200, 30)
