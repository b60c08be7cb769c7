"""An archive format: how a session's frames become files, and how the files give them back.

``write(frames, out_dir, context)`` writes every frame (the ``SessionFrame`` stream of
``recorder.storage.reader``) into files under ``out_dir`` and returns one ``FileRecord`` per file;
``read(out_dir, files)`` yields the frames back in session order using the format's ordinary
reader (zipfile + the image codec, tifffile, h5py), which is what verification trusts.
Per-segment formats write one file per MCAP segment, so an hour is tens of objects.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np

from thermcap.archive.exceptions import UnknownCodecError
from thermcap.archive.parallel import ordered_map
from thermcap.recorder.icd.names import format_name
from thermcap.recorder.radiometry import LinearModel, model_from_dict
from thermcap.recorder.registry import Registry
from thermcap.recorder.storage.digest import DEFAULT_DIGEST
from thermcap.recorder.storage.reader import SessionFrame

__all__ = [
    "ArchiveContext",
    "ArchiveFormat",
    "DecodedFrame",
    "FileRecord",
    "RowBlock",
    "format_registry",
    "frame_name",
    "get_format",
    "locate",
    "ordered_map",
    "positions_in",
    "register_format",
]

T = TypeVar("T")
R = TypeVar("R")


@dataclass
class FileRecord:
    path: str  # relative to the format's folder
    frames: int
    bytes: int = 0
    digest: str = ""  #: the file's, by ``ArchiveContext.digest``'s hash


@dataclass
class DecodedFrame:
    """One frame as a format's own reader gives it back: what verification compares with the
    source, every part of it (a frame is its counts, its sidecar and its time)."""

    pixels: np.ndarray
    sidecar: bytes
    log_time: int | None  # None where an old archive did not store it apart from the sidecar


@dataclass(frozen=True)
class RowBlock:
    """Part of one frame: rows ``first_row .. first_row + len(rows)`` of session frame ``index``."""

    index: int
    first_row: int
    rows: np.ndarray


@dataclass
class ArchiveContext:
    """What a format may need besides the frames: the session's metadata and a thread budget."""

    session_id: str
    session_meta: dict[str, Any] = field(default_factory=dict)
    total_frames: int | None = None
    frames_per_segment: dict[str, int] = field(default_factory=dict)
    workers: int = 2
    on_frame: Callable[[], None] | None = None
    digest: str = DEFAULT_DIGEST  #: the hash each file written is recorded by (recorder.storage.digest)

    @property
    def sensor_id(self) -> str:
        return (self.session_meta.get("sensor") or {}).get("sensor_id") or "SENSOR"

    @property
    def temp_range(self) -> tuple[float, float]:
        try:
            model = model_from_dict(self.session_meta.get("radiometric_model") or {"kind": "linear"})
        except ValueError:
            return (-40.0, 550.0)
        if isinstance(model, LinearModel):
            return (model.temp_min_c, model.temp_max_c)
        rng = self.session_meta.get("scene_temp_range_c") or (-40.0, 550.0)
        return (float(rng[0]), float(rng[1]))


def frame_name(ctx: ArchiveContext, frame: SessionFrame) -> str:
    """The ICD file name of a frame (no extension): thermal_<UTC time>_<sensor>_<range>."""
    return format_name(frame.log_time, ctx.sensor_id, *ctx.temp_range)


class ArchiveFormat(ABC):
    format_id: str  # a class constant, except where one class serves several ids (ZippedFrames)
    description: ClassVar[str]

    @abstractmethod
    def write(self, frames: Iterable[SessionFrame], out_dir: Path, ctx: ArchiveContext) -> list[FileRecord]: ...

    @abstractmethod
    def read(self, out_dir: Path, files: list[str], workers: int = 2) -> Iterator[DecodedFrame]:
        """Frames in session order, with their sidecars and times, decoded by the format's
        ordinary reader on up to ``workers`` threads: two where a format is read alone (verify,
        scrub), its share of the cores where the archive reads several back at once
        (``ArchiveContext.workers``), since more threads than cores cost CPU in switching."""

    def read_frame(self, open_file: Callable[[str], Any], files: list[dict[str, Any]], index: int) -> DecodedFrame:
        """Frame ``index`` of the session (pixels, sidecar, time) with as little reading as the
        format allows. ``open_file(path)`` gives a seekable binary file for one of ``files``
        (local, or ranged reads from an object store). Formats with random access override it;
        this default walks the one file that holds the frame."""
        rel, k = locate(files, index)
        import tempfile

        with open_file(rel) as src, tempfile.TemporaryDirectory() as tmp:
            local = Path(tmp) / Path(rel).name
            with open(local, "wb") as dst:
                while chunk := src.read(1 << 20):
                    dst.write(chunk)
            for i, frame in enumerate(self.read(Path(tmp), [local.name])):
                if i == k:
                    return frame
        raise IndexError(f"{rel} holds fewer than {k + 1} frames")

    def assemble(self, parts: list[tuple[Path, list[dict[str, Any]]]], out_dir: Path,
                 ctx: ArchiveContext) -> list[FileRecord] | None:
        """The session's files in ``out_dir`` from per-segment parts (each a folder and the
        files this format wrote there for one segment, verified), or None where a format keeps
        one file per segment, so the parts' files are the session's as they are. A format with
        one file per session (hdf5) joins them without encoding again."""
        return None

    def read_rows(self, open_file: Callable[[str], Any], files: list[dict[str, Any]], indices: range,
                  y0: int, y1: int) -> Iterator[RowBlock] | None:
        """Rows ``y0..y1`` (exclusive) of the frames ``indices`` (a step of 1 or more), decoding
        only what holds them, or None where the format cannot read part of a frame. Each block
        covers whole storage units (TIFF strips): ``first_row`` is where it starts, so the
        caller can check it against the frame summary's band checksums before using it."""
        return None

    def get_config(self) -> dict[str, Any]:
        return {"id": self.format_id}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.get_config()})"


def positions_in(r: range, lo: int, hi: int) -> slice:
    """The positions of ``r`` (step >= 1) whose values lie in [lo, hi), without walking it:
    ``r[positions_in(r, lo, hi)]`` is the part of a frame range one file holds."""
    a = max(0, -(-(lo - r.start) // r.step))
    return slice(a, max(a, -(-(hi - r.start) // r.step)))


def locate(files: list[dict[str, Any]], index: int) -> tuple[str, int]:
    """(file path, position in it) of session frame ``index``, from the manifest's file list."""
    if index < 0:
        raise IndexError(f"no frame {index}")
    for rec in files:
        if index < rec["frames"]:
            return rec["path"], index
        index -= rec["frames"]
    raise IndexError("frame beyond the archive's files")


format_registry: Registry[ArchiveFormat] = Registry("format", UnknownCodecError)


@dataclass(frozen=True, order=True)
class ReadCost:
    """What reading a copy costs, as ranks a reader orders copies by (lower first): ``frame`` is
    one frame alone by ranged reads (a browser's request, a Zarr chunk), ``stream`` every frame in
    order (an export, an analysis, a repair). ``thermcap bench archive`` measures the decoders
    behind them; a format declares its costs where it is registered, so every reader of copies
    takes them in one order."""

    frame: int
    stream: int


#: The MCAP source, as a copy beside the archive's: a chunk read and decompressed for a frame.
MCAP_SOURCE_COST = ReadCost(frame=50, stream=15)
_read_costs: dict[str, ReadCost] = {}


_UNDECLARED = ReadCost(10**6, 10**6)


def register_format(format_id: str, factory: Callable[..., ArchiveFormat], cost: ReadCost = _UNDECLARED) -> None:
    """``cost``: what reading it costs beside the other formats; one that declares none is read last."""
    format_registry.register(format_id, factory)
    _read_costs[format_id] = cost


def read_cost(format_id: str) -> ReadCost:
    """The declared cost of reading format ``format_id`` (an unknown id last)."""
    return _read_costs.get(format_id, _UNDECLARED)


def get_format(config: dict[str, Any] | str) -> ArchiveFormat:
    return format_registry.build(config)


def group_by_segment(frames: Iterable[SessionFrame]) -> Iterator[tuple[str, Iterator[SessionFrame]]]:
    """Split the session's frame stream into per-segment runs without materialising them."""
    it = iter(frames)
    try:
        first = next(it)
    except StopIteration:
        return
    state: dict[str, Any] = {"next": first}

    def run(segment: str) -> Iterator[SessionFrame]:
        while state["next"] is not None and state["next"].segment == segment:
            yield state["next"]
            state["next"] = next(it, None)

    while state["next"] is not None:
        seg = state["next"].segment
        yield seg, run(seg)
        # a consumer that stopped early: skip the rest of this segment
        while state["next"] is not None and state["next"].segment == seg:
            state["next"] = next(it, None)


def sidecar_text(frame: SessionFrame) -> str:
    """The sidecar exactly as recorded (the archiver refuses a source frame without one)."""
    return frame.sidecar.decode("utf-8") if frame.sidecar else json.dumps({})


def time_from_sidecar(sidecar: bytes) -> int | None:
    from thermcap.recorder.icd.names import parse_rfc3339

    try:
        return parse_rfc3339(json.loads(sidecar)["capture"]["timestamp"])
    except (ValueError, KeyError, TypeError):
        return None

