"""What an importer gives back: frames exactly as stored, their model, and what else to keep."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from thermcap.recorder.exceptions import ImportFileError, TruncatedImageError
from thermcap.recorder.radiometry import RadiometricModel

__all__ = ["ImportFileError", "ImportedFrame", "TruncatedImageError", "read_exact"]


@dataclass
class ImportedFrame:
    path: str
    format: str  # e.g. "dji-rjpeg", "flir-rjpeg", "flir-fff", "terraref-bin", "icd-tiff"
    layout: str | None
    pixels: np.ndarray  # (H, W) uint16, bit-exact as stored (signed layouts keep their bit pattern)
    model: RadiometricModel
    timestamp_ns: int | None = None
    sensor_model: str = ""
    sensor_id: str = "IMPORT"
    vendor_metadata: dict[str, Any] = field(default_factory=dict)
    blobs: dict[str, bytes] = field(default_factory=dict)  # calibration blobs kept bit-exact
    frame_index: int = 0  # within a multi-frame file (SEQ/CSQ)
    #: the file carries no radiometric model (a ROS 2 bag): ``model`` is assumed, and
    #: ``thermcap import --model`` may give the camera's own
    model_assumed: bool = False


def read_exact(path: str, data: bytes, offset: int, length: int, what: str) -> bytes:
    if offset < 0 or offset + length > len(data):
        raise ImportFileError(f"{path}: truncated {what} (needs bytes {offset}..{offset + length}, "
                              f"file has {len(data)})")
    return data[offset:offset + length]
