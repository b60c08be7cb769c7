"""One frame: raw counts, PNG16, TIFF, temperatures, colour preview, rebuilt DJI R-JPEG, sidecar."""

from __future__ import annotations

from typing import Literal
from urllib.parse import quote

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response

from api.routes.common import session_row
from api.security import require
from archive.codecs import get_codec
from recorder.exports.render import celsius, celsius_tiff, preview_png, session_model, tiff16
from recorder.exports.rjpeg import SEGMENTS_BLOB, rebuild_rjpeg
from recorder.radiometry import describe_model

router = APIRouter(prefix="/api/v1/sessions/{session_id}/frames", tags=["frames"],
                   dependencies=[Depends(require("read"))])

# The archive's own PNG16 writer (Up filter + libdeflate, read by libpng, Pillow and browsers).
_PNG16 = get_codec("png16")
_CACHE = {"Cache-Control": "public, max-age=31536000, immutable"}  # a recorded frame never changes


def _check_index(row: dict, n: int) -> None:
    if n < 0 or n >= row["frames"]:
        raise HTTPException(404, f"session {row['id']} has frames 0..{row['frames'] - 1}, not {n}")


@router.get("/{n}", responses={200: {"content": {"image/png": {}, "image/tiff": {}, "application/octet-stream": {}}}})
def get_frame(request: Request, session_id: str, n: int,
              format: Literal["raw", "png16", "tiff", "celsius-tiff", "preview", "dji-rjpeg"] = "png16",
              palette: Literal["ironbow", "gray", "turbo"] = "ironbow",
              min: float | None = Query(None, ge=-273.15, le=5000),
              max: float | None = Query(None, ge=-273.15, le=5000)) -> Response:
    row = session_row(request, session_id)
    _check_index(row, n)
    reader = request.app.state.frames
    if format == "png16":
        stored = reader.encoded(session_id, n, "png16")
        body = stored if stored is not None else _PNG16.encode(np.asarray(reader.pixels(session_id, n)))
        return Response(body, media_type="image/png", headers=_CACHE)
    frame = reader.pixels(session_id, n)
    h, w = frame.shape
    dims = {"X-Width": str(w), "X-Height": str(h), **_CACHE}
    if format == "raw":
        return Response(frame.astype("<u2", copy=False).tobytes(), media_type="application/octet-stream",
                        headers={**dims, "X-Dtype": "uint16le"})
    if format == "tiff":
        return Response(tiff16(frame), media_type="image/tiff", headers=dims)
    if format == "dji-rjpeg":  # for DJI's own tools: the R-JPEG rebuilt from the archive
        name, segments = reader.attachment(session_id, n, SEGMENTS_BLOB)
        disposition = f'attachment; filename="{quote(name or "frame.jpg")}"'
        try:
            body = rebuild_rjpeg(frame, segments)
        except ValueError as exc:
            raise HTTPException(409, f"frame {n}: {exc}") from None
        return Response(body, media_type="image/jpeg",
                        headers={**dims, "Content-Disposition": disposition})
    model = session_model(row["radiometric_model"])
    if format == "celsius-tiff":
        return Response(celsius_tiff(frame, model), media_type="image/tiff", headers=dims)
    if min is not None and max is not None and max <= min:
        raise HTTPException(400, "max must be greater than min")
    return Response(preview_png(frame, model, palette, min, max), media_type="image/png", headers=dims)


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
    model = session_model(row["radiometric_model"])
    value = round(float(celsius(frame[y:y + 1, x:x + 1], model)[0, 0]), 4)
    return {"x": x, "y": y, "counts": int(frame[y, x]), "celsius": value,
            "approximate": getattr(model, "approximate", False),
            "model": describe_model(model)}

