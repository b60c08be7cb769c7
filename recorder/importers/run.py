"""``thermcap import``: files and folders into recorded sessions, through the recorder's own path.

Two passes: the first reads every file, detects its format by content and checks it (a corrupt
or unsupported file is reported with its reason and left out, so nothing half-read is ever
written); the second records the good frames, ordered by capture time, as ordinary sessions.
Files with different frame sizes or radiometric models go to separate sessions (one model per
session is what lets the API compute temperatures); ``session_per_file`` splits further. DJI
frames measured by an SDK backend (``dji_sdk.py``) carry per-count tables, and frames whose tables
agree share a session and one merged table. Vendor
metadata travels on ``/import/source`` (one message per frame) and calibration blobs as MCAP
attachments, bit-exact.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, cast

import numpy as np

from thermcap.recorder.capture.recorder import Recorder, RecordingResult, new_session_id
from thermcap.recorder.capture.sources.base import CapturedFrame, FrameSource, SensorInfo
from thermcap.recorder.importers import ImportedFrame, ImportFileError, TruncatedImageError, iter_file
from thermcap.recorder.importers.dji_sdk import DjiBackend
from thermcap.recorder.radiometry import LookupTableModel, RadiometricModel, TemperatureUnavailable, describe_model
from thermcap.recorder.storage.digest import frame_sha256

__all__ = ["ImportReport", "import_paths"]

TOPIC_IMPORT = "/import/source"
SDK_BATCH = 96  # files measured per SDK call: amortises its start-up, bounds the frames held
_IMPORT_SCHEMA = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "thermcap.ImportSource",
                  "type": "object", "properties": {"path": {"type": "string"}, "format": {"type": "string"},
                                                   "layout": {"type": ["string", "null"]},
                                                   "vendor": {"type": "object"}},
                  "required": ["path", "format"]}


@dataclass
class ImportReport:
    files: list[dict[str, Any]]
    sessions: list[RecordingResult]
    failed: list[dict[str, str]]
    #: files whose complete images were imported but whose last image is cut (named by byte count)
    truncated: list[dict[str, Any]] = field(default_factory=list)


def _walk(paths: list[str]) -> list[str]:
    out = []
    for p in paths:
        if os.path.isdir(p):
            for dirpath, _dirs, names in sorted(os.walk(p)):
                for n in sorted(names):
                    if n.endswith((".json", ".txt", ".md")) or n.startswith(".") or n == "metadata.yaml":
                        continue  # sidecars, notes and a bag's metadata are read with the file they describe
                    out.append(os.path.join(dirpath, n))
        else:
            out.append(p)
    return out


def celsius_stats(model: Any, pixels: np.ndarray) -> dict[str, float]:
    """min, max and mean temperature of a frame through its model, computed per distinct count
    (a model maps a count to one temperature): a few thousand model evaluations instead of one
    per pixel, 10x faster on Planck models, the same numbers. NaN temperatures are left out."""
    hist = np.bincount(np.asarray(pixels, dtype=np.uint16).ravel(), minlength=1)
    counts = np.flatnonzero(hist)
    temps = np.asarray(model.to_celsius(counts.astype(np.uint16)), dtype=np.float64)
    ok = np.isfinite(temps)
    if not ok.any():
        return {"min": float("nan"), "max": float("nan"), "mean": float("nan")}
    w = hist[counts][ok]
    return {"min": float(temps[ok].min()), "max": float(temps[ok].max()),
            "mean": float(np.dot(temps[ok], w) / w.sum())}


#: The readers' words on what they left out or found short (``vendor_metadata``), in the report too.
IMPORT_NOTES = ("pages_left_out", "skipped_before", "skipped_after", "short_trailer")


def _summary(f: ImportedFrame) -> dict[str, Any]:
    celsius: dict[str, Any] | None
    try:
        celsius = {k: round(v, 4) for k, v in celsius_stats(f.model, f.pixels).items()}
        if getattr(f.model, "approximate", False):
            celsius["approximate"] = True
    except TemperatureUnavailable as exc:
        celsius = None
        reason = str(exc)
    out = {"path": f.path, "format": f.format, "layout": f.layout, "frame_index": f.frame_index,
           "width": int(f.pixels.shape[1]), "height": int(f.pixels.shape[0]),
           "raw_sha256": frame_sha256(f.pixels),
           "celsius": celsius, "model": describe_model(f.model)}
    notes = {k: f.vendor_metadata[k] for k in IMPORT_NOTES if k in f.vendor_metadata}
    if notes:  # what the reader left out of the file or found short, in the report as in the recording
        out["notes"] = _jsonable(notes)
    if celsius is None:
        out["celsius_unavailable"] = reason
        out["missing"] = {"temperature": reason}  # imported, counts bit-exact: only the °C is absent
    elif celsius.get("approximate"):
        out["missing"] = {"exact_temperature": "the approximate DJI formula (no DJI SDK backend)"}
    return out


class _ImportSource(FrameSource):
    """Replays checked files (re-read now, so memory holds one file at a time)."""

    name = "import"
    extra_topics: ClassVar[dict[str, dict[str, Any]]] = {TOPIC_IMPORT: _IMPORT_SCHEMA}

    def __init__(self, items: list[tuple[str, int, int]], first: ImportedFrame, model: RadiometricModel) -> None:
        self.items = items  # (path, frame index within file, timestamp ns)
        self.model = model
        self._frames = _FrameCursor()
        h, w = first.pixels.shape
        self.sensor = SensorInfo(model=first.sensor_model or first.format, sensor_id=first.sensor_id, width=w, height=h,
                                 frame_rate_hz=1.0, pixel_pitch_um=None, netd_mk=None, serial_number="unknown",
                                 type="imported")

    def describe(self) -> dict[str, Any]:
        return {"source": "import", "files": len({p for p, _, _ in self.items})}

    def frames(self) -> Iterator[CapturedFrame]:
        for i, (path, k, ts) in enumerate(self.items):
            f = self._frames.frame(path, k)
            if f.model_assumed and f.model.to_dict() != self.model.to_dict():  # given with --model
                f.vendor_metadata["radiometric_model"] = "given on import (--model): the file carries none"
            yield CapturedFrame(
                index=i, timestamp_ns=ts, pixels=f.pixels, capture_mono_ns=time.monotonic_ns(),
                sidecar={"capture": {"source_file": os.path.basename(path)}},
                messages=[(TOPIC_IMPORT, {"path": path, "format": f.format, "layout": f.layout,
                                          "vendor": _jsonable(f.vendor_metadata)})],
                attachments=[(f"{os.path.basename(path)}/{name}", "application/octet-stream", blob)
                             for name, blob in f.blobs.items()])


class _FrameCursor:
    """Frame ``k`` of a file, reading forward through it: frames of a SEQ come in order, so a long
    file is decoded once, one frame at a time (a step back starts the file again)."""

    def __init__(self) -> None:
        self.path: str | None = None
        self.frames: Iterator[ImportedFrame] = iter(())
        self.next_k = 0

    def frame(self, path: str, k: int) -> ImportedFrame:
        if path != self.path or k < self.next_k:
            self.path, self.frames, self.next_k = path, iter_file(path), 0
        while True:
            f = next(self.frames, None)
            if f is None:
                raise ImportFileError(f"{path}: has no frame {k} any more (changed since it was checked)")
            self.next_k += 1
            if self.next_k > k:
                return f


def _jsonable(obj: Any) -> Any:
    return json.loads(json.dumps(obj, default=str))


@dataclass
class _Entry:
    path: str
    frame_index: int
    timestamp_ns: int
    frame: ImportedFrame


def _measure_with_sdk(entries: list[_Entry], backend: DjiBackend | None) -> dict[str, str]:
    """Replace the DJI frames' models by tables the vendor SDK measured; returns per-path reasons
    where it could not (the frame keeps its own, honest model: approximate or none)."""
    dji = [e for e in entries if e.frame.format == "dji-rjpeg"]
    if backend is None or not dji:
        return {}
    measured = backend.measure(sorted({e.path for e in dji}))
    problems = {}
    for e in dji:
        temp = measured.get(e.path, "not measured")
        try:
            if isinstance(temp, str):
                raise TemperatureUnavailable(temp)
            if temp.shape != e.frame.pixels.shape:
                raise TemperatureUnavailable(f"{backend.name} measured {temp.shape[1]}x{temp.shape[0]}, the stored "
                                             f"frame is {e.frame.pixels.shape[1]}x{e.frame.pixels.shape[0]}")
            e.frame.model = LookupTableModel.from_measurement(e.frame.pixels, temp, source=backend.name,
                                                              derived_from=e.frame.model.to_dict())
        except TemperatureUnavailable as exc:
            problems[e.path] = str(exc)
    return problems


def _split_tables(members: list[_Entry]) -> list[tuple[Any, list[_Entry]]]:
    """One session per model. Frames whose SDK tables agree on every shared count share a session
    and its merged table (a survey flight from one camera); a disagreement starts another."""
    if not isinstance(members[0].frame.model, LookupTableModel):
        return [(members[0].frame.model, members)]
    parts: list[tuple[LookupTableModel, list[_Entry]]] = []
    for e in members:
        for i, (table, group) in enumerate(parts):
            assert isinstance(e.frame.model, LookupTableModel)  # one session's frames share a model kind
            merged = table.merged(e.frame.model)
            if merged is not None:
                parts[i] = (merged, [*group, e])
                break
        else:
            parts.append((cast(LookupTableModel, e.frame.model), [e]))
    return parts


def import_paths(paths: list[str], root: str | Path, *, session: str | None = None, session_per_file: bool = False,
                 analysis: bool = True, dji_sdk: DjiBackend | None = None, terraref_variant: str = "pipeline",
                 on_file: Callable[[str], None] | None = None,
                 model: RadiometricModel | None = None) -> ImportReport:
    """Import ``paths``; ``dji_sdk`` (see :func:`recorder.importers.dji_sdk.find_backend`) measures
    DJI temperatures with DJI's own code, in batches of ``SDK_BATCH`` files to bound memory.
    ``model`` is the camera's radiometric model for files that carry none (a ROS 2 bag); a file
    with its own keeps it."""
    files, failed, truncated = [], [], []
    groups: dict[str, list[_Entry]] = {}
    waiting: list[_Entry] = []

    def settle(batch: list[_Entry]) -> None:
        problems = _measure_with_sdk(batch, dji_sdk)
        for e in batch:
            f = e.frame
            model_key = ({"kind": f.model.kind, "source": f.model.source, "derived_from": f.model.derived_from}
                         if isinstance(f.model, LookupTableModel) else f.model.to_dict())
            key = e.path if session_per_file else json.dumps([f.pixels.shape, model_key, f.sensor_id], sort_keys=True)
            groups.setdefault(key, []).append(e)
            summary = _summary(f)
            if e.path in problems:
                summary["dji_sdk_error"] = problems[e.path]
            files.append(summary)
            # keep only the description until the recording pass re-reads the file
            f.pixels, f.blobs, f.vendor_metadata = f.pixels[:1, :1].copy(), {}, {}  # a view would pin the frame
        batch.clear()

    for path in _walk(paths):
        try:
            mtime = int(os.stat(path).st_mtime * 1e9)
            for f in iter_file(path, terraref_variant=terraref_variant):
                if model is not None and f.model_assumed:
                    f.model, f.model_assumed = model, False
                e = _Entry(path, f.frame_index, f.timestamp_ns if f.timestamp_ns is not None else mtime, f)
                if dji_sdk is not None and f.format == "dji-rjpeg":
                    waiting.append(e)  # measured in batches: the SDK's start-up is paid once per batch
                    if len(waiting) >= SDK_BATCH:
                        settle(waiting)
                else:
                    settle([e])
        except TruncatedImageError as exc:
            if exc.image == 0:  # not one complete image: the file failed
                failed.append({"path": path, "error": str(exc)})
            else:  # the complete images before the cut are kept; the cut one is reported
                truncated.append({"path": path, "error": str(exc), "kept_images": exc.image, "at_byte": exc.at_byte,
                                  "got_bytes": exc.got, "expected_bytes": exc.expected})
        except (ImportFileError, OSError) as exc:
            # nothing of a file that failed part-way is recorded: take back what it gave
            waiting[:] = [e for e in waiting if e.path != path]
            for members in groups.values():
                members[:] = [e for e in members if e.path != path]
            files[:] = [fs for fs in files if fs["path"] != path]
            reason = str(exc) if isinstance(exc, ImportFileError) else f"{path}: cannot read ({exc.strerror or exc})"
            failed.append({"path": path, "error": reason})
        if on_file:
            on_file(path)
    settle(waiting)
    groups = {k: v for k, v in groups.items() if v}
    parts = [part for members in groups.values() for part in _split_tables(members)]
    sessions = []
    for n, (model, members) in enumerate(parts):
        members.sort(key=lambda m: (m.timestamp_ns, m.path, m.frame_index))  # capture time, then name
        items, last = [], None
        for e in members:
            ts = e.timestamp_ns if last is None or e.timestamp_ns > last else last + 1  # strictly increasing log times
            items.append((e.path, e.frame_index, ts))
            last = ts
        first = _FrameCursor().frame(members[0].path, members[0].frame_index)
        sid = session if session and len(parts) == 1 else (f"{session}-{n + 1}" if session else
                                                           new_session_id(first.sensor_id))
        rec = Recorder(_ImportSource(items, first, model), root, session_id=sid, analysis=analysis,
                       analysis_max_fps=1e6, queue_frames=8, recover_leftovers=False, wait_when_full=True)
        result = rec.run()
        sessions.append(result)
        paths_in = {p for p, _, _ in items}
        for fsum in files:
            if fsum["path"] in paths_in:
                fsum["session_id"] = result.session_id
    return ImportReport(files=files, sessions=sessions, failed=failed, truncated=truncated)
