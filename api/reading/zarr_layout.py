"""A served session as a Zarr (format 2) store with consolidated metadata.

Stock ``xr.open_zarr(url)`` reads it over fsspec's HTTP with no extra arguments: format 2 keys
(``.zgroup``, ``.zarray``, ``.zattrs``) and ``.zmetadata``, so a reader fetches the metadata once
and then one chunk a frame. Chunks are raw little-endian arrays, uncompressed: the counts leave
exactly as verified, and on a LAN decoding costs more than the bytes saved.

Variables (dims time, y, x; ``y`` top-down, as the sensor stored rows):
- ``counts`` uint16, one chunk a frame, bit-exact;
- ``temperature`` float32 °C, computed here per frame by the session's radiometric model (its
  latest version covering the frame, as every route does), NaN at the bad-pixel map's pixels;
- ``time`` (CF: nanoseconds since the epoch, read as datetime64), ``frame`` and the per-frame
  sidecar summaries (``FRAME_FIELDS``) as coordinates.
"""

from __future__ import annotations

import json
import re
from typing import Any

from thermcap.archive.reading.dataset_description import (
    PIXEL_AXIS_DTYPE,
    coordinate_attrs,
    variable_attrs,
)
from thermcap.archive.reading.frame_table import FRAME_FIELDS, FrameTable

__all__ = ["ChunkKey", "parse_chunk_key", "store_metadata"]

IMAGE_VARIABLES = {"counts": "<u2", "temperature": "<f4"}
COORDINATES = ["frame", *FRAME_FIELDS]


def _array(shape: list[int], chunks: list[int], dtype: str, fill: Any) -> dict[str, Any]:
    # fill_value null for the integers: xarray would read a fill value as "missing" and turn the
    # counts into floats
    return {"zarr_format": 2, "shape": shape, "chunks": chunks, "dtype": dtype, "compressor": None,
            "fill_value": fill, "order": "C", "filters": None, "dimension_separator": "."}


def store_metadata(table: FrameTable, width: int, height: int, session_attrs: dict[str, Any]) -> dict[str, Any]:
    """Every metadata document of the store, by key (what ``.zmetadata`` consolidates)."""
    n = len(table)
    one_chunk = [max(n, 1)]
    meta: dict[str, Any] = {".zgroup": {"zarr_format": 2}, ".zattrs": dict(session_attrs)}
    both = " ".join(COORDINATES)
    meta["counts/.zarray"] = _array([n, height, width], [1, height, width], "<u2", None)
    meta["counts/.zattrs"] = {"_ARRAY_DIMENSIONS": ["time", "y", "x"], **variable_attrs("counts"), "coordinates": both}
    meta["temperature/.zarray"] = _array([n, height, width], [1, height, width], "<f4", "NaN")
    meta["temperature/.zattrs"] = {"_ARRAY_DIMENSIONS": ["time", "y", "x"],
                                   **variable_attrs("temperature", session_attrs.get("model_version", "")),
                                   "coordinates": both}
    meta["time/.zarray"] = _array([n], one_chunk, "<i8", None)
    meta["time/.zattrs"] = {"_ARRAY_DIMENSIONS": ["time"], "units": "nanoseconds since 1970-01-01T00:00:00Z",
                            "calendar": "proleptic_gregorian", **coordinate_attrs("time")}
    meta["frame/.zarray"] = _array([n], one_chunk, "<i8", None)
    meta["frame/.zattrs"] = {"_ARRAY_DIMENSIONS": ["time"], **coordinate_attrs("frame")}
    for name, (_, dtype, _what) in FRAME_FIELDS.items():
        meta[f"{name}/.zarray"] = _array([n], one_chunk, dtype, "NaN" if dtype == "<f8" else None)
        meta[f"{name}/.zattrs"] = {"_ARRAY_DIMENSIONS": ["time"], **coordinate_attrs(name)}
    for axis, size in (("y", height), ("x", width)):
        meta[f"{axis}/.zarray"] = _array([size], [size], PIXEL_AXIS_DTYPE, None)
        meta[f"{axis}/.zattrs"] = {"_ARRAY_DIMENSIONS": [axis], **coordinate_attrs(axis)}
    meta[".zmetadata"] = {"zarr_consolidated_format": 1, "metadata": dict(meta)}
    return meta


_CHUNK = re.compile(r"^(?P<var>[a-z_]+)/(?P<i>\d{1,9})(?:\.0\.0)?$")


class ChunkKey:
    def __init__(self, variable: str, index: int) -> None:
        self.variable, self.index = variable, index


def parse_chunk_key(key: str) -> ChunkKey | None:
    """``counts/12.0.0`` -> (counts, 12); ``time/0`` -> (time, 0); None for anything else."""
    m = _CHUNK.match(key)
    if m is None:
        return None
    var, i = m.group("var"), int(m.group("i"))
    image = var in IMAGE_VARIABLES
    if image != key.endswith(".0.0"):
        return None
    return ChunkKey(var, i)


def dumps(doc: Any) -> bytes:
    return json.dumps(doc, allow_nan=True).encode()
