"""DJI R-JPEGs rebuilt from the archive, for DJI's own tools.

The importer keeps every APP segment of a DJI file bit-exact (``dji_rjpeg_segments.bin``, the raw
frame's run replaced by a placeholder); with the archived frame that is enough to write an
R-JPEG that DJI's Thermal SDK measures exactly as it measured the original.
"""

from __future__ import annotations

import struct
from typing import cast

import numpy as np

from thermcap.recorder.importers.dji import DJI_SEGMENT, RAW_PLACEHOLDER, SEGMENTS_BLOB, app_segment
from thermcap.recorder.importers.jpeg import app_segments

__all__ = ["SEGMENTS_BLOB", "rebuild_rjpeg"]


def rebuild_rjpeg(pixels: np.ndarray, segments_blob: bytes) -> bytes:
    """An R-JPEG from an archived frame and its ``dji_rjpeg_segments.bin``: the original APP
    segments (EXIF, XMP, parameters, calibration) around the frame, split as DJI splits it, and an
    8x8 grey picture in place of the visible image (DJI's SDK reads only the APP segments; checked
    with dji-thermal-cli on every layout of the samples). Not the original file: its visible image
    is not archived."""
    import imagecodecs

    raw = np.ascontiguousarray(pixels, dtype="<u2").tobytes()
    parts, pos = [b"\xff\xd8"], 0
    while pos + 4 <= len(segments_blob):
        marker = segments_blob[pos + 1]
        (length,) = struct.unpack(">H", segments_blob[pos + 2:pos + 4])
        payload = segments_blob[pos + 4:pos + 2 + length]
        if segments_blob[pos] != 0xFF or len(payload) != length - 2:
            raise ValueError(f"{SEGMENTS_BLOB} is damaged at byte {pos}")
        if payload == RAW_PLACEHOLDER:
            parts += [app_segment(marker, raw[i:i + DJI_SEGMENT]) for i in range(0, len(raw), DJI_SEGMENT)]
        else:
            parts.append(segments_blob[pos:pos + 2 + length])
        pos += 2 + length
    grey = cast(bytes, imagecodecs.jpeg8_encode(np.full((8, 8), 128, np.uint8)))
    tables = b"".join(app_segment(m, p) for m, p in app_segments("grey", grey) if not 0xE0 <= m <= 0xEF)
    parts += [tables, grey[grey.index(b"\xff\xda"):]]
    return b"".join(parts)
