"""``/api/v1/sessions/{id}/zarr``: every served session as a Zarr store (see
``api.reading.zarr_layout``), read with stock ``xr.open_zarr(url)`` over fsspec."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Request, Response

from thermcap.api.cache_policy import Kind, cache_headers
from thermcap.api.reading.zarr_layout import COORDINATES, dumps, parse_chunk_key, store_metadata
from thermcap.api.routes.common import FrameModel, kept, session_row
from thermcap.api.security import require
from thermcap.archive.reading.frame_table import FrameTable
from thermcap.recorder.radiometry.params import models_named
from thermcap.recorder.storage.layout import DataRoot

__all__ = ["router"]

router = APIRouter(prefix="/api/v1/sessions/{session_id}/zarr", tags=["zarr"],
                   dependencies=[Depends(require("read"))])



def _store(request: Request, row: dict[str, Any]) -> tuple[FrameTable, dict[str, Any]]:
    """The session's frame table and the store's metadata documents, built once per indexed
    state of the session (its fingerprint), not for every key a reader asks for."""

    from thermcap.recorder.radiometry.params import read_versions

    try:  # the model versions in force now: a new one is another store (its metadata names it)
        versions = read_versions(DataRoot.of(request.app.state.settings.root).session_dir(row["id"]))
    except ValueError as exc:
        raise HTTPException(500, str(exc)) from None
    named = models_named(json.loads(row.get("radiometric_model") or "null") or {"kind": "linear"}, versions)

    def build() -> tuple[FrameTable, dict[str, Any]]:
        table = request.app.state.frames.columns.get(row["id"]).table()  # chunk i is frame i
        return table, _metadata(row, table, named)

    return kept(request, "zarr_stores", (row["id"], row.get("fingerprint"), named["radiometric_model_versions"]),
                build, keep=64)


def _metadata(row: dict[str, Any], table: FrameTable, named: dict[str, str]) -> dict[str, Any]:
    attrs = {"title": f"thermcap session {row['id']}", "source": "thermcap", "session_id": row["id"],
             "sensor": row.get("sensor"), "sensor_id": row.get("sensor_id"), "fps": row.get("fps"),
             "frames_dropped": row.get("frames_dropped"), **named}
    return store_metadata(table, int(row["width"] or 0), int(row["height"] or 0), attrs)


_KEY_RESPONSES: dict[int | str, dict] = {200: {"content": {"application/json": {}, "application/octet-stream": {}}}}


@router.get("/{key:path}", responses=_KEY_RESPONSES, response_class=Response)
@router.head("/{key:path}", name="head_zarr_key", responses=_KEY_RESPONSES, response_class=Response)
def get_zarr_key(request: Request, session_id: str, key: str) -> Response:
    """A key of the store: a metadata document (JSON) or a chunk (raw little-endian bytes)."""
    row = session_row(request, session_id)
    table, meta = _store(request, row)
    if key in meta:  # it names the model in force
        return Response(dumps(meta[key]), media_type="application/json", headers=cache_headers(request, Kind.MODEL))
    chunk = parse_chunk_key(key)
    if chunk is None:  # zarr.json and the like: a reader probing for format 3 must see "not here"
        raise HTTPException(404, f"no key {key!r} in this Zarr store")
    var, i = chunk.variable, chunk.index
    n = len(table)
    if var in ("counts", "temperature"):
        if i >= n:
            raise HTTPException(404, f"no frame {i}: the session has {n}")
        frame = int(table.index[i])
        counts = np.asarray(request.app.state.frames.pixels(session_id, frame))
        if var == "counts":
            body = counts.astype("<u2", copy=False).tobytes()
        else:
            body = FrameModel(request, row).temperatures(frame, counts).celsius.astype("<f4", copy=False).tobytes()
        kind = Kind.FIXED if var == "counts" else Kind.MODEL
        return Response(body, media_type="application/octet-stream", headers=cache_headers(request, kind))
    if i != 0 or var not in (*COORDINATES, "time", "y", "x"):
        raise HTTPException(404, f"no key {key!r} in this Zarr store")
    if var == "time":
        values = table.timestamp_ns.astype("<i8")
    elif var == "frame":
        values = table.index.astype("<i8")
    elif var in ("y", "x"):
        values = np.arange(int(row["height" if var == "y" else "width"] or 0), dtype="<i4")
    else:
        values = table.fields[var]
        values = values.astype(values.dtype.newbyteorder("<"), copy=False)
    # coordinates come from the index, which a reindex may change: revalidated
    return Response(values.tobytes(), media_type="application/octet-stream", headers=cache_headers(request, Kind.MODEL))


def zarr_url(base: str, session_id: str) -> str:
    return f"{base.rstrip('/')}/api/v1/sessions/{session_id}/zarr"


__all__ += ["zarr_url"]

