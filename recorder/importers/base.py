"""What an importer gives back: frames exactly as stored, their model, and what else to keep."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from recorder.exceptions import SourceError
from recorder.radiometry import RadiometricModel

__all__ = ["ImportError_", "ImportedFrame", "read_exact"]


class ImportError_(SourceError):
    """A file could not be imported; the message names the file and the problem."""


class TruncatedImageError(ImportError_):
    """A multi-image file (SEQ, CSQ) ends inside an image: the images before it are complete and
    are imported; this one is reported by its byte count, as the raw source reports a cut frame."""

    def __init__(self, path: str, image: int, at_byte: int, got: int, expected: int) -> None:
        self.path, self.image, self.at_byte, self.got, self.expected = path, image, at_byte, got, expected
        super().__init__(f"{path}: image {image} at byte {at_byte} is cut: {got} of its {expected} bytes are there "
                         f"({image} complete images before it were imported)")


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


def read_exact(path: str, data: bytes, offset: int, length: int, what: str) -> bytes:
    if offset < 0 or offset + length > len(data):
        raise ImportError_(f"{path}: truncated {what} (needs bytes {offset}..{offset + length}, file has {len(data)})")
    return data[offset:offset + length]
