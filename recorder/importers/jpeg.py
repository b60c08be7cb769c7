"""JPEG marker walking: the APPn segments before the image data, where thermal cameras hide
their raw frames and calibration (formats.md 1.1, 3.1)."""

from __future__ import annotations

import struct

from thermcap.recorder.importers.base import ImportFileError

__all__ = ["app_segments", "concat_app"]


def app_segments(path: str, data: bytes) -> list[tuple[int, bytes]]:
    """[(marker, payload)] for every segment from SOI up to SOS, in file order."""
    if data[:2] != b"\xff\xd8":
        raise ImportFileError(f"{path}: not a JPEG (no SOI marker)")
    out: list[tuple[int, bytes]] = []
    pos = 2
    n = len(data)
    while pos + 4 <= n:
        if data[pos] != 0xFF:
            raise ImportFileError(f"{path}: corrupt JPEG: expected a marker at byte {pos}")
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
            pos += 2
            continue
        if marker == 0xDA:  # start of scan: the APP segments are all behind us
            return out
        if marker == 0xD9:
            return out
        (length,) = struct.unpack(">H", data[pos + 2:pos + 4])
        if length < 2 or pos + 2 + length > n:
            raise ImportFileError(f"{path}: truncated JPEG segment 0x{marker:02X} at byte {pos} "
                               f"(length {length}, file has {n} bytes)")
        out.append((marker, data[pos + 4:pos + 2 + length]))
        pos += 2 + length
    raise ImportFileError(f"{path}: truncated JPEG (no start-of-scan marker)")


def concat_app(segments: list[tuple[int, bytes]], marker: int) -> bytes:
    """DJI's multi-segment blobs: consecutive segments of one marker, concatenated, no headers."""
    return b"".join(p for m, p in segments if m == marker)
