"""Thermographer's tools over stored frames: measurements (spot, box, line, polygon, with ΔT),
line profiles, histograms, isotherms, and a region's statistic as a time series."""

from __future__ import annotations

import csv
import io
import json
from typing import Annotated, Literal

import imagecodecs
import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response

from thermcap.api.reading.regions import RegionReader
from thermcap.api.routes.common import CelsiusQuery, FrameModel, session_row
from thermcap.api.security import require
from thermcap.recorder.radiometry import describe_model
from thermcap.recorder.thermography.measure import (
    Line,
    Tool,
    ToolError,
    histogram,
    isotherm,
    line_profile,
    measure,
    parse_tool,
)

router = APIRouter(prefix="/api/v1/sessions/{session_id}", tags=["thermography"],
                   dependencies=[Depends(require("read"))])


def _frame_temps(request: Request, session_id: str, n: int) -> tuple[dict, np.ndarray]:
    """(what to say about the model used, °C) of frame ``n``."""
    row = session_row(request, session_id)
    if n < 0 or n >= row["frames"]:
        raise HTTPException(404, f"session {row['id']} has frames 0..{row['frames'] - 1}, not {n}")
    models = FrameModel(request, row)
    model, said = models.at(n)
    ft = models.temperatures(n, request.app.state.frames.pixels(session_id, n))
    return {**said, "model": describe_model(model), "bad_pixels": ft.describe()["bad_pixels"]}, ft.celsius


def _tools(texts: list[str]) -> list:
    try:
        return [parse_tool(t) for t in texts]
    except ToolError as exc:
        raise HTTPException(400, str(exc)) from None


@router.get("/frames/{n}/measure")
def get_measure(request: Request, session_id: str, n: int,
                tool: Annotated[list[str], Query(description="spot:x,y | box:x0,y0,x1,y1 | line:... | polygon:...; "
                                                             "repeat for several (ΔT between the first two)")]) -> dict:
    said, temps = _frame_temps(request, session_id, n)
    try:
        ms = [measure(temps, t, label=text) for t, text in zip(_tools(tool), tool, strict=True)]
    except ToolError as exc:
        raise HTTPException(400, str(exc)) from None
    out: dict = {"frame": n, **said, "measurements": [m.to_dict() for m in ms]}
    if len(ms) >= 2 and ms[0].max_c is not None and ms[1].max_c is not None:
        out["delta_t_c"] = {"max": round(ms[0].max_c - ms[1].max_c, 4),
                            "mean": round((ms[0].mean_c or 0) - (ms[1].mean_c or 0), 4)}
    return out


@router.get("/frames/{n}/profile")
def get_profile(request: Request, session_id: str, n: int,
                line: str = Query(..., description="x0,y0,x1,y1")) -> dict:
    _, temps = _frame_temps(request, session_id, n)
    try:
        tool = parse_tool(f"line:{line}")
        assert isinstance(tool, Line)
        return {"frame": n, "line": line, "samples": line_profile(temps, tool)}
    except ToolError as exc:
        raise HTTPException(400, str(exc)) from None


@router.get("/frames/{n}/histogram")
def get_histogram(request: Request, session_id: str, n: int, bins: int = Query(64, ge=1, le=4096),
                  min: CelsiusQuery = None, max: CelsiusQuery = None, tool: str | None = None) -> dict:
    _, temps = _frame_temps(request, session_id, n)
    try:
        return {"frame": n, **histogram(temps, bins, min, max, parse_tool(tool) if tool else None)}
    except ToolError as exc:
        raise HTTPException(400, str(exc)) from None


@router.get("/frames/{n}/isotherm", responses={200: {"content": {"image/png": {}, "application/json": {}}}})
def get_isotherm(request: Request, session_id: str, n: int, above: CelsiusQuery = None, below: CelsiusQuery = None,
                 format: Literal["json", "png"] = "json") -> Response:
    _, temps = _frame_temps(request, session_id, n)
    try:
        mask = isotherm(temps, above, below)
    except ToolError as exc:
        raise HTTPException(400, str(exc)) from None
    if format == "png":
        return Response(imagecodecs.png_encode(mask.astype(np.uint8) * 255), media_type="image/png")
    body = {"frame": n, "above_c": above, "below_c": below, "pixels": int(mask.sum()),
            "fraction": round(float(mask.mean()), 6)}
    return Response(json.dumps(body), media_type="application/json")


def series_args(request: Request, session_id: str, tool: str, start: int, end: int | None,
                 step: int) -> tuple[dict, Tool, range, FrameModel, dict[int, int]]:
    row = session_row(request, session_id)
    stop = min(row["frames"], end if end is not None else row["frames"])
    if tool == "frame":  # the whole frame: what the frame summary answers without decoding
        tool = f"box:0,0,{(row['width'] or 1) - 1},{(row['height'] or 1) - 1}"
    t = _tools([tool])[0]
    times = dict(enumerate(request.app.state.frames.columns.get(session_id).timestamp_ns.tolist()))
    return row, t, range(start, max(start, stop), step), FrameModel(request, row), times


def series_body(regions: RegionReader, row: dict, t: Tool, tool: str, stat: str, indices: range, models: FrameModel,
                times: dict[int, int]) -> dict:
    """The series as the API gives it: its points, how they were read, and the model versions
    they used (the same on a Dask worker as here)."""
    result = regions.series(row, t, stat, indices, lambda i: models.at(i)[0], times)
    versions = sorted({models.at(i)[1]["model_version"] for i in indices})
    return {"tool": tool, "stat": stat, "model_versions": versions, **result.to_dict()}


def compute_series(request: Request, session_id: str, tool: str, stat: str, start: int, end: int | None,
                   step: int) -> dict:
    row, t, indices, models, times = series_args(request, session_id, tool, start, end, step)
    try:
        return series_body(request.app.state.regions, row, t, tool, stat, indices, models, times)
    except ToolError as exc:
        raise HTTPException(400, str(exc)) from None


@router.get("/series")
def get_series(request: Request, session_id: str,
               tool: str = Query(..., description="a tool (box:x0,y0,x1,y1 ...) or `frame` for the whole frame"),
               stat: Literal["max", "mean", "min"] = "max",
               start: int = Query(0, ge=0), end: int | None = Query(None, ge=1), step: int = Query(1, ge=1),
               format: Literal["json", "csv"] = "json") -> Response:
    """The statistic of ``tool`` on frames start..end (exclusive), every ``step``. The whole
    frame comes from the archive's frame summary; a box reads only the TIFF strips holding its
    rows (each checked against its band checksum); ``method`` says which was used."""
    body = compute_series(request, session_id, tool, stat, start, end, step)
    if format == "csv":
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=["frame", "timestamp_ns", "celsius"])
        w.writeheader()
        w.writerows(body["points"])
        return Response(buf.getvalue(), media_type="text/csv",
                        headers={"X-Thermcap-Series-Method": body["method"],
                                 "X-Thermcap-Model-Versions": ",".join(map(str, body["model_versions"]))})
    return Response(json.dumps(body), media_type="application/json")
