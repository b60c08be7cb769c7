"""Catalog and search: sessions, their frames, events and contrast-grade timeline."""

from __future__ import annotations

import json
from typing import Any, Literal

import numpy as np
from fastapi import APIRouter, Depends, Query, Request, Response
from sqlalchemy import func, literal, literal_column, or_, select, tuple_

from thermcap.api import db
from thermcap.api.reading.frame_search import search_targets
from thermcap.api.routes.common import decode_cursor, encode_cursor, iso, page_size, parse_time, session_row
from thermcap.api.security import require
from thermcap.archive.manifest import record_digest
from thermcap.recorder.radiometry import LookupTableModel, model_from_dict
from thermcap.recorder.storage.coverage import gaps as coverage_gaps

router = APIRouter(prefix="/api/v1", tags=["sessions"], dependencies=[Depends(require("read"))])


def _model(text: str | None, full: bool) -> dict[str, Any] | None:
    """A session's model; listings show a lookup table (thousands of entries) by its identity only."""
    model = json.loads(text) if text else None
    if not full and model and model.get("kind") == "lookup_table":
        table = model_from_dict(model)
        assert isinstance(table, LookupTableModel)
        return table.summary()
    return model


def _session_summary(row: dict[str, Any], full_model: bool = False) -> dict[str, Any]:
    return {
        "id": row["id"], "sensor": row["sensor"], "sensor_id": row["sensor_id"], "width": row["width"],
        "height": row["height"], "fps": row["fps"], "start": iso(row["start_ns"]), "end": iso(row["end_ns"]),
        "start_ns": row["start_ns"], "end_ns": row["end_ns"],
        # first to last frame, as `thermcap info` and `ls` give it
        "duration_s": round((row["end_ns"] - row["start_ns"]) / 1e9, 6) if row["start_ns"] is not None
        and row["end_ns"] is not None else 0.0,
        "frames": row["frames"], "frames_dropped": row["frames_dropped"], "status": row["status"],
        "min_grade": row["min_grade"], "max_grade": row["max_grade"], "has_targets": row["has_targets"],
        "has_slew_to_cue": row["has_slew_to_cue"],
        "radiometric_model": _model(row["radiometric_model"], full_model),
        "source_deleted": row["source_deleted"],
    }


# The catalog's order, spelt as the index ix_sessions_catalog is (a bound 0 would not match it, and
# every page would sort every session)
_START = func.coalesce(db.sessions.c.start_ns, literal_column("0"))


@router.get("/sessions")
def list_sessions(request: Request, response: Response, sensor: str | None = None, start: str | None = None,
                  end: str | None = None,
                  min_grade: float | None = Query(None, ge=0, le=1), max_grade: float | None = Query(None, ge=0, le=1),
                  has_targets: bool | None = None, slew_to_cue: bool | None = None,
                  sort: Literal["start", "-start"] = "-start", limit: int = 100, cursor: str | None = None) -> dict:
    """Sessions overlapping [start, end); ``min_grade``: some frame at least this good;
    ``max_grade``: some frame at most this good (``max_grade=0.3`` finds thermal crossover)."""
    n = page_size(request, limit, response)
    t0, t1 = parse_time(start, "start"), parse_time(end, "end")
    s = db.sessions.c
    where = []
    if sensor:
        where.append(or_(s.sensor_id == sensor, s.sensor == sensor))
    if t0 is not None:
        where.append(s.end_ns >= t0)
    if t1 is not None:
        where.append(s.start_ns < t1)
    if min_grade is not None:
        where.append(s.max_grade >= min_grade)
    if max_grade is not None:
        where.append(s.min_grade <= max_grade)
    if has_targets is not None:
        where.append(s.has_targets == has_targets)
    if slew_to_cue is not None:
        where.append(s.has_slew_to_cue == slew_to_cue)
    desc = sort.startswith("-")
    after = decode_cursor(cursor, (int, str))
    if after:  # a row-value bound: an index range from there, however deep the page
        key = tuple_(_START, s.id)
        where.append(key < tuple_(literal(after[0]), literal(after[1])) if desc
                     else key > tuple_(literal(after[0]), literal(after[1])))
    order = [_START.desc(), s.id.desc()] if desc else [_START, s.id]
    with request.app.state.engine.connect() as conn:
        rows = conn.execute(select(db.sessions).where(*where).order_by(*order).limit(n + 1)).mappings().all()
    items = [_session_summary(dict(r)) for r in rows[:n]]
    nxt = encode_cursor([rows[n - 1]["start_ns"] or 0, rows[n - 1]["id"]]) if len(rows) > n else None
    return {"items": items, "next_cursor": nxt}


@router.get("/sessions/{session_id}")
def get_session(request: Request, session_id: str) -> dict:
    row = session_row(request, session_id)
    with request.app.state.engine.connect() as conn:
        archives = conn.execute(select(db.archives).where(db.archives.c.session_id == session_id)).mappings().all()
        segments = conn.execute(select(db.segments).where(db.segments.c.session_id == session_id)
                                .order_by(db.segments.c.name)).mappings().all()
    coverage = json.loads(row["coverage"] or "[]")
    period = 1e9 / row["fps"] if row.get("fps") else 0.0  # no declared rate: a gap's seconds are its span
    gaps = coverage_gaps(coverage, period)
    return {
        **_session_summary(row, full_model=True),
        "archives": [{"format": a["format"], "bytes": a["bytes"], "objects": a["objects"], "ratio": a["ratio"],
                      "verified": a["verified"],
                      "files": [{"path": f["path"], "frames": f["frames"], "bytes": f["bytes"],
                                 **dict([record_digest(f) or ("sha256", None)]),  # under its hash's name
                                 "url": f"/api/v1/sessions/{session_id}/archives/{a['format']}/{f['path']}"}
                                for f in json.loads(a["files"])]} for a in archives],
        "segments": [{"name": s["name"], "frames": s["frames"], "bytes": s["bytes"]} for s in segments],
        "coverage": [{"start": iso(a), "end": iso(b), "start_ns": a, "end_ns": b} for a, b in coverage],
        # recorder.storage.coverage: over 2.5 frame periods without a frame; seconds beyond the one period
        "gaps": [{"start": iso(a), "end": iso(b), "seconds": round(seconds, 6)} for a, b, seconds in gaps],
        "temperature": _temperature_available(row["radiometric_model"]),
    }


def _temperature_available(model_json: str | None) -> dict:
    """Whether this server can give °C for the session, and if not why: the page greys out what
    would only answer 409 (a DJI layout that needs DJI's SDK, not configured here)."""
    import numpy as np

    from thermcap.recorder.exports.render import session_model
    from thermcap.recorder.radiometry import TemperatureUnavailable

    try:
        session_model(model_json).to_celsius(np.zeros((1, 1), np.uint16))
    except TemperatureUnavailable as exc:
        return {"available": False, "why": str(exc)}
    except ValueError as exc:
        return {"available": False, "why": f"the session's radiometric model is not usable: {exc}"}
    return {"available": True, "why": None}


@router.get("/sessions/{session_id}/foxglove-layout")
def get_foxglove_layout(request: Request, session_id: str) -> dict:
    """A Foxglove layout for this session: its colour range fits the session's counts (16 frames
    spread over it), detections drawn over the image, the sidecar's numbers plotted. Import it
    in Foxglove with Layouts -> Import from file."""
    import numpy as np

    from thermcap.recorder.storage.foxglove_layout import layout_for, ranges_from_frames

    row = session_row(request, session_id)
    reader = request.app.state.frames
    picks = sorted({int(i) for i in np.linspace(0, max(0, row["frames"] - 1), num=min(16, max(1, row["frames"])))})
    ranges: dict[str | None, tuple[int, int]] = {None: (0, 16383)}
    if row["frames"]:
        ranges = ranges_from_frames((None, reader.pixels(session_id, i)) for i in picks)
    return layout_for(ranges)


@router.get("/sessions/{session_id}/frames")
def list_frames(request: Request, response: Response, session_id: str, start: str | None = None, end: str | None = None,
                min_grade: float | None = Query(None, ge=0, le=1), max_grade: float | None = Query(None, ge=0, le=1),
                slew_to_cue: bool | None = None, has_targets: bool | None = None, limit: int = 500,
                cursor: str | None = None) -> dict:
    session_row(request, session_id)
    n = page_size(request, limit, response)
    cols = request.app.state.frames.columns.get(session_id)
    keep = np.ones(len(cols), bool)
    t0, t1 = parse_time(start, "start"), parse_time(end, "end")
    if t0 is not None:
        keep &= cols.timestamp_ns >= t0
    if t1 is not None:
        keep &= cols.timestamp_ns < t1
    if min_grade is not None:
        keep &= cols.grade >= min_grade  # NaN (not graded) passes neither bound
    if max_grade is not None:
        keep &= cols.grade <= max_grade
    if slew_to_cue is not None:
        keep &= cols.slew_to_cue == slew_to_cue
    if has_targets is not None:
        keep &= (cols.target_count > 0) == has_targets
    after = decode_cursor(cursor, (int,))
    picks = np.flatnonzero(keep)
    if after:
        picks = picks[picks > int(after[0])]
    items = []
    for i in picks[:n].tolist():
        r = cols.row(i)
        items.append({"index": i, "timestamp": iso(r["timestamp_ns"]), "timestamp_ns": r["timestamp_ns"],
                      "segment": r["segment"], "thermal_contrast_grade": r["grade"],
                      "slew_to_cue_active": r["slew_to_cue"], "target_count": r["target_count"],
                      "max_target_temp_c": r["max_target_temp_c"]})
    return {"items": items, "next_cursor": encode_cursor([items[-1]["index"]]) if len(picks) > n else None}


@router.get("/frames")
def search_frames(request: Request, response: Response, max_grade: float | None = Query(None, ge=0, le=1),
                  min_target_c: float | None = Query(None, description="frames whose hottest target is at least this",
                                                     ge=-273.15, le=5000, allow_inf_nan=False),
                  sensor: str | None = None, limit: int = 100, cursor: str | None = None) -> dict:
    """Frames across every session: ``max_grade=0.3&min_target_c=40`` finds frames in thermal
    crossover with a target above 40 °C. Hottest first; page with ``next_cursor``. Answered from
    partial indexes (graded frames, frames with a target), so the frames without either cost
    nothing however many there are."""
    n = page_size(request, limit, response)
    after = decode_cursor(cursor, (float, str, int))
    with request.app.state.engine.connect() as conn:
        found = search_targets(conn, limit=n + 1, min_target_c=min_target_c, max_grade=max_grade, sensor=sensor,
                               after=(float(after[0]), str(after[1]), int(after[2])) if after else None)
    items = [{"session_id": r.session_id, "index": r.idx, "timestamp": iso(r.timestamp_ns),
              "thermal_contrast_grade": r.grade, "target_count": r.target_count,
              "max_target_temp_c": r.max_target_temp_c} for r in found[:n]]
    last = found[n - 1] if len(found) > n else None
    nxt = encode_cursor([last.max_target_temp_c, last.session_id, last.idx]) if last else None
    return {"items": items, "next_cursor": nxt}


@router.get("/sessions/{session_id}/timeline")
def timeline(request: Request, session_id: str, bins: int = Query(400, ge=1, le=4000)) -> dict:
    """The contrast grade over the session in ``bins`` buckets (min, mean, max): for the browser view."""
    row = session_row(request, session_id)
    cols = request.app.state.frames.columns.get(session_id)
    n = max(1, len(cols))
    out = []
    for k in np.unique(np.arange(len(cols)) * bins // n):
        part = slice(-(-int(k) * n // bins), -(-(int(k) + 1) * n // bins))
        grade = cols.grade[part]
        graded = grade[~np.isnan(grade)]
        out.append({"first_frame": part.start, "min": float(graded.min()) if len(graded) else None,
                    "mean": float(graded.mean()) if len(graded) else None,
                    "max": float(graded.max()) if len(graded) else None,
                    "targets": int(cols.target_count[part].max()), "slew_to_cue": bool(cols.slew_to_cue[part].any())})
    return {"frames": row["frames"], "bins": out}


@router.get("/sessions/{session_id}/events")
def session_events(request: Request, session_id: str, kind: str | None = None) -> dict:
    session_row(request, session_id)
    e = db.events.c
    where = [e.session_id == session_id] + ([e.kind == kind] if kind else [])
    with request.app.state.engine.connect() as conn:
        rows = conn.execute(select(db.events).where(*where).order_by(e.start_ns)).mappings().all()
    return {"items": [{"kind": r["kind"], "start": iso(r["start_ns"]), "end": iso(r["end_ns"]),
                       "start_ns": r["start_ns"], "end_ns": r["end_ns"], "seconds": (r["end_ns"] - r["start_ns"]) / 1e9,
                       "detail": json.loads(r["detail"] or "{}")} for r in rows]}
