"""Archive downloads: HTTP Range (206, 416), strong ETags from the manifest, 304, CORS-exposed."""

from __future__ import annotations

import json

from fastapi import APIRouter, Depends, HTTPException, Request, Response
from fastapi.responses import RedirectResponse, StreamingResponse
from sqlalchemy import select

from thermcap.api import db
from thermcap.api.cache_policy import Kind, cache_headers
from thermcap.api.http_conventions import etag_matches
from thermcap.api.reading.frames import Damage
from thermcap.api.routes.common import parse_range, session_row
from thermcap.api.security import check_file_name, require
from thermcap.api.verified_files import verified_stream
from thermcap.archive.manifest import record_digest
from thermcap.recorder.storage.layout import archive_key

router = APIRouter(prefix="/api/v1/sessions/{session_id}/archives", tags=["archives"],
                   dependencies=[Depends(require("read"))])



def _archive(request: Request, session_id: str, fmt: str) -> dict:
    session_row(request, session_id)
    check_file_name(fmt)
    with request.app.state.engine.connect() as conn:
        row = conn.execute(select(db.archives).where(db.archives.c.session_id == session_id,
                                                     db.archives.c.format == fmt)).mappings().first()
    if row is None or not row["verified"]:
        raise HTTPException(404, f"session {session_id} has no verified {fmt!r} archive")
    return dict(row)


_FILE_RESPONSES: dict[int | str, dict] = {200: {"content": {"application/octet-stream": {}},
                                                "description": "the file, or the Range asked for (206)"}}


@router.get("/{fmt}")
def list_archive(request: Request, session_id: str, fmt: str) -> dict:
    row = _archive(request, session_id, fmt)
    files = json.loads(row["files"])
    return {"format": fmt, "bytes": row["bytes"], "objects": row["objects"], "ratio": row["ratio"],
            "files": [{**f, "url": f"/api/v1/sessions/{session_id}/archives/{fmt}/{f['path']}"} for f in files]}


# GET and HEAD as two routes of one function, so each operation has an OpenAPI ID of its own
@router.get("/{fmt}/{name}", name="download_archive_file", response_class=Response, responses=_FILE_RESPONSES)
@router.head("/{fmt}/{name}", name="head_archive_file", response_class=Response, responses=_FILE_RESPONSES)
def download(request: Request, session_id: str, fmt: str, name: str, redirect: bool = False) -> Response:
    row = _archive(request, session_id, fmt)
    check_file_name(name)
    entry = next((f for f in json.loads(row["files"]) if f["path"] == name), None)
    if entry is None:  # only files the manifest lists are served: nothing else under the root is reachable
        raise HTTPException(404, f"{fmt} archive of {session_id} has no file {name!r}")
    store = request.app.state.store
    key = archive_key(session_id, fmt, name)
    named = record_digest(entry)
    if named is None:  # not one the archiver wrote: it never verified
        raise HTTPException(404, f"{fmt} archive of {session_id} names no digest for {name!r}")
    etag = f'"{named[1]}"'
    if redirect:
        url = store.sign(key)
        if url:
            return RedirectResponse(url, status_code=307)
    size = entry["bytes"]
    base = {"ETag": etag, "Accept-Ranges": "bytes", **cache_headers(request, Kind.FIXED),  # named by its digest
            "Content-Type": "application/octet-stream"}
    if etag_matches(request.headers.get("if-none-match"), etag):
        return Response(status_code=304, headers=base)
    if store.head(key) is None:
        raise HTTPException(404, f"{key} is listed in the manifest but missing from the store")
    problem = request.app.state.files.problem(key, named, size)
    if problem is not None:  # never send damaged bytes under the manifest's ETag
        request.app.state.frames.damage.report(Damage(session_id, -1, f"{fmt}:{name}", problem))
        raise HTTPException(503, f"{fmt}/{name} of {session_id} is damaged ({problem}); another format may serve "
                                 "its frames, and `thermcap scrub --repair` rebuilds it from a verified copy")
    rng = request.headers.get("range")
    if_range = request.headers.get("if-range")
    span = parse_range(rng, size) if rng and (not if_range or if_range.strip() == etag) else None
    start, end = span if span else (0, size)
    headers = {**base, "Content-Length": str(end - start)}
    status = 200
    if span:
        status = 206
        headers["Content-Range"] = f"bytes {start}-{end - 1}/{size}"
    if request.method == "HEAD" or end == start:
        return Response(status_code=status, headers=headers)
    body = store.stream_range(key, start, end)
    if (start, end) == (0, size):  # a whole file: hashed as it goes, the last piece sent only if it matches

        def damaged(why: str) -> None:
            request.app.state.files.forget(key)
            request.app.state.frames.damage.report(Damage(session_id, -1, f"{fmt}:{name}", why))

        body = verified_stream(body, named, damaged)
    return StreamingResponse(body, status_code=status, headers=headers, media_type="application/octet-stream")
