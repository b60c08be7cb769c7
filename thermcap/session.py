"""A recorded session in Python, wherever it is: a folder on disk, an id under a data root, or a
session a thermcap server serves over HTTP.

``open`` returns a ``Session``: its metadata, events and radiometric model versions, frames by
index or by time, and ``to_xarray()``, a lazy Dataset of the counts (uint16, bit-exact) and the
temperatures (float32 °C). Every frame comes from the same verified readers ``thermcap serve``
uses (the MCAP source while it exists, else a verified archive copy), so a count read here is
the count recorded.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from thermcap.recorder.radiometry.params import ModelVersion

if TYPE_CHECKING:
    import xarray as xr

    from thermcap.archive.reading.frame_table import FrameTable

__all__ = ["Frame", "LocalSession", "ModelVersion", "Session"]

class Frame:
    """One frame: its counts exactly as recorded, its time and its ICD sidecar. Over HTTP the
    time and the sidecar are fetched when first asked for: most readers only want counts."""

    def __init__(self, index: int, time_ns: int | Callable[[], int], counts: np.ndarray,
                 sidecar: dict[str, Any] | Callable[[], dict[str, Any]]) -> None:
        self.index = index
        self.counts = counts  # (H, W) uint16, read-only
        self._time, self._sidecar = time_ns, sidecar

    def __repr__(self) -> str:
        return f"<Frame {self.index}: {self.counts.shape[1]}x{self.counts.shape[0]} {self.counts.dtype}>"

    @cached_property
    def time_ns(self) -> int:
        """Log time, ns since the Unix epoch."""
        return int(self._time() if callable(self._time) else self._time)

    @cached_property
    def sidecar(self) -> dict[str, Any]:
        return dict(self._sidecar() if callable(self._sidecar) else self._sidecar)

    @property
    def time(self) -> np.datetime64:
        return np.datetime64(self.time_ns, "ns")


class Session(ABC):
    """What every session offers, wherever it is read from."""

    id: str
    meta: dict[str, Any]

    @property
    @abstractmethod
    def table(self) -> FrameTable:
        """Every frame's time and sidecar summary, as arrays (read once)."""

    @abstractmethod
    def counts(self, index: int) -> np.ndarray:
        """Frame ``index``'s counts, (H, W) uint16, bit-exact."""

    @abstractmethod
    def sidecar(self, index: int) -> dict[str, Any]:
        """Frame ``index``'s ICD sidecar as recorded."""

    @property
    @abstractmethod
    def events(self) -> list[dict[str, Any]]:
        """The session's events (kind, start/end ns, detail), in time order."""

    @property
    @abstractmethod
    def model_versions(self) -> list[ModelVersion]:
        """The re-parameterisations after capture (``thermcap radiometry``); version 0, the model
        recorded, is ``radiometric_model``."""

    @abstractmethod
    def to_xarray(self, model_version: int | None = None, *, chunk_frames: int | None = None) -> xr.Dataset:
        """A lazy Dataset: ``counts`` and ``temperature`` (time, y, x), read only when asked, in
        dask chunks of ``chunk_frames`` frames (None: the session's own, 16 frames read here,
        a served shard over HTTP)."""

    # -- shared by every kind of session ------------------------------------------------------

    def __len__(self) -> int:
        return len(self.table)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.id!r}: {len(self)} frames, {self.width}x{self.height}>"

    width: int
    height: int

    @property
    def radiometric_model(self) -> dict[str, Any]:
        return dict(self.meta.get("radiometric_model") or {"kind": "linear"})

    @property
    def times(self) -> np.ndarray:
        """Every frame's time, datetime64[ns]."""
        return self.table.timestamp_ns.astype("datetime64[ns]")

    def frame(self, index: int) -> Frame:
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"frame {index}: session {self.id!r} has {n} frames")
        index %= n
        number = int(self.table.index[index])
        return Frame(number, int(self.table.timestamp_ns[index]), self.counts(number), self.sidecar(number))

    def __getitem__(self, index: int) -> Frame:
        return self.frame(index)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self.frame(i)

    def frame_at(self, when: str | int | np.datetime64) -> Frame:
        """The frame shown at ``when`` (an RFC 3339 time, a datetime64, or ns since the epoch):
        the last one logged at or before it."""
        if isinstance(when, int):
            t = when
        else:
            text = when.rstrip("Z") if isinstance(when, str) else when  # numpy reads UTC times without the Z
            t = int(np.datetime64(text, "ns").astype(np.int64))  # type: ignore[call-overload]
        i = int(np.searchsorted(self.table.timestamp_ns, t, side="right")) - 1
        if i < 0:
            raise IndexError(f"{when}: before session {self.id!r} began")
        return self.frame(i)


def _coords(table: FrameTable, height: int, width: int) -> dict[str, Any]:
    from thermcap.archive.reading.dataset_description import PIXEL_AXIS_DTYPE, coordinate_attrs
    from thermcap.archive.reading.frame_table import FRAME_FIELDS

    coords: dict[str, Any] = {"time": ("time", table.timestamp_ns.astype("datetime64[ns]"), coordinate_attrs("time")),
                              "frame": ("time", table.index, coordinate_attrs("frame"))}
    for name in FRAME_FIELDS:
        coords[name] = ("time", table.fields[name], coordinate_attrs(name))
    for axis, size in (("y", height), ("x", width)):
        coords[axis] = (axis, np.arange(size, dtype=PIXEL_AXIS_DTYPE), coordinate_attrs(axis))
    return coords


class LocalSession(Session):
    """A session folder on this machine, read where it lies: numbered as the index numbers it,
    every frame from the first copy that verifies (``archive.reading.folder``). Opening and
    reading write nothing, and need none of the server's packages."""

    def __init__(self, session_dir: Path, root: Path) -> None:
        from thermcap.archive.reading.folder import FolderFrames
        from thermcap.recorder.storage.reader import read_session_meta

        self.session_dir, self.root = session_dir, root
        self.meta = read_session_meta(session_dir)
        self.id = str(self.meta.get("session_id") or session_dir.name)
        self.frames = FolderFrames(session_dir, self.id)
        self.problems = self.frames.problems  # what could not be read (damaged chunks, lost segments)
        self.width, self.height = self._size()

    def _size(self) -> tuple[int, int]:
        sidecars = self.frames.numbered.sidecars
        res = ((sidecars[0] if sidecars else {}).get("sensor") or {}).get("resolution") or {}
        src = (self.frames.numbered.manifest or {}).get("source") or {}
        return int(res.get("width") or src.get("width") or 0), int(res.get("height") or src.get("height") or 0)

    @property
    def table(self) -> FrameTable:
        return self.frames.table

    def counts(self, index: int) -> np.ndarray:
        return self.frames.pixels(index)

    def sidecar(self, index: int) -> dict[str, Any]:
        return self.frames.sidecar(index)

    @cached_property
    def events(self) -> list[dict[str, Any]]:
        from thermcap.recorder.storage.layout import SessionLayout

        try:
            doc = json.loads(SessionLayout.of(self.session_dir).events_json.read_text())
        except (OSError, ValueError):
            return []
        events = [{"kind": e["kind"], "start_ns": e["start_ns"], "end_ns": e["end_ns"], "detail": e.get("detail", {})}
                  for e in doc.get("events") or [] if isinstance(e, dict) and "kind" in e]
        return sorted(events, key=lambda e: (e["start_ns"] or 0))

    @property
    def model_versions(self) -> list[ModelVersion]:
        from thermcap.recorder.radiometry.params import read_versions

        return read_versions(self.session_dir)

    def temperatures(self, model_version: int | None = None, bad_pixels: str = "nan") -> Any:
        """The session's ``SessionTemperatures``: the model (a version, or the latest covering
        each frame) and the bad-pixel rule every temperature here is computed with."""
        from thermcap.recorder.radiometry.session import SessionTemperatures

        return SessionTemperatures.of(self.session_dir, self.meta, version=model_version, bad_pixels=bad_pixels)

    def temperature(self, index: int, model_version: int | None = None) -> np.ndarray:
        """Frame ``index`` in °C (float32), bad pixels NaN."""
        return self.temperatures(model_version).celsius(index, self.counts(index)).celsius

    def to_xarray(self, model_version: int | None = None, *, chunk_frames: int | None = None) -> xr.Dataset:
        return lazy_dataset(self, self.temperatures(model_version), model_version, chunk_frames)


#: frames a dask chunk holds when a session read here is opened as a Dataset
LOCAL_CHUNK_FRAMES = 16


def lazy_dataset(session: Session, temps: Any, model_version: int | None, chunk_frames: int | None) -> xr.Dataset:
    """The Dataset of a session whose frames this process reads itself (a folder, a bucket):
    dask chunks of ``chunk_frames`` frames through ``session.counts``, temperatures through
    ``temps`` (a ``SessionTemperatures``, checked before anything is read)."""
    import dask.array as da
    import xarray as xr

    if chunk_frames is None:
        chunk_frames = LOCAL_CHUNK_FRAMES
    if chunk_frames < 1:
        raise ValueError(f"chunk_frames must be at least 1, not {chunk_frames}")
    table, h, w = session.table, session.height, session.width
    n = len(table)
    sizes = tuple(min(chunk_frames, n - s) for s in range(0, n, chunk_frames)) or (0,)
    numbers = table.index

    def read_counts(block_info: dict | None = None) -> np.ndarray:
        assert block_info is not None
        (a, b), _, _ = block_info[None]["array-location"]
        return np.stack([session.counts(int(k)) for k in numbers[a:b]]) if b > a else np.empty((0, h, w), np.uint16)

    counts = da.map_blocks(read_counts, chunks=(sizes, (h,), (w,)), dtype=np.uint16,
                           meta=np.empty((0, 0, 0), np.uint16), name=f"thermcap-counts-{type(session).__name__}-"
                                                                      f"{session.id}")

    def to_celsius(block: np.ndarray, block_info: dict | None = None) -> np.ndarray:
        assert block_info is not None
        a, b = block_info[0]["array-location"][0]
        out = np.empty(block.shape, np.float32)
        for j, k in enumerate(numbers[a:b]):
            out[j] = temps.celsius(int(k), block[j]).celsius
        return out

    celsius = da.map_blocks(to_celsius, counts, dtype=np.float32, meta=np.empty((0, 0, 0), np.float32))
    from thermcap.archive.reading.dataset_description import session_attrs, variable_attrs
    from thermcap.recorder.radiometry.params import models_named

    named = models_named(session.radiometric_model, list(getattr(temps, "versions", None) or []), model_version)
    return xr.Dataset(
        {"counts": (("time", "y", "x"), counts, variable_attrs("counts")),
         "temperature": (("time", "y", "x"), celsius, variable_attrs("temperature", named["model_version"]))},
        coords=_coords(table, h, w),
        attrs=session_attrs(session.id, session.meta.get("sensor"), session.meta.get("frames_dropped"), named))
