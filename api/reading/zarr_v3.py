"""The same served session as a Zarr format 3 store, beside format 2, from the same verified bytes.

``zarr.json`` at the root is a group with its members' metadata consolidated inline, so a reader
fetches one document before any data. ``counts`` (uint16) and ``temperature`` (float32, NaN
fill) are sharded over time: a shard holds ``frames_per_shard`` frames, one inner chunk a frame,
uncompressed, with the shard's index at its end (``sharding_indexed``; the index checked by
crc32c). One request for a shard carries all its frames; a reader after one frame asks for the
index (a suffix range) and then that frame's range, and the server reads only that frame.

Coordinates are one chunk each. Keys use the default encoding with ``/``: ``counts/c/3/0/0`` is
the fourth shard, ``time/c/0`` the time coordinate. The attributes are format 2's (one source:
``zarr_layout.store_metadata``), with ``_ARRAY_DIMENSIONS`` become ``dimension_names``.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any

import google_crc32c
import numpy as np

from thermcap.api.reading.zarr_layout import IMAGE_VARIABLES

__all__ = ["ShardKey", "ShardLayout", "parse_v3_key", "shard_index", "store_metadata_v3"]

#: frames a shard holds at most, however small (a 32x24 camera's 4,096 frames are 6 MiB); the
#: bytes a shard holds at most are the server's setting (16 MiB: 25 frames of 640x512 counts).
#: A shard's frames are read one by one as the response is written, never held together.
MAX_FRAMES_PER_SHARD = 4096
_DATA_TYPES = {"<u2": "uint16", "<f4": "float32", "<f8": "float64", "<i8": "int64", "<i4": "int32", "|u1": "uint8",
               "<u4": "uint32", "|b1": "bool"}
_MISSING = (1 << 64) - 1  # an index entry for an inner chunk that is not there: the fill value


@dataclass(frozen=True)
class ShardLayout:
    """Where each frame lies in a shard of ``frames_per_shard`` frames of ``frame_bytes`` each."""

    frames: int  # in the session
    frames_per_shard: int
    frame_bytes: int

    @classmethod
    def of(cls, frames: int, height: int, width: int, shard_bytes: int) -> ShardLayout:
        per = max(1, min(MAX_FRAMES_PER_SHARD, shard_bytes // max(1, height * width * 2)))
        return cls(frames, per, height * width * 2)

    def held(self, shard: int, itemsize: int) -> tuple[range, int]:
        """The frames shard ``shard`` holds, and one frame's bytes at this item size."""
        lo = shard * self.frames_per_shard
        return range(lo, min(lo + self.frames_per_shard, self.frames)), self.frame_bytes // 2 * itemsize

    def index_bytes(self) -> int:
        return self.frames_per_shard * 16 + 4

    def shard_size(self, shard: int, itemsize: int) -> int:
        held, fb = self.held(shard, itemsize)
        return len(held) * fb + self.index_bytes()


def shard_index(layout: ShardLayout, shard: int, itemsize: int) -> bytes:
    """The index at a shard's end: (offset, length) a frame, little-endian uint64, then crc32c."""
    held, fb = layout.held(shard, itemsize)
    entries = np.full((layout.frames_per_shard, 2), _MISSING, dtype="<u8")
    entries[: len(held), 0] = np.arange(len(held), dtype="<u8") * fb
    entries[: len(held), 1] = fb
    body = entries.tobytes()
    return body + struct.pack("<I", google_crc32c.value(body))


def _array(shape: list[int], chunk: list[int], dtype: str, fill: Any, attrs: dict[str, Any],
           shard_inner: list[int] | None = None) -> dict[str, Any]:
    attrs = dict(attrs)
    dims = attrs.pop("_ARRAY_DIMENSIONS")
    plain = [{"name": "bytes", "configuration": {"endian": "little"}}]
    codecs = plain if shard_inner is None else [{"name": "sharding_indexed", "configuration": {
        "chunk_shape": shard_inner, "codecs": plain,
        "index_codecs": [{"name": "bytes", "configuration": {"endian": "little"}}, {"name": "crc32c"}],
        "index_location": "end"}}]
    return {"zarr_format": 3, "node_type": "array", "shape": shape, "data_type": _DATA_TYPES[dtype],
            "chunk_grid": {"name": "regular", "configuration": {"chunk_shape": chunk}},
            "chunk_key_encoding": {"name": "default", "configuration": {"separator": "/"}},
            "fill_value": fill, "codecs": codecs, "attributes": attrs, "dimension_names": dims}


def store_metadata_v3(v2: dict[str, Any], layout: ShardLayout, height: int, width: int) -> dict[str, Any]:
    """Every format 3 document by key (``zarr.json``, ``counts/zarr.json``, ...), built from the
    format 2 documents so the two formats cannot describe the session two ways."""
    members: dict[str, Any] = {}
    for key, zarray in v2.items():
        if not key.endswith("/.zarray"):
            continue
        name = key[: -len("/.zarray")]
        attrs = v2[f"{name}/.zattrs"]
        dtype = zarray["dtype"]
        fill = zarray["fill_value"]
        if fill is None:  # format 3 needs one; xarray reads it only through _FillValue, which these lack
            fill = 0 if dtype != "|b1" else False
        if name in IMAGE_VARIABLES:
            members[name] = _array(zarray["shape"], [layout.frames_per_shard, height, width], dtype, fill, attrs,
                                   shard_inner=[1, height, width])
        else:
            members[name] = _array(zarray["shape"], [max(1, zarray["shape"][0])], dtype, fill, attrs)
    group = {"zarr_format": 3, "node_type": "group", "attributes": v2[".zattrs"],
             "consolidated_metadata": {"kind": "inline", "must_understand": False, "metadata": members}}
    out: dict[str, Any] = {"zarr.json": group}
    out.update({f"{name}/zarr.json": doc for name, doc in members.items()})
    return out


@dataclass(frozen=True)
class ShardKey:
    variable: str
    index: int  # the shard (image variables) or the chunk (coordinates, always 0)


_KEY = re.compile(r"^(?P<var>[a-z_]+)/c/(?P<i>\d{1,9})(?P<rest>(?:/\d{1,9})*)$")


def parse_v3_key(key: str) -> ShardKey | None:
    """``counts/c/3/0/0`` -> (counts, 3); ``time/c/0`` -> (time, 0); None for anything else."""
    m = _KEY.match(key)
    if m is None:
        return None
    var, rest = m.group("var"), m.group("rest")
    image = var in IMAGE_VARIABLES
    if (image and rest != "/0/0") or (not image and rest):
        return None
    return ShardKey(var, int(m.group("i")))
