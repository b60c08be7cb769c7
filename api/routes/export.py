"""``export.mcap``: a time range and topic subset of a session as one streamed, indexed MCAP."""

from __future__ import annotations

import io

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Request
from fastapi.responses import StreamingResponse

from thermcap.api.routes.common import parse_time, session_row
from thermcap.api.security import require
from thermcap.archive.blobs import BlobFile
from thermcap.archive.reading.mcap_slice import export_mcap, unreadable_segments
from thermcap.recorder.storage.layout import EXTRAS_MCAP, DataRoot, archive_key

router = APIRouter(prefix="/api/v1/sessions/{session_id}", tags=["export"], dependencies=[Depends(require("read"))])


@router.get("/export.mcap", name="export_mcap", responses={200: {"content": {"application/octet-stream": {}}}})
def export(request: Request, session_id: str, start: str | None = None, end: str | None = None,
           topics: str | None = None) -> StreamingResponse:
    row = session_row(request, session_id)
    t0, t1 = parse_time(start, "start"), parse_time(end, "end")
    if t0 is not None and t1 is not None and t1 <= t0:
        raise HTTPException(400, "end must be after start")
    topic_list = [t for t in (topics or "").split(",") if t] or None
    session_dir = DataRoot.of(request.app.state.settings.root).session_dir(session_id)
    unreadable = unreadable_segments(session_dir)
    if unreadable:  # said before the first byte: a 200 that stops half way is no answer
        raise HTTPException(409, f"session {session_id}: {'; '.join(unreadable[:3])}; `thermcap recover` repairs "
                                 f"a segment that was cut short")
    frames = None
    if not session_dir.is_dir() or row["source_deleted"]:
        reader = request.app.state.frames
        times = reader.columns.get(session_id).timestamp_ns
        keep = np.ones(len(times), bool)
        if t0 is not None:
            keep &= times >= t0
        if t1 is not None:
            keep &= times < t1
        rows = [(int(i), int(times[i])) for i in np.flatnonzero(keep)]
        frames = ((i, t, (lambda i=i: reader.pixels(session_id, i)), (lambda i=i: reader.sidecar(session_id, i)))
                  for i, t in rows)
    extras = None
    if frames is not None:
        store = request.app.state.store
        key = archive_key(session_id, EXTRAS_MCAP)
        head = store.head(key)
        if head is not None:
            def extras():
                return io.BufferedReader(BlobFile(store, key, head["size"]), buffer_size=1 << 20)
    name = f"{session_id}.mcap"
    return StreamingResponse(export_mcap(session_dir, t0, t1, topic_list, frames, extras),
                             media_type="application/octet-stream",
                             headers={"Content-Disposition": f'attachment; filename="{name}"'})
