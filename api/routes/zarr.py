"""``/api/v1/sessions/{id}/zarr``: every served session as a Zarr store, format 2
(``api.reading.zarr_layout``) and format 3 with shards over time (``api.reading.zarr_v3``) under
one URL, read with stock ``xr.open_zarr(url)``, zarr-python and tensorstore."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Request, Response
from fastapi.responses import StreamingResponse

from thermcap.api.cache_policy import Kind, cache_headers
from thermcap.api.reading.zarr_layout import COORDINATES, IMAGE_VARIABLES, dumps, parse_chunk_key, store_metadata
from thermcap.api.reading.zarr_v3 import ShardLayout, parse_v3_key, shard_index, store_metadata_v3
from thermcap.api.routes.common import FrameModel, kept, parse_range, session_row
from thermcap.api.security import require
from thermcap.archive.reading.dataset_description import session_attrs
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
        return table, _metadata(row, table, named, request.app.state.settings.zarr_shard_bytes)

    return kept(request, "zarr_stores", (row["id"], row.get("fingerprint"), named["radiometric_model_versions"]),
                build, keep=64)


def _metadata(row: dict[str, Any], table: FrameTable, named: dict[str, str], shard_bytes: int) -> dict[str, Any]:
    sensor = {"model": row.get("sensor"), "sensor_id": row.get("sensor_id"), "frame_rate_hz": row.get("fps")}
    attrs = session_attrs(row["id"], sensor, row.get("frames_dropped"), named)
    width, height = int(row["width"] or 0), int(row["height"] or 0)
    v2 = store_metadata(table, width, height, attrs)
    layout = ShardLayout.of(len(table), height, width, shard_bytes)
    return {**v2, **store_metadata_v3(v2, layout, height, width)}


_KEY_RESPONSES: dict[int | str, dict] = {200: {"content": {"application/json": {}, "application/octet-stream": {}}}}


@router.get("/{key:path}", responses=_KEY_RESPONSES, response_class=Response)
@router.head("/{key:path}", name="head_zarr_key", responses=_KEY_RESPONSES, response_class=Response)
def get_zarr_key(request: Request, session_id: str, key: str) -> Response:
    """A key of the store: a metadata document (JSON) or a chunk (raw little-endian bytes)."""
    row = session_row(request, session_id)
    table, meta = _store(request, row)
    if key in meta:  # it names the model in force
        return Response(dumps(meta[key]), media_type="application/json", headers=cache_headers(request, Kind.MODEL))
    v3 = parse_v3_key(key)
    if v3 is not None and v3.variable in IMAGE_VARIABLES:
        return _shard(request, row, table, v3.variable, v3.index)
    chunk = parse_chunk_key(key) if v3 is None else v3
    if chunk is None:
        raise HTTPException(404, f"no key {key!r} in this Zarr store")
    var, i = chunk.variable, chunk.index
    n = len(table)
    if var in ("counts", "temperature"):
        if i >= n:
            raise HTTPException(404, f"no frame {i}: the session has {n}")
        body = _frame_chunks(request, row, table, var)(i)
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


def _frame_chunks(request: Request, row: dict[str, Any], table: FrameTable, var: str) -> Callable[[int], bytes]:
    """Frame ``i``'s chunk of ``var`` (format 2's chunk, format 3's inner chunk), read and
    checked through the frames reader; the model for temperatures is built once, on first use."""
    model: list[FrameModel] = []

    def chunk(i: int) -> bytes:
        frame = int(table.index[i])
        counts = np.asarray(request.app.state.frames.pixels(row["id"], frame))
        if var == "counts":
            return counts.astype("<u2", copy=False).tobytes()
        if not model:
            model.append(FrameModel(request, row))
        return model[0].temperatures(frame, counts).celsius.astype("<f4", copy=False).tobytes()

    return chunk


def _shard(request: Request, row: dict[str, Any], table: FrameTable, var: str, shard: int) -> Response:
    """A shard of ``var``, whole or the byte range asked for; only the frames the range touches
    are read, one at a time as the response goes out."""
    height, width = int(row["height"] or 0), int(row["width"] or 0)
    layout = ShardLayout.of(len(table), height, width, request.app.state.settings.zarr_shard_bytes)
    itemsize = 2 if var == "counts" else 4
    held, fb = layout.held(shard, itemsize)
    if not held:
        raise HTTPException(404, f"no shard {shard} of {var}: the session has {layout.frames} frames, "
                                 f"{layout.frames_per_shard} a shard")
    size = layout.shard_size(shard, itemsize)
    asked = request.headers.get("range")
    wanted = parse_range(asked, size) if asked else None
    start, end = wanted or (0, size)
    data_end = len(held) * fb
    frame_chunk = _frame_chunks(request, row, table, var)

    def pieces() -> Iterator[bytes]:
        at = start
        while at < min(end, data_end):
            k = at // fb
            frame = frame_chunk(held[k])
            yield frame[at - k * fb: min(end, (k + 1) * fb) - k * fb]
            at = (k + 1) * fb
        if end > data_end:
            yield shard_index(layout, shard, itemsize)[max(start, data_end) - data_end: end - data_end]

    # counts under a shard's URL are not forever: the server's shard size or a longer session moves them
    headers = {**cache_headers(request, Kind.LAYOUT if var == "counts" else Kind.MODEL), "Accept-Ranges": "bytes",
               "Content-Length": str(end - start)}
    status = 200
    if wanted is not None:
        status, headers["Content-Range"] = 206, f"bytes {start}-{end - 1}/{size}"
    if request.method == "HEAD":
        return Response(status_code=status, headers=headers, media_type="application/octet-stream")
    return StreamingResponse(pieces(), status_code=status, headers=headers, media_type="application/octet-stream")


def zarr_url(base: str, session_id: str) -> str:
    return f"{base.rstrip('/')}/api/v1/sessions/{session_id}/zarr"


__all__ += ["zarr_url"]

