"""A session a thermcap server serves, read over its HTTP API (``thermcap.Client``)."""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from thermcap.recorder.radiometry.params import ModelVersion
from thermcap.session import Frame, Session

if TYPE_CHECKING:
    import xarray as xr

    from thermcap.archive.reading.frame_table import FrameTable

__all__ = ["RemoteSession"]


class RemoteSession(Session):
    """A session a thermcap server serves: frames over its HTTP API, the Dataset through its
    Zarr endpoint (format 3, read lazily, a shard a request)."""

    def __init__(self, client: Any, session_id: str) -> None:  # a thermcap.Client
        self.client, self.id = client, session_id

    @cached_property
    def detail(self) -> Any:
        """The session as the server describes it (one request, on first use)."""
        return self.client.session(self.id)

    @property
    def width(self) -> int:  # type: ignore[override]
        return int(self.detail.width)

    @property
    def height(self) -> int:  # type: ignore[override]
        return int(self.detail.height)

    @property
    def meta(self) -> dict[str, Any]:  # type: ignore[override]
        d = self.detail
        return {"session_id": self.id, "width": d.width, "height": d.height, "sensor": d.sensor, "fps": d.fps,
                "radiometric_model": d.radiometric_model}

    def frame(self, index: int) -> Frame:
        """One frame in one request (its counts, time and size come together); the sidecar is
        fetched when asked for (``Frame.sidecar``)."""
        if index < 0:
            index += len(self)
        return Frame(index, lambda: int(self.table.timestamp_ns[index]), self.counts(index),
                     lambda: self.sidecar(index))

    @cached_property
    def table(self) -> FrameTable:
        from thermcap.archive.reading.frame_table import FRAME_FIELDS, FrameTable, field_array

        infos = list(self.client.frames(self.id))
        fields = {name: field_array(name, [getattr(f, name) for f in infos]) for name in FRAME_FIELDS}
        return FrameTable(self.id, np.array([f.index for f in infos], np.int64),
                          np.array([f.timestamp_ns for f in infos], np.int64), fields)

    def counts(self, index: int) -> np.ndarray:
        return self.client.frame_counts(self.id, index)

    def sidecar(self, index: int) -> dict[str, Any]:
        return self.client.frame_metadata(self.id, index)

    @property
    def events(self) -> list[dict[str, Any]]:
        return self.client.events(self.id)

    @property
    def model_versions(self) -> list[ModelVersion]:
        return self.client.model_versions(self.id)

    def to_xarray(self, model_version: int | None = None, *, chunk_frames: int | None = None) -> xr.Dataset:
        """The server's Zarr store (format 3), in dask chunks of one served shard each (or of
        ``chunk_frames`` frames): the task graph grows with shards, and each task is one request."""
        import xarray as xr

        if model_version is not None:
            # the server's store gives each frame the latest version covering it: that is one
            # version for the whole session only when the latest covers every frame
            versions = self.model_versions
            latest = max(versions, key=lambda v: v.version, default=None)
            whole = latest is None or latest.frames is None
            if model_version != (latest.version if latest else 0) or not whole:
                raise ValueError(f"model version {model_version}: the server's Zarr store gives each frame the "
                                 f"latest version covering it (pass model_version=None for that); compute other "
                                 f"versions from `counts` with thermcap.open on the data root")
        if chunk_frames is not None and chunk_frames < 1:
            raise ValueError(f"chunk_frames must be at least 1, not {chunk_frames}")
        ds = xr.open_zarr(self.client.zarr_url(self.id), zarr_format=3, chunks=None,
                          storage_options={"headers": self.client.headers})
        frames = chunk_frames or (ds.counts.encoding.get("shards") or ds.counts.encoding.get("chunks") or (1,))[0]
        return ds.chunk({"time": frames})


