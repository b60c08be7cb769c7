"""One frame: raw counts, PNG16, TIFF, temperatures, colour preview, rebuilt DJI R-JPEG, sidecar."""

from __future__ import annotations

from typing import Any, Literal
from urllib.parse import quote

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response

from thermcap.api.cache_policy import Kind, cache_headers
from thermcap.api.http_conventions import body_etag, etag_matches
from thermcap.api.routes.common import CelsiusQuery, FrameModel, kept, session_row
from thermcap.api.security import require
from thermcap.archive.codecs import get_codec
from thermcap.recorder.exports.colorbar import TemperatureRange
from thermcap.recorder.exports.render import celsius, celsius_tiff, frame_range, preview_png, tiff16
from thermcap.recorder.importers.dji_rebuild import SEGMENTS_BLOB, rebuild_rjpeg
from thermcap.recorder.radiometry import TemperatureUnavailable, describe_model

router = APIRouter(prefix="/api/v1/sessions/{session_id}/frames", tags=["frames"],
                   dependencies=[Depends(require("read"))])

# The archive's own PNG16 writer (Up filter + libdeflate, read by libpng, Pillow and browsers).
_PNG16 = get_codec("png16")


def _send(request: Request, body: bytes, media_type: str, headers: dict[str, str]) -> Response:
    """The body with a strong ETag (``body_etag``), a 304 when the client holds it already, and
    only the headers for HEAD."""
    etag = body_etag(body)
    headers = {**headers, "ETag": etag}
    if etag_matches(request.headers.get("if-none-match"), etag):
        return Response(status_code=304, headers=headers)
    if request.method == "HEAD":
        return Response(b"", media_type=media_type, headers={**headers, "Content-Length": str(len(body))})
    return Response(body, media_type=media_type, headers=headers)


def _check_index(row: dict, n: int) -> None:
    if n < 0 or n >= row["frames"]:
        raise HTTPException(404, f"session {row['id']} has frames 0..{row['frames'] - 1}, not {n}")


_FRAME_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"content": {"image/png": {}, "image/tiff": {}, "application/octet-stream": {}}},
    304: {"description": "If-None-Match matched the ETag"}}


# GET and HEAD as two routes of one function: one route with both methods gives both operations
# the same OpenAPI ID, and client generators then keep only one of them
@router.get("/{n}", responses=_FRAME_RESPONSES, response_class=Response)
@router.head("/{n}", responses=_FRAME_RESPONSES, name="head_frame", response_class=Response)
def get_frame(request: Request, session_id: str, n: int,
              format: Literal["raw", "png16", "tiff", "celsius-tiff", "preview", "dji-rjpeg"] = "png16",
              palette: Literal["ironbow", "gray", "turbo"] = "ironbow",
              min: CelsiusQuery = None,
              max: CelsiusQuery = None,
              range: Literal["frame", "session", "fixed"] | None = Query(
                  None, description="preview scale: the frame's own (default), one for the whole session, or "
                                    "fixed by min and max (the default when both are given)"),
              colorbar: bool = Query(True, description="preview: draw the °C scale into the picture")) -> Response:
    row = session_row(request, session_id)
    _check_index(row, n)
    reader = request.app.state.frames
    if format == "png16":
        stored = reader.encoded(session_id, n, "png16")
        body = stored if stored is not None else _PNG16.encode(np.asarray(reader.pixels(session_id, n)))
        return _send(request, body, "image/png", cache_headers(request, Kind.FIXED))
    frame = reader.pixels(session_id, n)
    h, w = frame.shape
    dims = {"X-Width": str(w), "X-Height": str(h), **cache_headers(request, Kind.FIXED)}
    if format == "raw":
        return _send(request, frame.astype("<u2", copy=False).tobytes(), "application/octet-stream",
                     {**dims, "X-Dtype": "uint16le"})
    if format == "tiff":
        return _send(request, tiff16(frame), "image/tiff", dims)
    if format == "dji-rjpeg":  # for DJI's own tools: the R-JPEG rebuilt from the archive
        name, segments = reader.attachment(session_id, n, SEGMENTS_BLOB)
        disposition = f'attachment; filename="{quote(name or "frame.jpg")}"'
        try:
            body = rebuild_rjpeg(frame, segments)
        except ValueError as exc:
            raise HTTPException(409, f"frame {n}: {exc}") from None
        return _send(request, body, "image/jpeg", {**dims, "Content-Disposition": disposition})
    models = FrameModel(request, row)
    model, said = models.at(n)
    # from here on the bytes are temperatures: a new model version changes them
    dims = {**dims, "X-Model-Version": str(said["model_version"]), **cache_headers(request, Kind.MODEL)}
    if format == "celsius-tiff":
        return _send(request, celsius_tiff(models.temperatures(n, frame)), "image/tiff", dims)
    if min is not None and max is not None and max <= min:
        raise HTTPException(400, "max must be greater than min")
    mode = range or ("fixed" if min is not None and max is not None else "frame")
    if mode == "fixed" and (min is None or max is None):
        raise HTTPException(400, "range=fixed needs min and max (°C)")
    fixed = (min, max) if mode == "fixed" else (None, None)
    span = _session_range(request, row, model) if mode == "session" else None
    png, rng = preview_png(frame, model, palette, *fixed, colorbar=colorbar, session_range=span)
    return _send(request, png, "image/png", {**dims, **rng.headers()})


def _session_range(request: Request, row: dict, model) -> TemperatureRange | None:
    """One scale for a whole session: the widest 0.5..99.5 percentiles of 16 frames spread over
    it, computed once per session and model (a re-parameterised model has its own scale) and
    kept, up to a bound."""
    def measure() -> TemperatureRange | None:
        reader = request.app.state.frames
        picks = sorted({int(i) for i in np.linspace(0, row["frames"] - 1, num=min(16, row["frames"]))})
        try:
            parts = [frame_range(celsius(reader.pixels(row["id"], i), model)) for i in picks]
        except TemperatureUnavailable:
            return None
        return TemperatureRange(min(p.lo for p in parts), max(p.hi for p in parts), "session")

    # models are frozen dataclasses: hashable, compared by value
    return kept(request, "session_ranges", (row["id"], row["frames"], model), measure)


@router.get("/{n}/metadata")
def get_frame_metadata(request: Request, session_id: str, n: int) -> dict:
    row = session_row(request, session_id)
    _check_index(row, n)
    return request.app.state.frames.sidecar(session_id, n)


@router.get("/{n}/temperature")
def get_temperature(request: Request, session_id: str, n: int, x: int = Query(..., ge=0),
                    y: int = Query(..., ge=0)) -> dict:
    """Temperature (C) of one pixel through the session's radiometric model."""
    row = session_row(request, session_id)
    _check_index(row, n)
    frame = request.app.state.frames.pixels(session_id, n)
    h, w = frame.shape
    if x >= w or y >= h:
        raise HTTPException(400, f"pixel ({x}, {y}) is outside the {w}x{h} frame")
    models = FrameModel(request, row)
    model, said = models.at(n)
    mask = models.temps.bad_pixel_map
    bad = mask is not None and mask.shape == frame.shape and bool(mask[y, x])
    value = None if bad else round(float(celsius(frame[y:y + 1, x:x + 1], model)[0, 0]), 4)
    return {"x": x, "y": y, "counts": int(frame[y, x]), "celsius": value, "bad_pixel": bad,
            "approximate": getattr(model, "approximate", False),
            "model": describe_model(model), **said}

