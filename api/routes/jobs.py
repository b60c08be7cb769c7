"""Jobs: a region series submitted as a job, and every job's state (the API's own and the
archive workers'), from the jobs table."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from typing import Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from fastapi.responses import JSONResponse

from thermcap.api.jobs.records import STATES, get_job, job_id, list_jobs, submit_job
from thermcap.api.routes.measure import series_args, series_body
from thermcap.api.security import require
from thermcap.recorder.thermography.measure import Tool, ToolError, bounds

router = APIRouter(tags=["jobs"], dependencies=[Depends(require("read"))])


@dataclass(frozen=True)
class SeriesTask:
    """What a Dask worker needs to read a session: addresses, never an engine or a client."""

    root: str
    db_url: str
    s3_bucket: str | None
    s3_endpoint: str | None
    s3_region: str
    s3_prefix: str


def series_task(cfg: SeriesTask, row: dict, tool: Tool, tool_text: str, stat: str, indices: range, models: Any,
                times: dict[int, int]) -> dict:
    """On a Dask worker: the same series the API would compute, through the same verified
    readers (the summary, the strips, the frames)."""
    from pathlib import Path

    from thermcap.api.db import make_engine
    from thermcap.api.reading.frames import FrameReader
    from thermcap.api.reading.regions import RegionReader
    from thermcap.archive.blobs import open_store

    engine = make_engine(cfg.db_url)
    try:
        store = open_store(Path(cfg.root), bucket=cfg.s3_bucket, endpoint=cfg.s3_endpoint, region=cfg.s3_region,
                           prefix=cfg.s3_prefix)
        regions = RegionReader(FrameReader(engine, store, Path(cfg.root)), engine, store)
        return series_body(regions, row, tool, tool_text, stat, indices, models, times)
    finally:
        engine.dispose()


def _links(jid: str) -> dict[str, str]:
    return {"self": f"/api/v1/jobs/{jid}", "result": f"/api/v1/jobs/{jid}/result"}


@router.post("/api/v1/sessions/{session_id}/series/jobs", status_code=202)
def submit_series(request: Request, session_id: str, tool: str = Query(...),
                  stat: Literal["max", "mean", "min"] = "max", start: int = Query(0, ge=0),
                  end: int | None = Query(None, ge=1), step: int = Query(1, ge=1)) -> JSONResponse:
    """The series as a job: 202 with the job (poll ``links.self``), or 200 when the same series
    of the same session content is already done (its result is kept)."""
    row, t, indices, models, times = series_args(request, session_id, tool, start, end, step)
    try:
        bounds(t, (int(row["height"] or 0), int(row["width"] or 0)))
    except ToolError as exc:
        raise HTTPException(400, str(exc)) from None
    params = {"tool": tool, "stat": stat, "start": start, "end": end, "step": step,
              "object_parameters": models.overrides}
    content = json.dumps([row["fingerprint"], [v.to_dict() for v in models.versions]])
    jid = job_id("series", session_id, params, content)
    engine, runner = request.app.state.engine, request.app.state.jobs
    job, new = submit_job(engine, jid, "series", session_id, params)
    if new or runner.lost(job):
        regions = request.app.state.regions

        def work() -> dict:
            return series_body(regions, row, t, tool, stat, indices, models, times)

        settings = request.app.state.settings
        remote = (series_task, (SeriesTask(str(settings.root), settings.db_url, settings.s3_bucket,
                                           settings.s3_endpoint, settings.s3_region, settings.s3_prefix),
                                row, t, tool, stat, indices, models, times))
        runner.run(job, work, lambda out: {"points": len(out["points"]), "method": out["method"]}, remote=remote)
        job = get_job(engine, jid) or job
    body = {**job.to_dict(with_result=False), "links": _links(jid)}
    return JSONResponse(body, status_code=200 if job.state == "done" else 202)


@router.get("/api/v1/jobs", name="list_jobs")
def get_jobs(request: Request, state: Literal[STATES] | None = None,  # type: ignore[valid-type]
             kind: str | None = None, session: str | None = None,
             limit: int = Query(100, ge=1, le=1000)) -> dict:
    jobs = list_jobs(request.app.state.engine, state=state, kind=kind, session_id=session, limit=limit)
    return {"items": [{**j.to_dict(), "links": _links(j.id)} for j in jobs]}


@router.get("/api/v1/jobs/{jid}", name="get_job")
def get_one(request: Request, jid: str) -> dict:
    job = get_job(request.app.state.engine, jid)
    if job is None:
        raise HTTPException(404, f"no job {jid}")
    return {**job.to_dict(), "links": _links(jid)}


@router.get("/api/v1/jobs/{jid}/result", name="get_job_result")
def get_result(request: Request, jid: str, format: Literal["json", "csv"] = "json") -> Response:
    job = get_job(request.app.state.engine, jid)
    if job is None:
        raise HTTPException(404, f"no job {jid}")
    if job.state != "done":
        raise HTTPException(409, f"job {jid} is {job.state}" + (f": {job.error}" if job.error else ""))
    key = (job.result or {}).get("blob")
    head = request.app.state.store.head(key) if key else None
    if head is None:
        raise HTTPException(404, f"job {jid} kept no result")
    data = request.app.state.store.get_range(key, 0, head["size"])
    if format == "csv":
        points = json.loads(data).get("points", [])
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=["frame", "timestamp_ns", "celsius"])
        w.writeheader()
        w.writerows(points)
        return Response(buf.getvalue(), media_type="text/csv")
    return Response(data, media_type="application/json")
