"""A reference file beside each HDF5 archive in a bucket, so xarray reads its chunks straight
from S3 without thermcap's server (kerchunk's JSON, version 1).

kerchunk translates the HDF5 file's small datasets and attributes; the frames themselves are
SZIP-compressed (HDF5's own filter, kept for HDF5 1.10 tools), which kerchunk does not map, so
their chunk table is written here from h5py's chunk index, each chunk decoded by imagecodecs'
``imagecodecs_szip`` codec with HDF5's 4-byte size header (gzip files are kerchunk's own).
Reading one: ``imagecodecs.numcodecs.register_codecs()``, then
``xr.open_dataset("reference://", engine="zarr", backend_kwargs={"consolidated": False,
"storage_options": {"fo": REFS_URL, "remote_protocol": "s3", "remote_options": {...}}})``.
"""

from __future__ import annotations

import base64
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from thermcap.recorder.storage.layout import REFS_SUFFIX

__all__ = ["REFS_SUFFIX", "hdf5_references"]


_SZIP_OPTIONS = {"nn": 4 | 32 | 128 | 1, "ec": 4 | 128 | 1}  # H5_SZIP_NN/EC | MSB | RAW, as HDF5 passes them


def hdf5_references(path: Path, url: str) -> dict[str, Any]:
    """The references of the HDF5 file at ``path``, its bytes to be read from ``url``."""
    import h5py
    from kerchunk.hdf import SingleHdf5ToZarr

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # kerchunk warns of the SZIP dataset it leaves to us
        with open(path, "rb") as f:
            refs: dict[str, Any] = SingleHdf5ToZarr(f, url, inline_threshold=0).translate()
    table = refs["refs"]
    for key in [k for k in table if k.endswith("/.zarray")]:  # integers have no fill value: 0 is a count
        meta = json.loads(table[key])
        if meta.get("dtype", "").lstrip("<>|")[:1] in ("i", "u") and meta.get("fill_value") is not None:
            table[key] = json.dumps({**meta, "fill_value": None})
    with h5py.File(path, "r") as h5:
        d = h5["frames"]
        if "frames/.zarray" in table or d.compression != "szip":
            return _as_served(refs, d.shape[1])
        plist = d.id.get_create_plist()
        values = next(plist.get_filter(i)[2] for i in range(plist.get_nfilters())
                      if plist.get_filter(i)[3] == b"szip")  # (flags, options, client values, name)
        options_mask, pixels_per_block, bits_per_pixel, pixels_per_scanline = values
        n, h, w = d.shape
        table["frames/.zarray"] = json.dumps({
            "zarr_format": 2, "shape": [n, h, w], "chunks": list(d.chunks), "dtype": d.dtype.newbyteorder("<").str,
            "compressor": {"id": "imagecodecs_szip", "options_mask": int(options_mask),
                           "pixels_per_block": int(pixels_per_block), "bits_per_pixel": int(bits_per_pixel),
                           "pixels_per_scanline": int(pixels_per_scanline), "header": True},
            "fill_value": None, "order": "C", "filters": None})
        dims = [dim[0].name.lstrip("/") if len(dim) else name for dim, name in zip(d.dims, ("time", "y", "x"),
                                                                                    strict=True)]
        table["frames/.zattrs"] = json.dumps({"_ARRAY_DIMENSIONS": dims, "units": "1",
                                              "long_name": "raw sensor counts"})
        for k in range(d.id.get_num_chunks()):
            info = d.id.get_chunk_info(k)
            if info.filter_mask:
                raise ValueError(f"{path}: chunk {k} skipped a filter; not referenced")
            i = info.chunk_offset[0] // d.chunks[0]
            table[f"frames/{i}.0.0"] = [url, int(info.byte_offset), int(info.size)]
    return _as_served(refs, h)


def _as_served(refs: dict[str, Any], height: int) -> dict[str, Any]:
    """The references in the one convention every array of a session has (the served Zarr store,
    ``to_xarray()``): the counts are ``counts``, ``y`` is the row with 0 at the top, and each
    axis says which it is. An archive written before that convention (``y`` counted from the
    bottom) reads the same way: the file's own coordinate values are replaced here, not its
    frames. The temperature table's dimension, ``counts`` in the file, is ``count`` here."""
    table = refs["refs"]
    renamed: dict[str, Any] = {}
    for key, value in table.items():
        var, sep, rest = key.partition("/")
        if sep and var == "counts":
            key = f"count/{rest}"
        elif sep and var == "frames":
            key = f"counts/{rest}"
        renamed[key] = value
    for key in [k for k in renamed if k.endswith("/.zattrs")]:
        attrs = json.loads(renamed[key]) if isinstance(renamed[key], str) else dict(renamed[key])
        dims = attrs.get("_ARRAY_DIMENSIONS")
        if dims:
            attrs["_ARRAY_DIMENSIONS"] = ["count" if d == "counts" else d for d in dims]
        if key == "counts/.zattrs":
            attrs["long_name"] = attrs.get("long_name") or "raw sensor counts"
        elif key in ("time/.zattrs", "x/.zattrs"):
            attrs["axis"] = "T" if key.startswith("time") else "X"
        renamed[key] = json.dumps(attrs)
    if "y/.zarray" in renamed:
        renamed["y/.zarray"] = json.dumps({"zarr_format": 2, "shape": [height], "chunks": [height], "dtype": "<i4",
                                           "compressor": None, "fill_value": None, "order": "C", "filters": None})
        renamed = {k: v for k, v in renamed.items() if not (k.startswith("y/") and k[2:3].isdigit())}
        renamed["y/0"] = "base64:" + base64.b64encode(np.arange(height, dtype="<i4").tobytes()).decode()
        renamed["y/.zattrs"] = json.dumps({"_ARRAY_DIMENSIONS": ["y"], "long_name": "row, 0 at the top",
                                           "units": "1", "axis": "Y"})
    refs["refs"] = renamed
    return refs
