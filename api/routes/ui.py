"""The browser view: two static pages (no build step) that call the JSON API."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qs

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, RedirectResponse

from thermcap.api.security import TOKEN_COOKIE, scopes_for_token

router = APIRouter(include_in_schema=False)
_STATIC = Path(__file__).resolve().parent.parent / "static"


@router.get("/", response_class=HTMLResponse)
def index_page() -> HTMLResponse:
    return HTMLResponse((_STATIC / "index.html").read_text())


@router.get("/static/{name}.js")
def static_js(name: str):
    """The pages' scripts, by name from a fixed list (a request path never reaches the disk)."""
    from fastapi import HTTPException
    from fastapi.responses import Response

    if name not in _SCRIPTS:
        raise HTTPException(404, f"no script {name}.js")
    return Response((_STATIC / f"{name}.js").read_text(), media_type="text/javascript")


_SCRIPTS = ("common", "workbench")


@router.get("/ui/sessions/{session_id}", response_class=HTMLResponse)
def session_page(session_id: str) -> HTMLResponse:
    # The id is used only by the page's script, through the API, which validates it.
    return HTMLResponse((_STATIC / "session.html").read_text())


_LOGIN = """<!doctype html><meta charset="utf-8"><title>thermcap: sign in</title>
<form method="post" action="/login" style="font-family:sans-serif;margin:4em auto;max-width:24em">
<h1>thermcap</h1><p>{message}</p>
<label>API token <input name="token" type="password" autocomplete="current-password" autofocus></label>
<button type="submit">Sign in</button></form>"""


@router.get("/login", response_class=HTMLResponse)
def login_page() -> HTMLResponse:
    return HTMLResponse(_LOGIN.format(message="This service needs a token (THERMCAP_TOKENS)."))


@router.post("/login")
async def login(request: Request):
    """The token arrives in a form body, never a URL; it becomes an HttpOnly cookie."""
    body = (await request.body())[:4096].decode("utf-8", errors="replace")
    token = (parse_qs(body).get("token") or [""])[0]
    if scopes_for_token(request.app.state.settings.tokens, token) is None:
        return HTMLResponse(_LOGIN.format(message="That token is not valid."), status_code=401)
    response = RedirectResponse("/", status_code=303)
    response.set_cookie(TOKEN_COOKIE, token, httponly=True, samesite="strict", path="/")
    return response
