"""``export.mcap``: a time range and topic subset of a session as one streamed, indexed MCAP."""

from __future__ import annotations

import io

from fastapi import APIRouter, Depends, HTTPException, Request
from fastapi.responses import StreamingResponse
from sqlalchemy import select

from thermcap.api import db
from thermcap.api.reading.frames import BlobFile
from thermcap.api.reading.mcap_slice import export_mcap
from thermcap.api.routes.common import parse_time, session_row
from thermcap.api.security import require
from thermcap.recorder.storage.layout import EXTRAS_MCAP

router = APIRouter(prefix="/api/v1/sessions/{session_id}", tags=["export"], dependencies=[Depends(require("read"))])


@router.get("/export.mcap", name="export_mcap", responses={200: {"content": {"application/octet-stream": {}}}})
def export(request: Request, session_id: str, start: str | None = None, end: str | None = None,
           topics: str | None = None) -> StreamingResponse:
    row = session_row(request, session_id)
    t0, t1 = parse_time(start, "start"), parse_time(end, "end")
    if t0 is not None and t1 is not None and t1 <= t0:
        raise HTTPException(400, "end must be after start")
    topic_list = [t for t in (topics or "").split(",") if t] or None
    session_dir = request.app.state.settings.root / "sessions" / session_id
    frames = None
    if not session_dir.is_dir() or row["source_deleted"]:
        f = db.frames.c
        where = [f.session_id == session_id] + ([f.timestamp_ns >= t0] if t0 is not None else []) + \
            ([f.timestamp_ns < t1] if t1 is not None else [])
        with request.app.state.engine.connect() as conn:
            rows = conn.execute(select(f.idx, f.timestamp_ns).where(*where).order_by(f.idx)).all()
        reader = request.app.state.frames
        frames = ((i, t, (lambda i=i: reader.pixels(session_id, i)), (lambda i=i: reader.sidecar(session_id, i)))
                  for i, t in rows)
    extras = None
    if frames is not None:
        store = request.app.state.store
        key = f"sessions/{session_id}/archive/{EXTRAS_MCAP}"
        head = store.head(key)
        if head is not None:
            def extras():
                return io.BufferedReader(BlobFile(store, key, head["size"]), buffer_size=1 << 20)
    name = f"{session_id}.mcap"
    return StreamingResponse(export_mcap(session_dir, t0, t1, topic_list, frames, extras),
                             media_type="application/octet-stream",
                             headers={"Content-Disposition": f'attachment; filename="{name}"'})
