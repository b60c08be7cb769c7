"""The OpenAPI document says what the service really does, so a generated client works: the
bearer token every route but ``PUBLIC_PATHS`` needs (a security scheme), and the one error
shape every route answers (``Problem``, RFC 9457), in place of FastAPI's validation schema,
which the service never sends."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI

from thermcap.api.problems import PROBLEM_JSON
from thermcap.api.security import PUBLIC_PATHS

__all__ = ["describe"]

SCHEME = "bearerAuth"

PROBLEM_SCHEMA: dict[str, Any] = {
    "title": "Problem", "type": "object", "required": ["type", "title", "status", "detail"],
    "description": "RFC 9457 problem details: every error the service answers.",
    "properties": {
        "type": {"type": "string", "example": "about:blank"},
        "title": {"type": "string", "example": "Not Found"},
        "status": {"type": "integer", "example": 404},
        "detail": {"type": "string", "example": "no session 'zz'"},
        "error": {"type": "string", "description": "the detail again, for clients older than this shape"},
        "problems": {"type": "array", "description": "a 422's invalid parameters",
                     "items": {"type": "object", "properties": {"where": {"type": "string"},
                                                                "problem": {"type": "string"}}}},
    },
}


def _problem_response(description: str) -> dict[str, Any]:
    return {"description": description,
            "content": {PROBLEM_JSON: {"schema": {"$ref": "#/components/schemas/Problem"}}}}


def describe(app: FastAPI) -> None:
    """Make ``app.openapi()`` add the security scheme and the error shape (built once, cached)."""
    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        doc = build()
        components = doc.setdefault("components", {})
        components.setdefault("securitySchemes", {})[SCHEME] = {
            "type": "http", "scheme": "bearer",
            "description": "A token from THERMCAP_TOKENS: every route but /healthz, /readyz and /login needs one "
                           "once tokens are configured."}
        schemas = components.setdefault("schemas", {})
        schemas["Problem"] = PROBLEM_SCHEMA
        for unused in ("HTTPValidationError", "ValidationError"):
            schemas.pop(unused, None)
        doc["security"] = [{SCHEME: []}]
        for path, operations in doc.get("paths", {}).items():
            for op in operations.values():
                if path in PUBLIC_PATHS:
                    op["security"] = []
                responses = op.setdefault("responses", {})
                if "422" in responses:
                    responses["422"] = _problem_response("An invalid parameter (each named in `problems`)")
                responses.setdefault("default", _problem_response("An error, as RFC 9457 problem details"))
        app.openapi_schema = doc
        return doc

    app.openapi = openapi  # type: ignore[method-assign]
