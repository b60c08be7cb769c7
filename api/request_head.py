"""A request's head (its line and headers) is bounded in size and in time, before any of it
reaches the application: ``thermcap serve`` runs uvicorn with this protocol.

The body limit (``security.BodyLimit``) sees only what the ASGI app sees; the head is parsed
before that, and the HTTP parser keeps a header line whole in memory however long it grows: 20
unauthenticated connections each sending a 16 MiB header line took the server from 449 to 822
MB. Here the bytes of a head are counted as they arrive, and past ``MAX_HEAD_BYTES`` the
connection is answered 431 and closed; a head not complete ``HEAD_TIMEOUT_S`` after its first
byte (or a connection that sends nothing) is answered 408 and closed, so slow clients cannot
hold connections open either. nginx's defaults are of the same order (32 KiB of headers, 60 s).
"""

from __future__ import annotations

import asyncio
from typing import Any

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from thermcap.api.problems import problem_body
from thermcap.recorder import settings

__all__ = ["HEAD_TIMEOUT_S", "MAX_HEAD_BYTES", "BoundedHead"]

MAX_HEAD_BYTES = 64 * 1024
HEAD_TIMEOUT_S = float(settings.HEAD_TIMEOUT_S.text())
_END = b"\r\n\r\n"


class BoundedHead(HttpToolsProtocol):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._in_head = True
        self._head_bytes = 0
        self._tail = b""  # the last bytes of the head so far: its end may be split across reads
        self._head_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._start_head()

    def connection_lost(self, exc: Exception | None) -> None:
        self._stop_timer()
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if self._in_head:
            seen = self._tail + data
            end = seen.find(_END)
            self._head_bytes += len(data) if end < 0 else max(0, end + len(_END) - len(self._tail))
            self._tail = seen[-3:] if end < 0 else b""
            if self._head_bytes > MAX_HEAD_BYTES:
                self._refuse(431, "Request Header Fields Too Large",
                             f"the request's line and headers are over {MAX_HEAD_BYTES // 1024} KiB")
                return
        super().data_received(data)

    def on_message_begin(self) -> None:
        super().on_message_begin()
        if not self._in_head:  # the next request on a kept-alive connection: a new head
            self._start_head()

    def on_headers_complete(self) -> None:
        self._in_head = False
        self._stop_timer()
        super().on_headers_complete()

    def on_message_complete(self) -> None:
        super().on_message_complete()
        self._in_head, self._head_bytes, self._tail = True, 0, b""  # its timer starts at the next byte

    def _start_head(self) -> None:
        self._in_head, self._head_bytes, self._tail = True, 0, b""
        self._stop_timer()
        self._head_timer = self.loop.call_later(HEAD_TIMEOUT_S, self._head_timed_out)

    def _stop_timer(self) -> None:
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def _head_timed_out(self) -> None:
        self._head_timer = None
        if self._in_head:
            self._refuse(408, "Request Timeout", f"the request's head did not arrive within {HEAD_TIMEOUT_S:g} s")

    def _refuse(self, status: int, reason: str, why: str) -> None:
        self._stop_timer()
        if self.transport.is_closing():
            return
        body = problem_body(status, why)
        self.transport.write(b"HTTP/1.1 %d %s\r\ncontent-type: application/problem+json\r\ncontent-length: %d\r\n"
                             b"connection: close\r\n\r\n" % (status, reason.encode(), len(body)) + body)
        self.transport.close()
