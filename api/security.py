"""Bearer tokens with ``read`` and ``write`` scopes, and the checks on names from requests.

With no token configured the service is open (it binds 127.0.0.1 by default). With tokens,
every route but /healthz and /readyz needs one; comparison is constant-time over every token,
so the time taken says nothing about how much of a guess was right.
"""

from __future__ import annotations

import hmac
import re

from fastapi import HTTPException, Request

__all__ = ["require", "SESSION_ID_RE", "FILE_NAME_RE", "check_session_id", "check_file_name"]

SESSION_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")
FILE_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")


def _scopes_for(request: Request) -> frozenset[str] | None:
    tokens: dict[str, frozenset[str]] = request.app.state.settings.tokens
    header = request.headers.get("authorization", "")
    scheme, _, given = header.partition(" ")
    if scheme.lower() != "bearer" or not given:
        return None
    found: frozenset[str] | None = None
    for token, scopes in tokens.items():  # no early exit: constant time in the number of tokens
        if hmac.compare_digest(token.encode(), given.strip().encode()):
            found = scopes
    return found


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
