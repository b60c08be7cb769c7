"""``thermcap analyze``: run the detector over a recorded (or imported) session, offline.

Results go beside the segments, never into them (recorded data is not rewritten):
``analysis.jsonl`` (one line per frame: index, log time, thermal_analysis, targets) and
``events.json`` (thermal crossover and slew-to-cue spans), both written to a temporary name
and renamed, and both the same bytes for the same input, so running it twice changes nothing.
The API's index prefers these per-frame results over the recorded sidecars.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from thermcap.recorder.analysis.detector import EventBuilder, HotSpotDetector
from thermcap.recorder.exceptions import McapFileError
from thermcap.recorder.radiometry import model_from_dict
from thermcap.recorder.radiometry.session import read_bad_pixel_map
from thermcap.recorder.storage.atomic import write_json_atomic
from thermcap.recorder.storage.layout import ANALYSIS_JSONL, EVENTS_JSON
from thermcap.recorder.storage.lock import session_locked
from thermcap.recorder.storage.reader import archived_frame_count, iter_session_frames, read_session_meta

__all__ = ["ANALYSIS_FILE", "EVENTS_FILE", "analyze_session"]

ANALYSIS_FILE = ANALYSIS_JSONL
EVENTS_FILE = EVENTS_JSON


def analyze_session(session_dir: str | Path, *, threshold_k: float = 5.0, min_area: int = 4,
                    min_crossover_s: float = 1.0, on_frame: Callable[[int], None] | None = None) -> dict[str, Any]:
    session_dir = Path(session_dir)
    meta = read_session_meta(session_dir)
    if not meta and not list(session_dir.glob("*.mcap")):
        raise McapFileError(f"{session_dir}: not a thermcap session")
    with session_locked(session_dir, "analyze"):
        return _analyze(session_dir, meta, threshold_k, min_area, min_crossover_s, on_frame)


def _expected_frames(session_dir: Path, meta: dict[str, Any]) -> int | None:
    archived = archived_frame_count(session_dir)
    if archived is not None:
        return archived
    n = meta.get("frames_written")
    return int(n) if isinstance(n, int) else None


def _analyze(session_dir: Path, meta: dict[str, Any], threshold_k: float, min_area: int, min_crossover_s: float,
             on_frame: Callable[[int], None] | None) -> dict[str, Any]:
    model = model_from_dict(meta.get("radiometric_model") or {"kind": "linear"})
    detector = HotSpotDetector(model, threshold_k=threshold_k, min_area=min_area,
                               bad_pixel_map=read_bad_pixel_map(session_dir))
    events = EventBuilder(min_crossover_s=min_crossover_s)
    tmp = session_dir / (ANALYSIS_FILE + ".tmp")
    frames = targets = 0
    with open(tmp, "w") as out:
        for frame in iter_session_frames(session_dir):
            dets, analysis = detector.detect(frame.pixels)
            recorded = frame.sidecar_dict()
            row = {"index": frame.index, "log_time": frame.log_time, "thermal_analysis": analysis,
                   "targets": [d.to_sidecar() for d in dets]}
            out.write(json.dumps(row, separators=(",", ":"), sort_keys=True) + "\n")
            events.add(frame.log_time, {"thermal_analysis": analysis, "slew_to_cue": recorded.get("slew_to_cue") or {}})
            frames += 1
            targets += len(dets)
            if on_frame:
                on_frame(frames)
        out.flush()
        os.fsync(out.fileno())
    expected = _expected_frames(session_dir, meta)
    if expected is not None and frames != expected:
        tmp.unlink()
        raise McapFileError(f"{session_dir}: read {frames} frames but the session holds {expected} (is its "
                            "source gone without a verified archive?); the previous analysis was kept")
    os.replace(tmp, session_dir / ANALYSIS_FILE)
    ev = events.finish()
    write_json_atomic(session_dir / EVENTS_FILE, {"session_id": meta.get("session_id", session_dir.name), "events": ev})
    return {"session": str(session_dir), "frames": frames, "detections": targets, "events": ev}
