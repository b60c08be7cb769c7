"""Health, readiness, Prometheus metrics, the audit, and (re)indexing on request."""

from __future__ import annotations

from fastapi import APIRouter, Depends, HTTPException, Request, Response
from prometheus_client import generate_latest
from sqlalchemy import func, select

from thermcap.api import db
from thermcap.api.indexing import IndexReport, index_root
from thermcap.api.security import has_token, require
from thermcap.recorder.storage.layout import SessionLayout
from thermcap.recorder.storage.reader import list_sessions

router = APIRouter()


@router.get("/healthz", tags=["meta"])
def healthz(request: Request) -> dict:
    """Alive; ``degraded`` (still 200: the service serves other copies) once it met a damaged copy.
    What and where (session and file names) only with a token: a probe needs the state, not the
    data root's names."""
    damage = request.app.state.frames.damage.summary()
    unserved = request.app.state.index_damage
    status = "degraded" if damage["damaged_copies_seen"] or unserved else "ok"
    return {"status": status, **damage, "not_served": unserved} if has_token(request) else {"status": status}


@router.get("/readyz", tags=["meta"])
def readyz(request: Request) -> dict:
    try:
        with request.app.state.engine.connect() as conn:
            n = conn.execute(select(func.count()).select_from(db.sessions)).scalar()
    except Exception as exc:
        raise HTTPException(503, f"index unreachable: {type(exc).__name__}") from None
    return {"status": "ready", "sessions": n}


@router.get("/metrics", tags=["meta"], dependencies=[Depends(require("read"))], response_class=Response,
            responses={200: {"content": {"text/plain; version=0.0.4": {}}, "description": "Prometheus metrics"}})
def metrics(request: Request) -> Response:
    with request.app.state.engine.connect() as conn:
        unverified = select(func.count()).select_from(db.archives).where(db.archives.c.verified.is_(False))
        damaged = conn.execute(unverified).scalar()
    request.app.state.archives_unverified.set(damaged or 0)
    return Response(generate_latest(request.app.state.metrics_registry), media_type="text/plain; version=0.0.4")


@router.get("/api/v1/audit", tags=["meta"], dependencies=[Depends(require("read"))])
def audit(request: Request, prices: str | None = None) -> dict:
    from thermcap.archive.costs import audit_sessions, load_prices

    if prices is not None:
        raise HTTPException(400, "custom price tables are set on the server (thermcap audit --prices), not per request")
    every = list_sessions(request.app.state.settings.root)
    dirs = [d for d in every if SessionLayout.of(d).manifest.exists()]
    left = [{"session": d.name, "why": "not archived yet"} for d in every if d not in dirs]
    return audit_sessions(dirs, load_prices(None), left)


@router.post("/api/v1/index", tags=["meta"], dependencies=[Depends(require("write"))])
def reindex(request: Request, force: bool = False) -> IndexReport:
    report = index_root(request.app.state.engine, request.app.state.settings.root, force=force,
                        store=request.app.state.store)
    request.app.state.index_damage = report.damaged
    return report
