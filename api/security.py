"""Bearer tokens with ``read`` and ``write`` scopes, and the checks on names from requests.

With no token configured the service is open (it binds 127.0.0.1 by default). With tokens,
every route but /healthz, /readyz and the login form needs one: the JSON API, the browser pages,
their scripts, /docs and /openapi.json alike. ``AuthGate`` checks that at the door, before any
routing, so a route added later cannot be left open by forgetting a dependency; ``require``
then checks the scope a route needs. Comparison is constant-time over every token, so the time
taken says nothing about how much of a guess was right.

A browser cannot add a header to a page it navigates to, so ``/login`` takes the token once in a
POSTed form (never in a URL, which access logs keep) and sets it as an HttpOnly, SameSite=Strict
cookie, which the pages' own requests then carry.
"""

from __future__ import annotations

import hmac
import re
from http.cookies import SimpleCookie
from typing import Any

from fastapi import HTTPException, Request

from thermcap.api.problems import PROBLEM_JSON, problem_body

__all__ = [
    "FILE_NAME_RE",
    "MAX_BODY_BYTES",
    "PUBLIC_PATHS",
    "SESSION_ID_RE",
    "TOKEN_COOKIE",
    "AuthGate",
    "BodyLimit",
    "check_file_name",
    "check_session_id",
    "given_token",
    "has_token",
    "require",
    "scopes_for_token",
]

PUBLIC_PATHS = frozenset({"/healthz", "/readyz", "/login"})
TOKEN_COOKIE = "thermcap_token"

SESSION_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")
FILE_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")


def scopes_for_token(tokens: dict[str, frozenset[str]], given: str | None) -> frozenset[str] | None:
    if not given:
        return None
    found: frozenset[str] | None = None
    for token, scopes in tokens.items():  # no early exit: constant time in the number of tokens
        if hmac.compare_digest(token.encode(), given.strip().encode()):
            found = scopes
    return found


#: Methods a browser may send across sites freely; anything else carried by the cookie must come
#: from a page of this server (SameSite=Strict does not tell ports of one host apart).
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


def _bearer(headers: dict[str, str]) -> bool:
    scheme, _, given = headers.get("authorization", "").partition(" ")
    return scheme.lower() == "bearer" and bool(given.strip())


def same_origin(headers: dict[str, str], scope: dict) -> bool:
    """Whether a request says it comes from a page of this server: its Origin (or, where a
    browser sent none, its Referer) names the scheme, host and port the request was sent to
    (the Host header, or the one a reverse proxy forwarded). A request that says nothing is not."""
    from urllib.parse import urlsplit

    claimed = headers.get("origin") or headers.get("referer") or ""
    if not claimed or claimed == "null":
        return False
    parts = urlsplit(claimed)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        return False
    own = {h.strip().lower() for h in (headers.get("host", ""), headers.get("x-forwarded-host", "")) if h.strip()}
    return parts.netloc.lower() in own


def given_token(authorization: str, cookie_header: str) -> str | None:
    scheme, _, given = authorization.partition(" ")
    if scheme.lower() == "bearer" and given.strip():
        return given.strip()
    if cookie_header:
        cookies: SimpleCookie = SimpleCookie()
        try:
            cookies.load(cookie_header)
        except Exception:  # a malformed Cookie header is no token, not a 500
            return None
        if TOKEN_COOKIE in cookies:
            return cookies[TOKEN_COOKIE].value
    return None


def has_token(request: Request) -> bool:
    """Whether the request may see what only token holders see (always, with no tokens set)."""
    return not request.app.state.settings.tokens or _scopes_for(request) is not None


def _scopes_for(request: Request) -> frozenset[str] | None:
    tokens: dict[str, frozenset[str]] = request.app.state.settings.tokens
    given = given_token(request.headers.get("authorization", ""), request.headers.get("cookie", ""))
    return scopes_for_token(tokens, given)


class AuthGate:
    """Pure ASGI: with tokens configured, nothing but ``PUBLIC_PATHS`` is served without a valid one."""

    def __init__(self, app: Any, *, tokens: dict[str, frozenset[str]]) -> None:
        self.app, self.tokens = app, tokens

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http" or not self.tokens or scope.get("path") in PUBLIC_PATHS \
                or scope.get("method") == "OPTIONS":  # CORS preflight carries no credentials
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        given = given_token(headers.get("authorization", ""), headers.get("cookie", ""))
        if scopes_for_token(self.tokens, given) is not None:
            if scope.get("method") not in SAFE_METHODS and not _bearer(headers) and not same_origin(headers, scope):
                await _send_error(send, 403, "a write carried by the login cookie must come from this server's own "
                                             "origin (its Origin or Referer header); scripts send the token as "
                                             "Authorization: Bearer")
                return
            await self.app(scope, receive, send)
            return
        if scope.get("method") == "GET" and "text/html" in headers.get("accept", ""):
            await _send(send, 303, b"", [(b"location", b"/login")])
            return
        body = problem_body(401, "a valid bearer token is required")
        await _send(send, 401, body, [(b"content-type", PROBLEM_JSON.encode()), (b"www-authenticate", b"Bearer")])


#: Request bodies are small (a login form, a radiometry change, a job): nothing larger is read.
MAX_BODY_BYTES = 1 << 20


class BodyLimit:
    """Pure ASGI: a request body over ``max_bytes`` is refused with 413 before it is read (by its
    Content-Length) or as soon as it passes the limit (a chunked one), so no route ever holds an
    unbounded body in memory, authenticated or not."""

    def __init__(self, app: Any, *, max_bytes: int = MAX_BODY_BYTES) -> None:
        self.app, self.max_bytes = app, max_bytes

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = next((v for k, v in scope.get("headers", []) if k.lower() == b"content-length"), None)
        if length is not None:
            text = length.decode("latin-1").strip()
            if not text.isdigit():
                await _send_error(send, 400, f"Content-Length {text[:40]!r} is not a byte count")
                return
            if int(text) > self.max_bytes:
                await _send_error(send, 413, f"the request body is {int(text):,} bytes; at most {self.max_bytes:,}")
                return
        seen = 0
        started = False

        async def counted() -> dict:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_bytes:
                    raise _TooLarge
            return message

        async def tracked(message: dict) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted, tracked)
        except _TooLarge:
            if not started:
                await _send_error(send, 413, f"the request body is over {self.max_bytes:,} bytes")


class _TooLarge(Exception):
    pass


async def _send_error(send: Any, status: int, message: str) -> None:
    await _send(send, status, problem_body(status, message), [(b"content-type", PROBLEM_JSON.encode())])


async def _send(send: Any, status: int, body: bytes, headers: list[tuple[bytes, bytes]]) -> None:
    await send({"type": "http.response.start", "status": status,
                "headers": [*headers, (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})


def require(scope: str):
    """A FastAPI dependency: 401 without a valid token, 403 without the scope."""

    def check(request: Request) -> None:
        if not request.app.state.settings.tokens:
            return
        scopes = _scopes_for(request)
        if scopes is None:
            raise HTTPException(401, "a valid bearer token is required", headers={"WWW-Authenticate": "Bearer"})
        if scope not in scopes:
            raise HTTPException(403, f"this token lacks the {scope!r} scope")

    return check


def check_session_id(session_id: str) -> str:
    if not SESSION_ID_RE.match(session_id) or ".." in session_id:
        raise HTTPException(400, f"invalid session id {session_id!r}")
    return session_id


def check_file_name(name: str) -> str:
    if not FILE_NAME_RE.match(name) or ".." in name:
        raise HTTPException(400, f"invalid file name {name!r}")
    return name
