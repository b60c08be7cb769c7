"""A Foxglove layout per session, whose colour range fits its data.

One fixed 0..16383 range washes out a simulator session (its counts sit between about 600 and
1,700) and clips a FLIR T640 (its counts reach 28,000). The layout here sets the Image panel's
``minValue``/``maxValue`` to the session's own 0.5..99.5 percentile counts, wires the detections
(``/thermal/annotations``) over the image, and plots the sidecar's typed fields. The recorder
writes it beside the session (``foxglove_layout.json``); the API serves it; Foxglove opens it
with *Layouts* -> *Import from file*.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.icd.topics import camera_topics
from thermcap.recorder.storage.atomic import write_json_atomic
from thermcap.recorder.storage.layout import FOXGLOVE_LAYOUT

__all__ = ["FOXGLOVE_LAYOUT", "CountsRange", "layout_for", "write_layout"]



@dataclass
class CountsRange:
    """The running 0.5..99.5 percentile counts of frames offered to it (a sample is enough)."""

    lo: int | None = None
    hi: int | None = None

    def add(self, pixels: np.ndarray) -> None:
        sample = pixels[::4, ::4] if pixels.size > 4096 else pixels
        lo, hi = (int(v) for v in np.percentile(sample, (0.5, 99.5)))
        self.lo = lo if self.lo is None else min(self.lo, lo)
        self.hi = hi if self.hi is None else max(self.hi, hi)

    def bounds(self) -> tuple[int, int]:
        if self.lo is None or self.hi is None:
            return 0, 16383
        return self.lo, max(self.hi, self.lo + 1)


def _image_panel(camera: str | None, lo: int, hi: int) -> dict[str, Any]:
    t = camera_topics(camera)
    return {"imageMode": {"imageTopic": t.image, "colorMode": "colormap", "colorMap": "turbo",
                          "minValue": lo, "maxValue": hi, "annotations": {t.annotations: {"visible": True}}},
            "scene": {}, "transforms": {}, "topics": {}, "layers": {}}


def layout_for(ranges: dict[str | None, tuple[int, int]]) -> dict[str, Any]:
    """The layout for a session's cameras (None: the single-camera topics) and their ranges."""
    config: dict[str, Any] = {}
    images = []
    for camera, (lo, hi) in ranges.items():
        pid = f"Image!{camera or 'thermal'}"
        config[pid] = _image_panel(camera, lo, hi)
        images.append(pid)
    first = camera_topics(next(iter(ranges)))
    config["Plot!analysis"] = {
        "paths": [{"value": f"{first.metadata}.thermal_contrast_grade", "enabled": True, "label": "contrast grade",
                   "timestampMethod": "receiveTime"},
                  {"value": f"{first.metadata}.max_target_temp_c", "enabled": True, "label": "max target °C",
                   "timestampMethod": "receiveTime"},
                  {"value": "/recorder/stats.queue_depth", "enabled": True, "label": "queue depth",
                   "timestampMethod": "receiveTime"}],
        "showLegend": True, "legendDisplay": "floating", "isSynced": True, "xAxisVal": "timestamp"}
    config["RawMessages!sidecar"] = {"topicPath": first.metadata, "diffEnabled": False}
    tree: Any = images[0]
    for pid in images[1:]:
        tree = {"first": tree, "second": pid, "direction": "column"}
    return {"configById": config, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
            "layout": {"first": tree, "second": {"first": "Plot!analysis", "second": "RawMessages!sidecar",
                                                 "direction": "column", "splitPercentage": 50},
                       "direction": "row", "splitPercentage": 65}}


def write_layout(session_dir: Path, ranges: dict[str | None, tuple[int, int]]) -> Path:
    path = Path(session_dir) / FOXGLOVE_LAYOUT
    write_json_atomic(path, layout_for(ranges), fsync=False, indent=1)  # derived from the session
    return path


def ranges_from_frames(frames: Iterable[tuple[str | None, np.ndarray]]) -> dict[str | None, tuple[int, int]]:
    acc: dict[str | None, CountsRange] = {}
    for camera, pixels in frames:
        acc.setdefault(camera, CountsRange()).add(pixels)
    return {c: r.bounds() for c, r in acc.items()} or {None: (0, 16383)}
