"""HTTP's conventions, kept in one place: ETags compared by RFC 9110's rules, JSON answered
with a weak ETag and a 304 when the client holds it, gzip for JSON a client accepts, and HEAD
wherever GET is.

``JsonConventions`` is pure ASGI: it holds a JSON answer's body (JSON routes answer whole
documents, never streams), so it can hash and compress it; other answers pass untouched, and
frames and archive files keep the strong ETags their routes set.
"""

from __future__ import annotations

import gzip
import hashlib
from typing import Any

from thermcap.recorder.storage.digest import new_hasher

__all__ = ["GZIP_MIN_BYTES", "HeadAsGet", "JsonConventions", "etag_matches"]

#: JSON below this is sent as it is: gzip's header and a round trip of CPU cost more than it saves.
GZIP_MIN_BYTES = 1024


def _opaque(tag: str) -> str:
    tag = tag.strip()
    return tag[2:] if tag.startswith("W/") else tag


#: The hash of a frame body's ETag: the archive's default (recorder.storage.digest), so a raw
#: frame's ETag is its manifest digest where the archive took it, and nothing is hashed again.
ETAG_HASH = "blake3"


def body_etag(body: bytes | memoryview, known: tuple[str, str] | None = None) -> str:
    """A strong ETag for a frame's body, quoted: its ``ETAG_HASH`` (any change of bytes changes
    it), the same whichever path answers. ``known``: (hash, hex) of these very bytes already
    taken, used as it is when it is that hash."""
    if known is not None and known[0] == ETAG_HASH:
        return f'"{known[1][:40]}"'
    h = new_hasher(ETAG_HASH)
    h.update(body)
    return f'"{h.hexdigest()[:40]}"'


def etag_matches(if_none_match: str | bytes | None, etag: str | bytes) -> bool:
    """RFC 9110 13.1.2: If-None-Match uses the weak comparison (``W/"x"`` matches ``"x"``), and
    ``*`` matches any current representation."""
    if if_none_match is None:
        return False
    inm = if_none_match.decode("latin-1") if isinstance(if_none_match, bytes) else if_none_match
    tag = etag.decode("latin-1") if isinstance(etag, bytes) else etag
    if inm.strip() == "*":
        return True
    return _opaque(tag) in {_opaque(t) for t in inm.split(",") if t.strip()}


def _accepts_gzip(headers: dict[bytes, bytes]) -> bool:
    for part in headers.get(b"accept-encoding", b"").decode("latin-1").split(","):
        name, _, params = part.strip().partition(";")
        if name.strip().lower() in ("gzip", "*"):
            q = params.strip()
            return not (q.startswith("q=") and float(q[2:] or 0) == 0)
    return False


class JsonConventions:
    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http" or scope["method"] not in ("GET", "HEAD"):
            await self.app(scope, receive, send)
            return
        headers = dict(scope.get("headers", []))
        start: dict[str, Any] = {}
        body: list[bytes] = []
        passthrough = False

        async def hold(message: dict) -> None:
            nonlocal passthrough
            if message["type"] == "http.response.start":
                kinds = dict(message.get("headers", []))
                is_json = kinds.get(b"content-type", b"").startswith(b"application/json")
                if message["status"] != 200 or not is_json or b"etag" in kinds or b"content-encoding" in kinds:
                    passthrough = True
                    await send(message)
                    return
                start.update(message)
                return
            if passthrough:
                await send(message)
                return
            body.append(message.get("body", b""))
            if message.get("more_body"):
                return
            await self._answer(start, b"".join(body), headers, send)

        await self.app(scope, receive, hold)

    @staticmethod
    async def _answer(start: dict, content: bytes, request: dict[bytes, bytes], send: Any) -> None:
        etag = b'W/"' + hashlib.blake2b(content, digest_size=16).hexdigest().encode() + b'"'
        out = [(k, v) for k, v in start.get("headers", []) if k.lower() != b"content-length"]
        out += [(b"etag", etag), (b"vary", b"Accept-Encoding")]
        if etag_matches(request.get(b"if-none-match"), etag):
            await send({"type": "http.response.start", "status": 304,
                        "headers": [(k, v) for k, v in out if k.lower() != b"content-type"]})
            await send({"type": "http.response.body", "body": b""})
            return
        if len(content) >= GZIP_MIN_BYTES and _accepts_gzip(request):
            content = gzip.compress(content, compresslevel=5, mtime=0)
            out.append((b"content-encoding", b"gzip"))
        out.append((b"content-length", str(len(content)).encode()))
        await send({"type": "http.response.start", "status": start["status"], "headers": out})
        await send({"type": "http.response.body", "body": content})


class HeadAsGet:
    """HEAD wherever GET is (RFC 9110 9.3.2): a HEAD no route answers itself is run as the GET
    and sent without its body, headers (Content-Length, ETag) as the GET's. Routes with their
    own HEAD (frames, archive files) keep it: they answer without reading what they would send."""

    def __init__(self, app: Any, router: Any) -> None:
        self.app, self.router = app, router

    def _answers_head(self, scope: dict) -> bool:
        from starlette.routing import Match

        return any(route.matches(scope)[0] == Match.FULL for route in self.router.routes)

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["method"] != "HEAD" or self._answers_head(scope):
            await self.app(scope, receive, self._allow_head(send))
            return

        async def without_body(message: dict) -> None:
            if message["type"] == "http.response.body":
                message = {**message, "body": b""}
            await send(message)

        await self.app({**scope, "method": "GET"}, receive, without_body)

    @staticmethod
    def _allow_head(send: Any) -> Any:
        """A 405's ``Allow`` names HEAD wherever it names GET: this middleware answers it there."""

        async def sending(message: dict) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405:
                headers = []
                for k, v in message.get("headers", []):
                    if k.lower() == b"allow":
                        methods = [m.strip() for m in v.decode("latin-1").split(",") if m.strip()]
                        if "GET" in methods and "HEAD" not in methods:
                            methods.append("HEAD")
                        v = ", ".join(methods).encode("latin-1")
                    headers.append((k, v))
                message = {**message, "headers": headers}
            await send(message)

        return sending
