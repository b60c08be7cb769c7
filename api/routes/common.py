"""Helpers the route modules share: the session lookup, cursors, times."""

from __future__ import annotations

import base64
import json
import re
from collections.abc import Callable, Hashable
from typing import Annotated, Any, TypeVar

from fastapi import HTTPException, Query, Request, Response
from sqlalchemy import bindparam, select

from thermcap.api import db
from thermcap.api.security import check_session_id
from thermcap.recorder.icd.names import iso_utc, parse_rfc3339
from thermcap.recorder.storage.layout import DataRoot

__all__ = ["CelsiusQuery", "FrameModel", "decode_cursor", "encode_cursor", "frame_model", "iso", "page_size",
           "parse_range", "parse_time", "session_row"]


#: Built once: building ``select(...).where(...)`` costs more than running it (SQLAlchemy coerces
#: every operand), and every frame request looks its session up.
T = TypeVar("T")

_SESSION_ROW = select(db.sessions).where(db.sessions.c.id == bindparam("session_id"))

#: A temperature from a query string: finite and physical, or a 422 naming it (NaN had reached
#: numpy and come back as a 500, or as a bare NaN in the JSON).
CelsiusQuery = Annotated[float | None, Query(ge=-273.15, le=5000, allow_inf_nan=False)]


def session_row(request: Request, session_id: str) -> dict[str, Any]:
    check_session_id(session_id)
    with request.app.state.engine.connect() as conn:
        row = conn.execute(_SESSION_ROW, {"session_id": session_id}).mappings().first()
    if row is None:
        raise HTTPException(404, f"no session {session_id!r}")
    return dict(row)


class FrameModel:
    """The radiometric model a frame's temperatures use here: the session's recorded model, its
    latest re-parameterisation covering the frame (``radiometry.json``), and any object
    parameters given on this request, and what to say about it in the response."""

    def __init__(self, request: Request, row: dict[str, Any]) -> None:
        from thermcap.recorder.exports.render import session_model
        from thermcap.recorder.radiometry.params import OBJECT_PARAMS, read_versions

        self.base = session_model(row["radiometric_model"])
        self.overrides: dict[str, float] = {}
        for name in OBJECT_PARAMS:
            if name in request.query_params:
                try:
                    self.overrides[name] = float(request.query_params[name])
                except ValueError:
                    raise HTTPException(400, f"{name} must be a number") from None
        from thermcap.recorder.radiometry.session import SessionTemperatures

        session_dir = DataRoot.of(request.app.state.settings.root).session_dir(row["id"])
        try:
            self.versions = read_versions(session_dir)
        except ValueError as exc:
            raise HTTPException(500, str(exc)) from None
        self.temps = SessionTemperatures(self.base, self.versions, _bad_pixels(request, row, session_dir),
                                         overrides=self.overrides or None)

    def at(self, frame: int) -> tuple[Any, dict[str, Any]]:
        """The model and what to say of it; built once per version (a series asks for every frame)."""
        try:
            model, version = self.temps.model_for(frame)
        except ValueError as exc:
            raise HTTPException(409, str(exc)) from None
        return model, {"model_version": version, **({"object_parameters": self.overrides} if self.overrides else {})}

    def temperatures(self, frame: int, counts: Any) -> Any:
        """Frame ``frame``'s °C through ``SessionTemperatures``: its model version, bad pixels NaN."""
        try:
            return self.temps.celsius(frame, counts)
        except ValueError as exc:
            raise HTTPException(409, str(exc)) from None


def kept(request: Request, name: str, key: Hashable, build: Callable[[], T], keep: int = 256) -> T:
    """``build()``, computed once per ``key`` and kept on the application under ``name``, at most
    ``keep`` of them (a full cache is dropped whole: the next requests rebuild what they use)."""
    cache: dict[Hashable, Any] = request.app.state.__dict__.setdefault(name, {})
    if key not in cache:
        if len(cache) >= keep:
            cache.clear()
        cache[key] = build()
    return cache[key]


def _bad_pixels(request: Request, row: dict[str, Any], session_dir: Any) -> Any:
    """The session's bad-pixel map, read once per indexed state of the session (its fingerprint)."""
    from thermcap.recorder.radiometry.session import read_bad_pixel_map

    def read() -> Any:
        try:
            return read_bad_pixel_map(session_dir)
        except Exception:  # the folder is gone (served from a bucket): no map to apply
            return None

    return kept(request, "bad_pixel_maps", (row["id"], row.get("fingerprint")), read)


def frame_model(request: Request, row: dict[str, Any], frame: int) -> tuple[Any, dict[str, Any]]:
    return FrameModel(request, row).at(frame)


def encode_cursor(values: list[Any]) -> str:
    return base64.urlsafe_b64encode(json.dumps(values).encode()).decode().rstrip("=")


def decode_cursor(cursor: str | None, types: tuple[type, ...]) -> list[Any] | None:
    """A cursor this service issued: a list of values of exactly ``types`` (ints within int64).
    Anything else, however it decodes, is a 400, never a 500 further down."""
    if not cursor:
        return None
    try:
        values = json.loads(base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)))
    except (ValueError, TypeError):
        raise HTTPException(400, "invalid cursor") from None
    ok = isinstance(values, list) and len(values) == len(types) and all(
        type(v) is t and (not isinstance(v, int) or -2**63 <= v < 2**63) for v, t in zip(values, types, strict=False))
    if not ok:
        raise HTTPException(400, "invalid cursor")
    return values


def parse_time(value: str | None, name: str) -> int | None:
    if value is None:
        return None
    try:
        return parse_rfc3339(value)
    except ValueError as exc:
        raise HTTPException(400, f"{name}: {exc}") from None


def iso(ns: int | None) -> str | None:
    return None if ns is None else iso_utc(ns)


def page_size(request: Request, limit: int, response: Response) -> int:
    """The page's size: ``limit``, or the server's most, said in ``X-Limit-Clamped`` when less
    than asked (a client paging by count must know its pages are smaller)."""
    cap = request.app.state.settings.max_page_size
    if limit < 1:
        raise HTTPException(400, "limit must be at least 1")
    if limit > cap:
        response.headers["X-Limit-Clamped"] = str(cap)
    return min(limit, cap)


_RANGE = re.compile(r"^bytes=(\d{0,18})-(\d{0,18})$")  # longer numbers: nothing served is that big (416)


def parse_range(header: str, size: int) -> tuple[int, int] | None:
    """``Range: bytes=a-b | a- | -n`` as [start, end) for a single satisfiable range; None to serve it
    all (several ranges: RFC 9110 lets a server answer with the whole); raises 416."""
    m = _RANGE.match(header.strip())
    if not m or (not m[1] and not m[2]):
        if "," in header:
            return None  # several ranges: RFC 9110 lets us answer with the whole file
        raise HTTPException(416, f"unsupported Range {header!r}", headers={"Content-Range": f"bytes */{size}"})
    if m[1]:
        start = int(m[1])
        end = min(int(m[2]) + 1, size) if m[2] else size
        if m[2] and int(m[2]) < start:
            raise HTTPException(416, "range end before start", headers={"Content-Range": f"bytes */{size}"})
    else:
        start, end = max(0, size - int(m[2])), size
    if start >= size or end <= start:
        raise HTTPException(416, f"range not satisfiable for {size} bytes",
                            headers={"Content-Range": f"bytes */{size}"})
    return start, end
