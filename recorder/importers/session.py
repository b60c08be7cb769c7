"""``thermcap import``: files and folders into recorded sessions, through the recorder's own path.

Two passes: the first reads every file, detects its format by content and checks it (a corrupt
or unsupported file is reported with its reason and left out, so nothing half-read is ever
written); the second records the good frames, ordered by capture time, as ordinary sessions.
Files with different frame sizes or radiometric models go to separate sessions (one model per
session is what lets the API compute temperatures); ``session_per_file`` splits further. Vendor
metadata travels on ``/import/source`` (one message per frame) and calibration blobs as MCAP
attachments, bit-exact.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from ..radiometry import TemperatureUnavailable
from ..recorder import Recorder, RecordingResult, new_session_id
from ..sources.base import CapturedFrame, FrameSource, SensorInfo
from . import ImportedFrame, ImportError_, read_file

__all__ = ["import_paths", "ImportReport"]

TOPIC_IMPORT = "/import/source"
_IMPORT_SCHEMA = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "thermcap.ImportSource",
                  "type": "object", "properties": {"path": {"type": "string"}, "format": {"type": "string"},
                                                   "layout": {"type": ["string", "null"]}, "vendor": {"type": "object"}},
                  "required": ["path", "format"]}


@dataclass
class ImportReport:
    files: list[dict[str, Any]]
    sessions: list[RecordingResult]
    failed: list[dict[str, str]]


def _walk(paths: list[str]) -> list[str]:
    out = []
    for p in paths:
        if os.path.isdir(p):
            for dirpath, _dirs, names in sorted(os.walk(p)):
                for n in sorted(names):
                    if n.endswith((".json", ".txt", ".md")) or n.startswith("."):
                        continue  # sidecars and notes are read with the file they describe
                    out.append(os.path.join(dirpath, n))
        else:
            out.append(p)
    return out


def _summary(f: ImportedFrame) -> dict[str, Any]:
    celsius: dict[str, Any] | None
    try:
        t = np.asarray(f.model.to_celsius(f.pixels), dtype=np.float64)
        celsius = {"min": round(float(np.nanmin(t)), 4), "max": round(float(np.nanmax(t)), 4),
                   "mean": round(float(np.nanmean(t)), 4)}
        if getattr(f.model, "approximate", False):
            celsius["approximate"] = True
    except TemperatureUnavailable as exc:
        celsius = None
        reason = str(exc)
    out = {"path": f.path, "format": f.format, "layout": f.layout, "frame_index": f.frame_index,
           "width": int(f.pixels.shape[1]), "height": int(f.pixels.shape[0]),
           "raw_sha256": hashlib.sha256(np.ascontiguousarray(f.pixels, dtype="<u2").tobytes()).hexdigest(),
           "celsius": celsius, "model": f.model.to_dict()}
    if celsius is None:
        out["celsius_unavailable"] = reason
    return out


class _ImportSource(FrameSource):
    """Replays checked files (re-read now, so memory holds one file at a time)."""

    name = "import"
    extra_topics = {TOPIC_IMPORT: _IMPORT_SCHEMA}

    def __init__(self, items: list[tuple[str, int, int]], first: ImportedFrame) -> None:
        self.items = items  # (path, frame index within file, timestamp ns)
        self.model = first.model
        h, w = first.pixels.shape
        self.sensor = SensorInfo(model=first.sensor_model or first.format, sensor_id=first.sensor_id, width=w, height=h,
                                 frame_rate_hz=1.0, pixel_pitch_um=None, netd_mk=None, serial_number="unknown",
                                 type="imported")

    def describe(self) -> dict[str, Any]:
        return {"source": "import", "files": len({p for p, _, _ in self.items})}

    def frames(self) -> Iterator[CapturedFrame]:
        cache: tuple[str, list[ImportedFrame]] | None = None
        for i, (path, k, ts) in enumerate(self.items):
            if cache is None or cache[0] != path:
                cache = (path, read_file(path))
            f = cache[1][k]
            yield CapturedFrame(
                index=i, timestamp_ns=ts, pixels=f.pixels, capture_mono_ns=time.monotonic_ns(),
                sidecar={"capture": {"source_file": os.path.basename(path)}},
                messages=[(TOPIC_IMPORT, {"path": path, "format": f.format, "layout": f.layout,
                                          "vendor": _jsonable(f.vendor_metadata)})],
                attachments=[(f"{os.path.basename(path)}/{name}", "application/octet-stream", blob)
                             for name, blob in f.blobs.items()])


def _jsonable(obj: Any) -> Any:
    return json.loads(json.dumps(obj, default=str))


def import_paths(paths: list[str], root: str | Path, *, session: str | None = None, session_per_file: bool = False,
                 analysis: bool = True, on_file: Callable[[str], None] | None = None) -> ImportReport:
    files, failed = [], []
    groups: dict[str, list[tuple[str, int, int, ImportedFrame]]] = {}
    for path in _walk(paths):
        try:
            frames = read_file(path)
        except ImportError_ as exc:
            failed.append({"path": path, "error": str(exc)})
            if on_file:
                on_file(path)
            continue
        mtime = int(os.stat(path).st_mtime * 1e9)
        for f in frames:
            key = path if session_per_file else json.dumps([f.pixels.shape, f.model.to_dict(), f.sensor_id], sort_keys=True)
            ts = f.timestamp_ns if f.timestamp_ns is not None else mtime
            groups.setdefault(key, []).append((path, f.frame_index, ts, f))
            files.append(_summary(f))
            f.pixels = f.pixels[:1, :1]  # keep only the description until the recording pass
        if on_file:
            on_file(path)
    sessions = []
    for n, (key, members) in enumerate(groups.items()):
        members.sort(key=lambda m: (m[2], m[0], m[1]))  # capture time, then name
        items, last = [], None
        for path, k, ts, _f in members:
            ts = ts if last is None or ts > last else last + 1  # strictly increasing log times
            items.append((path, k, ts))
            last = ts
        first = read_file(members[0][0])[members[0][1]]
        sid = session if session and len(groups) == 1 else (f"{session}-{n + 1}" if session else
                                                            new_session_id(first.sensor_id))
        rec = Recorder(_ImportSource(items, first), root, session_id=sid, analysis=analysis,
                       analysis_max_fps=1e6, queue_frames=8, recover_leftovers=False, wait_when_full=True)
        result = rec.run()
        sessions.append(result)
        for fsum in files:
            if any(fsum["path"] == p for p, _, _ in items):
                fsum["session_id"] = result.session_id
    return ImportReport(files=files, sessions=sessions, failed=failed)
