"""``thermcap.Client``: the HTTP API from Python, with typed results.

Listings page through the server's cursors for you (iterators: a catalog of thousands is read a
page at a time); frames come back as numpy arrays exactly as stored; an error is a
``ServerError`` carrying the status and what the server said, never a bare HTTP exception.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.radiometry.params import ModelVersion

__all__ = ["Client", "FrameInfo", "Job", "ServerError", "SessionInfo"]


class ServerError(RuntimeError):
    """The server answered with an error: ``status`` and its own words (``message``)."""

    def __init__(self, status: int, message: str, url: str) -> None:
        super().__init__(f"{status} from {url}: {message}")
        self.status, self.message, self.url = status, message, url


def _fields(cls: type, data: dict[str, Any]) -> dict[str, Any]:
    names = {f.name for f in dataclasses.fields(cls)}
    return {k: v for k, v in data.items() if k in names}


@dataclass(frozen=True)
class SessionInfo:
    """A session as the catalog lists it (``raw`` keeps every field the server sent)."""

    id: str
    sensor: str | None = None
    sensor_id: str | None = None
    width: int = 0
    height: int = 0
    fps: float | None = None
    start_ns: int | None = None
    end_ns: int | None = None
    frames: int = 0
    frames_dropped: int = 0
    status: str | None = None
    radiometric_model: dict[str, Any] | None = None
    source_deleted: bool = False
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SessionInfo:
        return cls(**_fields(cls, data), raw=data)


@dataclass(frozen=True)
class FrameInfo:
    """A frame as the index knows it: its time and sidecar summary (no pixels)."""

    index: int
    timestamp_ns: int
    segment: str | None = None
    thermal_contrast_grade: float | None = None
    slew_to_cue_active: bool = False
    target_count: int = 0
    max_target_temp_c: float | None = None
    session_id: str | None = None

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> FrameInfo:
        return cls(**_fields(cls, data))


@dataclass(frozen=True)
class Job:
    id: str
    kind: str
    state: str
    session_id: str | None = None
    error: str | None = None
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Job:
        return cls(**_fields(cls, data), raw=data)


class Client:
    """A thermcap server at ``url`` (``http://127.0.0.1:8000``), with its token when it has tokens."""

    def __init__(self, url: str, token: str | None = None, *, timeout: float = 60.0) -> None:
        import httpx

        self.url = url.rstrip("/")
        self.headers = {"Authorization": f"Bearer {token}"} if token else {}
        # plain http has no TLS to verify: skip building a certificate store (tens of ms a client)
        verify = not self.url.startswith("http://")
        self._http = httpx.Client(base_url=self.url, headers=self.headers, timeout=timeout, verify=verify)

    def __repr__(self) -> str:
        return f"<thermcap.Client {self.url}>"  # never the token

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._http.close()

    # -- the wire ------------------------------------------------------------------------------

    def _get(self, path: str, params: dict[str, Any] | None = None) -> Any:
        import httpx

        clean = {k: (str(v).lower() if isinstance(v, bool) else v) for k, v in (params or {}).items() if v is not None}
        try:
            r = self._http.get(path, params=clean)
        except httpx.HTTPError as exc:
            raise ServerError(0, f"no answer ({type(exc).__name__}: {exc})", f"{self.url}{path}") from None
        if r.status_code >= 400:
            try:
                said = r.json()
                message = said.get("error") or said.get("detail") or r.text
                if said.get("problems"):
                    message = f"{message}: " + "; ".join(f"{p['where']}: {p['problem']}" for p in said["problems"])
            except ValueError:
                message = r.text[:500]
            raise ServerError(r.status_code, str(message), str(r.url))
        return r

    def _pages(self, path: str, params: dict[str, Any]) -> Iterator[dict[str, Any]]:
        cursor = None
        while True:
            page = self._get(path, {**params, "cursor": cursor}).json()
            yield from page["items"]
            cursor = page.get("next_cursor")
            if not cursor:
                return

    # -- the catalog ---------------------------------------------------------------------------

    def sessions(self, *, sensor: str | None = None, start: str | None = None, end: str | None = None,
                 min_grade: float | None = None, max_grade: float | None = None, has_targets: bool | None = None,
                 sort: str = "-start", page_size: int = 100) -> Iterator[SessionInfo]:
        """Sessions overlapping [start, end) (RFC 3339), newest first; every page, lazily."""
        params = {"sensor": sensor, "start": start, "end": end, "min_grade": min_grade, "max_grade": max_grade,
                  "has_targets": has_targets, "sort": sort, "limit": page_size}
        for item in self._pages("/api/v1/sessions", params):
            yield SessionInfo.from_dict(item)

    def session(self, session_id: str) -> SessionInfo:
        return SessionInfo.from_dict(self._get(f"/api/v1/sessions/{session_id}").json())

    def frames(self, session_id: str, *, start: str | None = None, end: str | None = None,
               min_grade: float | None = None, max_grade: float | None = None, has_targets: bool | None = None,
               page_size: int = 1000) -> Iterator[FrameInfo]:
        params = {"start": start, "end": end, "min_grade": min_grade, "max_grade": max_grade,
                  "has_targets": has_targets, "limit": page_size}
        for item in self._pages(f"/api/v1/sessions/{session_id}/frames", params):
            yield FrameInfo.from_dict(item)

    def search_frames(self, *, max_grade: float | None = None, min_target_c: float | None = None,
                      page_size: int = 1000, **filters: Any) -> Iterator[FrameInfo]:
        """Frames across every session (``/api/v1/frames``): each with its ``session_id``."""
        params = {"max_grade": max_grade, "min_target_c": min_target_c, "limit": page_size, **filters}
        for item in self._pages("/api/v1/frames", params):
            yield FrameInfo.from_dict(item)

    def events(self, session_id: str, kind: str | None = None) -> list[dict[str, Any]]:
        return list(self._get(f"/api/v1/sessions/{session_id}/events", {"kind": kind}).json()["items"])

    def model_versions(self, session_id: str) -> list[ModelVersion]:
        data = self._get(f"/api/v1/sessions/{session_id}/radiometry").json()
        out = []
        for v in data["versions"]:
            frames = v.get("frames")
            out.append(ModelVersion(**{**v, "frames": tuple(frames) if frames else None}))
        return out

    # -- frames ---------------------------------------------------------------------------------

    def frame_counts(self, session_id: str, index: int) -> np.ndarray:
        """Frame ``index``'s counts, (H, W) uint16, exactly as stored."""
        r = self._get(f"/api/v1/sessions/{session_id}/frames/{index}", {"format": "raw"})
        h, w = int(r.headers["X-Height"]), int(r.headers["X-Width"])
        data = np.frombuffer(r.content, dtype="<u2")
        if data.size != h * w:
            raise ServerError(r.status_code, f"{data.size} counts for a {w}x{h} frame", str(r.url))
        return data.reshape(h, w).astype(np.uint16, copy=False)

    def frame_metadata(self, session_id: str, index: int) -> dict[str, Any]:
        return dict(self._get(f"/api/v1/sessions/{session_id}/frames/{index}/metadata").json())

    def zarr_url(self, session_id: str) -> str:
        return f"{self.url}/api/v1/sessions/{session_id}/zarr"

    def open(self, session_id: str) -> Any:
        """The session as a ``thermcap.Session`` (frames, ``to_xarray()`` over the Zarr endpoint)."""
        from thermcap.remote import RemoteSession

        return RemoteSession(self, session_id)

    # -- exports and jobs ----------------------------------------------------------------------

    def export_mcap(self, session_id: str, out: str | Path, *, start: str | None = None, end: str | None = None,
                    topics: list[str] | None = None) -> Path:
        """A cut of the session as one MCAP file at ``out`` (streamed; written whole or not at all)."""
        import httpx

        out = Path(out)
        part = out.with_name(out.name + ".partial")
        params = {k: v for k, v in {"start": start, "end": end,
                                    "topics": ",".join(topics) if topics else None}.items() if v is not None}
        url = f"/api/v1/sessions/{session_id}/export.mcap"
        try:
            with self._http.stream("GET", url, params=params) as r:
                if r.status_code >= 400:
                    r.read()
                    self._raise_for(r)
                with open(part, "wb") as f:
                    for block in r.iter_bytes(1 << 20):
                        f.write(block)
        except httpx.HTTPError as exc:
            part.unlink(missing_ok=True)
            raise ServerError(0, f"no answer ({type(exc).__name__}: {exc})", f"{self.url}{url}") from None
        part.replace(out)
        return out

    def _raise_for(self, r: Any) -> None:
        try:
            message = r.json().get("error") or r.text
        except ValueError:
            message = r.text[:500]
        raise ServerError(r.status_code, str(message), str(r.url))

    def jobs(self, *, state: str | None = None, kind: str | None = None, session_id: str | None = None,
             limit: int = 100) -> list[Job]:
        data = self._get("/api/v1/jobs", {"state": state, "kind": kind, "session": session_id, "limit": limit}).json()
        return [Job.from_dict(j) for j in data["items"]]

    def job(self, job_id: str) -> Job:
        return Job.from_dict(self._get(f"/api/v1/jobs/{job_id}").json())
