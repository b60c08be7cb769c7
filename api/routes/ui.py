"""The browser view: two static pages (no build step) that call the JSON API."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import HTMLResponse

router = APIRouter(include_in_schema=False)
_STATIC = Path(__file__).resolve().parent.parent / "static"


@router.get("/", response_class=HTMLResponse)
def index_page() -> HTMLResponse:
    return HTMLResponse((_STATIC / "index.html").read_text())


@router.get("/static/common.js")
def common_js():
    from fastapi.responses import Response

    return Response((_STATIC / "common.js").read_text(), media_type="text/javascript")


@router.get("/ui/sessions/{session_id}", response_class=HTMLResponse)
def session_page(session_id: str) -> HTMLResponse:
    # The id is used only by the page's script, through the API, which validates it.
    return HTMLResponse((_STATIC / "session.html").read_text())
