"""Every error the service answers, in one shape: RFC 9457 problem details
(``application/problem+json``: ``type``, ``title``, ``status``, ``detail``), whoever raised it:
a route, FastAPI's validation, Starlette's router, a middleware, the request-head guard. The
message is in ``detail`` and, for clients written before this shape, in ``error`` too."""

from __future__ import annotations

import json
from http import HTTPStatus
from typing import Any

from fastapi.responses import JSONResponse

__all__ = ["PROBLEM_JSON", "problem", "problem_body"]

PROBLEM_JSON = "application/problem+json"


def problem_body(status: int, detail: str, **extensions: Any) -> bytes:
    try:
        title = HTTPStatus(status).phrase
    except ValueError:
        title = "Error"
    doc = {"type": "about:blank", "title": title, "status": status, "detail": detail, "error": detail, **extensions}
    return json.dumps(doc).encode()


class _ProblemResponse(JSONResponse):
    media_type = PROBLEM_JSON


def problem(status: int, detail: Any, headers: dict[str, str] | None = None, **extensions: Any) -> JSONResponse:
    return _ProblemResponse(json.loads(problem_body(status, str(detail), **extensions)), status_code=status,
                            headers=headers)
