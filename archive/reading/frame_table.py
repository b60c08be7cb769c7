"""A session's frames as columns: each frame's time and sidecar summary as numpy arrays.

The Zarr endpoint and ``thermcap.open`` both need every frame's time and sidecar summary at once
(a coordinate of the dataset); the index's frames file has them as columns
(``api.reading.frame_columns``), read once per indexed state of the session.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FRAME_FIELDS", "FrameTable", "field_array"]

#: The per-frame sidecar summaries offered as coordinates: name -> (index column, dtype, what it is).
FRAME_FIELDS: dict[str, tuple[str, str, str]] = {
    "thermal_contrast_grade": ("grade", "<f8", "the ICD's thermal contrast grade, 0 (flat) to 1; NaN: not graded"),
    "target_count": ("target_count", "<i4", "targets the detector reported in the frame"),
    "max_target_temp_c": ("max_target_temp_c", "<f8", "the hottest target's temperature, °C; NaN: no target"),
    "slew_to_cue_active": ("slew_to_cue", "|b1", "the gimbal was slewing to a cue"),
}


@dataclass(frozen=True)
class FrameTable:
    session_id: str
    index: np.ndarray  # int64 [frames]: the frame numbers (0..n-1 for a session indexed whole)
    timestamp_ns: np.ndarray  # int64 [frames]: each frame's log time, ns since the Unix epoch
    fields: dict[str, np.ndarray]  # FRAME_FIELDS name -> [frames]

    def __len__(self) -> int:
        return len(self.index)


def field_array(name: str, values: Sequence[Any]) -> np.ndarray:
    """A FRAME_FIELDS column as its array: a missing float is NaN (not graded, no target), a
    missing count or flag is 0 / False."""
    dtype = FRAME_FIELDS[name][1]
    if dtype == "<f8":
        return np.array([np.nan if v is None else v for v in values], dtype=np.float64)
    return np.array([v or 0 for v in values], dtype=np.dtype(dtype))
