"""``create_app(settings)``: the FastAPI service over an indexed data root."""

from __future__ import annotations

import logging
import threading
import time
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse
from fastapi.routing import APIRoute
from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from starlette.exceptions import HTTPException as StarletteHTTPException

from thermcap.api.db import make_engine, migrate
from thermcap.api.exceptions import FrameNotFound, FrameUnavailable
from thermcap.api.fast_frames import FrameFastPath
from thermcap.api.http_conventions import HeadAsGet, JsonConventions
from thermcap.api.indexing import index_root
from thermcap.api.jobs.runner import JobRunner
from thermcap.api.openapi_contract import describe
from thermcap.api.problems import problem
from thermcap.api.reading.frames import FrameReader
from thermcap.api.reading.regions import RegionReader
from thermcap.api.security import AuthGate, BodyLimit
from thermcap.api.settings import Settings
from thermcap.api.storage import make_store
from thermcap.api.verified_files import FileVerifier
from thermcap.recorder import __version__
from thermcap.recorder.radiometry import TemperatureUnavailable

__all__ = ["create_app"]

log = logging.getLogger("thermcap.api")

EXPOSED = ["Accept-Ranges", "Content-Range", "Content-Length", "ETag", "Content-Type", "X-Width", "X-Height"]


class _Rescanner(threading.Thread):
    """Re-index the root now and then, so sessions archived while we were down, or by another
    process, appear without a restart."""

    def __init__(self, app: FastAPI, interval_s: float) -> None:
        super().__init__(name="thermcap-rescan", daemon=True)
        self.app, self.interval_s = app, interval_s
        self.halt = threading.Event()

    def run(self) -> None:
        while not self.halt.wait(self.interval_s):
            try:
                self.app.state.index_damage = index_root(self.app.state.engine, self.app.state.settings.root,
                                                         store=self.app.state.store).damaged
            except Exception as exc:  # never take the service down over a scan
                log.warning("background index failed: %s", exc)


class _Metrics:
    """Pure ASGI middleware (no per-request task, unlike @app.middleware): counts and times requests
    by route template, so /frames/{n} is one series, not one per frame."""

    def __init__(self, app, *, requests_total: Counter, latency: Histogram) -> None:
        self.app, self.requests_total, self.latency = app, requests_total, latency

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t = time.perf_counter()
        status = [500]

        async def send_wrapper(message) -> None:
            if message["type"] == "http.response.start":
                status[0] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_wrapper)
        finally:
            name = getattr(scope.get("route"), "path", "unmatched")
            self.requests_total.labels(name, scope["method"], str(status[0])).inc()
            self.latency.labels(name).observe(time.perf_counter() - t)


def create_app(settings: Settings | None = None, *, index_on_start: bool = True) -> FastAPI:
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        rescan = None
        if index_on_start:
            app.state.index_damage = index_root(app.state.engine, settings.root, store=app.state.store).damaged
        if settings.rescan_interval_s > 0:
            rescan = _Rescanner(app, settings.rescan_interval_s)
            rescan.start()
        yield
        if rescan:
            rescan.halt.set()
        app.state.jobs.close()

    app = FastAPI(title="thermcap", version=__version__, lifespan=lifespan, docs_url=None, redoc_url=None,
                  description="Radiometric thermal sessions: catalog, frames, exports, archives, audits.",
                  openapi_tags=OPENAPI_TAGS, generate_unique_id_function=_operation_id)
    app.state.settings = settings
    app.state.engine = make_engine(settings.db_url)
    app.state.index_damage = {}  # session folder -> the parts the last scan could not serve, and why
    migrate(app.state.engine)
    app.state.store = make_store(settings)
    app.state.frames = FrameReader(app.state.engine, app.state.store, settings.root)
    app.state.regions = RegionReader(app.state.frames, app.state.engine, app.state.store)
    app.state.files = FileVerifier(app.state.store, settings.root)
    app.state.jobs = JobRunner(app.state.engine, app.state.store, scheduler=settings.dask_scheduler)
    registry = CollectorRegistry()
    app.state.metrics_registry = registry
    requests_total = Counter("thermcap_http_requests_total", "HTTP requests", ["route", "method", "status"],
                             registry=registry)
    app.state.frames.damage.counter = Counter(
        "thermcap_damaged_copies_total", "Damaged copies of frames or files met while serving (never served)",
        ["copy"], registry=registry)
    app.state.archives_unverified = Gauge(
        "thermcap_archive_copies_unverified", "Archive copies in the catalog that are not verified (failed, or "
        "marked damaged by scrub) and so not offered", registry=registry)
    latency = Histogram("thermcap_http_request_seconds", "HTTP request latency", ["route"], registry=registry,
                        buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 10))

    app.add_middleware(JsonConventions)  # innermost: it sees the routes' own JSON answers, a HEAD's as its GET's
    app.add_middleware(HeadAsGet, router=app.router)  # HEAD as the GET where no route has HEAD, body dropped last
    app.add_middleware(AuthGate, tokens=settings.tokens)
    # inside the metrics, outside everything else: it checks tokens itself, and hands the rest on
    app.add_middleware(FrameFastPath, engine=app.state.engine, root=settings.root, store_kind=app.state.store.kind,
                       tokens=settings.tokens, locations=app.state.frames.locations, state=app.state)
    # outside the token check and the fast path: a 401 and a fast frame carry CORS headers too, so
    # a browser client can read why it was refused
    app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origins, allow_methods=["GET", "HEAD", "OPTIONS"],
                       allow_headers=["Authorization", "Range", "If-None-Match"], expose_headers=EXPOSED)
    app.add_middleware(_Metrics, requests_total=requests_total, latency=latency)
    app.add_middleware(BodyLimit)  # outermost: no body is read past the limit, token or not

    @app.exception_handler(StarletteHTTPException)  # a route's, and the router's own 404 and 405
    async def http_error(_request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return problem(exc.status_code, exc.detail, headers=getattr(exc, "headers", None))

    @app.exception_handler(FrameNotFound)
    async def frame_not_found(_request: Request, exc: FrameNotFound) -> JSONResponse:
        return problem(404, exc)

    @app.exception_handler(FrameUnavailable)
    async def frame_unavailable(_request: Request, exc: FrameUnavailable) -> JSONResponse:
        # Every copy is missing or damaged: say so rather than serve bytes that are not the recording
        return problem(503, exc)

    @app.exception_handler(TemperatureUnavailable)
    async def no_temperature(_request: Request, exc: TemperatureUnavailable) -> JSONResponse:
        # The counts are served; temperatures for this model need a vendor SDK (a conflict, not an error)
        return problem(409, exc)

    @app.exception_handler(RequestValidationError)
    async def bad_request(_request: Request, exc: RequestValidationError) -> JSONResponse:
        problems = [{"where": ".".join(str(x) for x in e.get("loc", ())),
                     "problem": e.get("msg")} for e in exc.errors()]
        said = "; ".join(f"{p['where']}: {p['problem']}" for p in problems)
        return problem(422, f"invalid request: {said}", problems=problems)

    from thermcap.api.routes import archives, docs, export, frames, jobs, measure, meta, radiometry, sessions, ui, zarr

    for module in (meta, sessions, frames, measure, radiometry, archives, export, jobs, zarr, docs, ui):
        app.include_router(module.router)
    describe(app)
    return app


#: The OpenAPI document's tags, each with what its routes are for.
OPENAPI_TAGS = [
    {"name": "meta", "description": "Health, readiness, Prometheus metrics, the storage audit, re-indexing."},
    {"name": "sessions", "description": "The catalog: sessions by time, sensor and contrast; their frames, events "
                                        "and timelines; frames across every session."},
    {"name": "frames", "description": "One frame: counts (raw, PNG16, TIFF), °C TIFF, previews, sidecar, a "
                                      "pixel's temperature."},
    {"name": "thermography", "description": "Measurements on frames (spots, lines, areas, histograms, isotherms), "
                                            "series over time, radiometric model versions."},
    {"name": "archives", "description": "The verified archive files of a session, hashed while they stream."},
    {"name": "export", "description": "A cut of a session by time and topic, as one MCAP file."},
    {"name": "jobs", "description": "Long work on the fleet's Dask cluster: series, and their results."},
    {"name": "zarr", "description": "Every session as a Zarr store: `xr.open_zarr(url)` reads it lazily."},
]


def _operation_id(route: APIRoute) -> str:
    """Operation ids are the routes' own function names (``list_sessions``), what a generated
    client calls them; FastAPI's default appends the path and method."""
    return route.name

