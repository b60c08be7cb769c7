"""``hdf5``: one file per session for scientific users, and a valid netCDF-4 file (CF-1.10).

``frames`` (N, H, W) uint16, one frame per chunk, SZIP (libaec, nearest-neighbour 32): ratio ~4
at ~400 fps, and stock h5py reads it without plugins (falls back to shuffle + gzip where an
h5py build lacks the SZIP encoder). The SZIP chunks are compressed by imagecodecs' libaec on the
archive's encode threads, outside the GIL, and handed to HDF5 whole (``write_direct_chunk``):
HDF5's own filter would compress them inside h5py's lock, one at a time, stalling every other
format's thread. The bytes are the ones HDF5's filter writes (its 4-byte size header, then the
CCSDS stream with the parameters ``H5Z_set_local_szip`` derives), which a test checks, and
verification reads them back through HDF5's own filter pipeline. Beside ``frames``:
``timestamps_ns`` (N,) int64; ``metadata`` (N,) UTF-8 JSON sidecars; the radiometric model,
sensor and session id as attributes.

For netCDF and CF readers (xarray, netCDF-C, MATLAB's ncread, Panoply): ``time``, ``y`` and
``x`` are dimension scales attached to every variable; ``time`` is in CF units (ns since the
Unix epoch); a linear model is CF packing on ``frames`` (``scale_factor``, ``add_offset``,
``units = "degC"``), so ``xarray.open_dataset(..., engine="h5netcdf")`` gives °C while the
stored counts stay the recorded ones; any other model (Planck, a DJI lookup) is a
``temperature_lut`` variable over a ``counts`` dimension, so ``lut[frames]`` is °C in any reader.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.formats.base import ArchiveContext, ArchiveFormat, DecodedFrame, FileRecord, locate, ordered_map
from thermcap.archive.formats.hdf5_heap import HeapStrings, heap_strings
from thermcap.recorder.storage.reader import SessionFrame

__all__ = ["LIBVER", "Hdf5"]

LIBVER = ("earliest", "v110")
#: Frames ``Hdf5.read`` takes in one call, at most this many bytes of them (16 at 640x512).
READ_BYTES = 10 << 20


def _szip_encoder_available() -> bool:
    if not h5py.h5z.filter_avail(h5py.h5z.FILTER_SZIP):
        return False
    return bool(h5py.h5z.get_filter_info(h5py.h5z.FILTER_SZIP) & h5py.h5z.FILTER_CONFIG_ENCODE_ENABLED)


def szip_chunk(frame: np.ndarray) -> tuple[int, bytes]:
    """One (H, W) little-endian uint16 frame as HDF5's SZIP filter stores it in a (1, H, W) chunk
    with ``compression_opts=("nn", 32)``, as (filter mask, bytes): the uncompressed size (uint32
    LE), then the CCSDS-121 stream with nearest-neighbour preprocessing, 32-pixel blocks and one
    scanline of the chunk's fastest dimension per reference sample interval (HDF5 caps it at 128
    blocks = 4096 pixels). Where that is no smaller than the frame, HDF5 stores the frame as it
    is with the (optional) filter marked skipped, and so does this."""
    import struct

    import imagecodecs

    frame = np.ascontiguousarray(frame, dtype="<u2")
    scanline = min(frame.shape[-1], 32 * 128)
    if scanline % 32:
        raise ArchiveError(f"szip_chunk needs a width that is a multiple of 32, got {frame.shape[-1]}")
    payload = imagecodecs.aec_encode(frame, bitspersample=16, flags=imagecodecs.AEC.FLAG.DATA_PREPROCESS,
                                     blocksize=32, rsi=scanline // 32)
    chunk = struct.pack("<I", frame.nbytes) + payload
    if len(chunk) >= frame.nbytes:
        return 1, frame.tobytes()
    return 0, chunk


class Hdf5(ArchiveFormat):
    format_id = "hdf5"
    description = "one HDF5 file per session: frames (N,H,W) uint16 chunked per frame, timestamps, sidecars"

    def __init__(self, filter: str | None = None) -> None:
        self.filter = filter or ("szip" if _szip_encoder_available() else "gzip")

    def get_config(self) -> dict:
        return {"id": self.format_id, "filter": self.filter}

    def _filter_kwargs(self) -> dict:
        if self.filter == "szip":
            return {"compression": "szip", "compression_opts": ("nn", 32)}
        if self.filter == "gzip":
            return {"compression": "gzip", "compression_opts": 1, "shuffle": True}
        raise ArchiveError(f"hdf5 filter must be szip or gzip, got {self.filter!r}")

    def write(self, frames: Iterable[SessionFrame], out_dir: Path, ctx: ArchiveContext) -> list[FileRecord]:
        rel = f"{ctx.session_id}.h5"
        n_total = ctx.total_frames
        if n_total is None:
            raise ArchiveError("hdf5 needs the frame count up front")
        n = 0
        direct = self.filter == "szip"

        def encoded(frame: SessionFrame) -> tuple[SessionFrame, tuple[int, bytes] | None]:
            px = np.asarray(frame.pixels)
            fits = px.ndim == 2 and px.shape[-1] % 32 == 0 and px.shape[-1] <= 4096  # else HDF5 pads: its own filter
            return frame, (szip_chunk(px) if direct and fits else None)

        with _SessionFile(out_dir / rel, n_total, self._filter_kwargs(), ctx) as out:
            for frame, chunk in ordered_map(encoded, frames, ctx.workers if direct else 1):
                px = np.asarray(frame.pixels)
                dset = out.frames(px.shape, frame.index)
                if n >= n_total:
                    raise ArchiveError(f"more frames than the {n_total} counted")
                if chunk is not None:
                    dset.id.write_direct_chunk((n, 0, 0), chunk[1], filter_mask=chunk[0])
                else:
                    dset[n] = px
                out.times[n] = frame.log_time
                out.meta[n] = frame.sidecar.decode() if frame.sidecar else "{}"
                n += 1
                if ctx.on_frame:
                    ctx.on_frame()
            if n != n_total:
                raise ArchiveError(f"expected {n_total} frames, got {n}")
        return [FileRecord(rel, n)]

    def assemble(self, parts: list[tuple[Path, list[dict[str, Any]]]], out_dir: Path,
                 ctx: ArchiveContext) -> list[FileRecord]:
        """The session file from the segments' files: each chunk copied as stored (the filter's
        bytes, its mask), with the times and sidecars, so no frame is encoded twice."""
        rel = f"{ctx.session_id}.h5"
        total = sum(int(r["frames"]) for _, files in parts for r in files)
        n = 0
        with _SessionFile(out_dir / rel, total, self._filter_kwargs(), ctx) as out:
            for folder, files in parts:
                for rec in files:
                    if not int(rec["frames"]):  # a segment with no frame of this session's camera
                        continue
                    try:
                        src_file = h5py.File(folder / rec["path"], "r")
                    except OSError as exc:
                        raise ArchiveError(f"{folder / rec['path']}: not a readable HDF5 part ({exc})") from exc
                    with src_file as src:
                        s = src["frames"]
                        if s.chunks != (1, *s.shape[1:]):
                            raise ArchiveError(f"{folder / rec['path']}: frames are not chunked one per frame")
                        m = s.shape[0]
                        if n + m > total:
                            raise ArchiveError(f"the parts hold more than the {total} frames they list")
                        dset = out.frames(s.shape[1:], n)
                        for k in range(m):
                            mask, chunk = s.id.read_direct_chunk((k, 0, 0))
                            dset.id.write_direct_chunk((n + k, 0, 0), chunk, filter_mask=mask)
                        out.times[n:n + m] = src["timestamps_ns"][...]
                        out.meta[n:n + m] = [v.decode("utf-8") if isinstance(v, bytes) else v
                                             for v in src["metadata"][...]]
                        n += m
            if n != total:
                raise ArchiveError(f"expected {total} frames from the parts, got {n}")
        return [FileRecord(rel, n)]

    def read(self, out_dir: Path, files: list[str], workers: int = 2) -> Iterator[DecodedFrame]:
        """Every frame through HDF5's own filter pipeline, ``READ_BYTES`` of frames a call.

        Why blocks: each h5py call lets go of the GIL and takes it back several times, and
        while the other formats verify beside it every retake waits its turn. A frame a call
        (and a call each for its time and its sidecar: four a frame) left the HDF5 reader, the
        one verification on a single thread, with about a third of a core beside the others, so
        it ran alone for the last 0.65-0.85 s of a 10 s archive; with 16 frames a call that
        tail is 0.6 s and the verification phase 5-10% shorter. With two ``workers`` the next
        block is read on a thread while the caller hashes this one, so HDF5's one lock is not
        left idle for a hash: the tail 0.68-1.07 -> 0.46-0.66 s (three runs each, alternated).
        With one (the archive's share for three formats on two cores), blocks are read in turn,
        while the other formats' read-backs keep the cores busy."""
        for rel in files:
            path = out_dir / rel
            try:
                with h5py.File(path, "r") as f, open(path, "rb") as raw:
                    d, meta = f["frames"], f["metadata"]
                    times = f["timestamps_ns"][...]
                    n = d.shape[0]
                    step = max(1, READ_BYTES // max(1, int(np.prod(d.shape[1:], dtype=np.int64)) * d.dtype.itemsize))
                    # the sidecars from the heap's bytes, bounded (HDF5's own read of a damaged
                    # collection can loop for good): hdf5_heap
                    fd = raw.fileno()

                    def read_at(off: int, size: int, fd: int = fd) -> bytes:
                        return os.pread(fd, size, off)  # the block threads share the file: no seek

                    at = heap_strings(meta)
                    strings = HeapStrings(read_at, *at, where=str(path)) if at is not None else None
                    blocks = [(d, meta, strings, i, step) for i in range(0, n, step)]
                    # the next block is read while the caller checks this one (two in flight)
                    for i, pixels, sidecars in ordered_map(_read_block, blocks, workers, window=2):
                        for k in range(pixels.shape[0]):
                            s = sidecars[k]
                            yield DecodedFrame(pixels[k], s.encode("utf-8") if isinstance(s, str) else bytes(s),
                                               int(times[i + k]))
            except (OSError, KeyError) as exc:
                raise ArchiveError(f"{path}: not a readable HDF5 archive ({exc})") from exc

    def read_frame(self, open_file, files: list[dict], index: int) -> DecodedFrame:
        """One chunk of ``frames`` (one frame per chunk) and one row each of the time and the
        sidecar: h5py reads a file object with seeks, so this is a few ranged reads. A sidecar
        the heap cannot give (damaged) comes back empty, which its hash then reports, and the
        pixels, checked by theirs, still serve."""
        rel, k = locate(files, index)
        with open_file(rel) as fh:
            try:
                with h5py.File(fh, "r") as f:
                    pixels, time_ns = f["frames"][k], int(f["timestamps_ns"][k])
                    at = heap_strings(f["metadata"])
                    if at is None:
                        meta = f["metadata"][k]
                        return DecodedFrame(pixels, meta.encode("utf-8") if isinstance(meta, str) else bytes(meta),
                                            time_ns)

                    def read_at(off: int, size: int) -> bytes:
                        fh.seek(off)
                        return fh.read(size)

                    try:
                        (sidecar,) = HeapStrings(read_at, *at, where=rel).get(k, k + 1)
                    except ArchiveError:
                        sidecar = b""
                    return DecodedFrame(pixels, sidecar, time_ns)
            except (OSError, KeyError, ValueError) as exc:
                raise ArchiveError(f"{rel}: not a readable HDF5 archive ({exc})") from exc


def _read_block(job: tuple[Any, Any, HeapStrings | None, int, int]) -> tuple[int, np.ndarray, Any]:
    """Frames ``i .. i + step`` (one h5py call) and their sidecars."""
    frames, meta, strings, i, step = job
    pixels = frames[i:i + step]
    return i, pixels, strings.get(i, i + pixels.shape[0]) if strings is not None else meta[i:i + step]


class _SessionFile:
    """An archive file being written: its datasets made on the first frame's shape, and on a
    clean close the attributes and the netCDF description. The oldest file-format bounds that
    hold what we use (chunks, SZIP, variable-length UTF-8): "latest" from the HDF5 2.x inside
    h5py's wheel is unreadable to HDF5 1.10 tools (h5dump, GDAL and MATLAB builds of that era)."""

    def __init__(self, path: Path, n_total: int, filter_kwargs: dict[str, Any], ctx: ArchiveContext) -> None:
        self.path, self.n_total, self.filter_kwargs, self.ctx = path, n_total, filter_kwargs, ctx
        self.f = h5py.File(path, "w-", libver=LIBVER)
        self.dset: Any = None
        self.times: Any = None
        self.meta: Any = None

    def frames(self, shape: tuple[int, ...], index: int) -> Any:
        if self.dset is None:
            h, w = shape
            self.dset = self.f.create_dataset("frames", shape=(self.n_total, h, w), dtype="<u2", chunks=(1, h, w),
                                              **self.filter_kwargs)
            self.times = self.f.create_dataset("timestamps_ns", shape=(self.n_total,), dtype="<i8")
            self.meta = self.f.create_dataset("metadata", shape=(self.n_total,), dtype=h5py.string_dtype("utf-8"))
        elif tuple(shape) != self.dset.shape[1:]:
            raise ArchiveError(f"frame {index} is {tuple(shape)}, the session's frames are {self.dset.shape[1:]}")
        return self.dset

    def __enter__(self) -> _SessionFile:
        return self

    def __exit__(self, exc_type: Any, *_: Any) -> None:
        try:
            if exc_type is None:
                f, ctx = self.f, self.ctx
                f.attrs["session_id"] = ctx.session_id
                f.attrs["radiometric_model"] = json.dumps(ctx.session_meta.get("radiometric_model"))
                f.attrs["sensor"] = json.dumps(ctx.session_meta.get("sensor"))
                f.attrs["format"] = "thermcap hdf5 archive 1"
                if self.dset is not None:
                    _describe_for_netcdf(f, self.dset, self.times, self.meta, ctx.session_meta)
        finally:
            self.f.close()


def _describe_for_netcdf(f: h5py.File, frames: Any, times: Any, meta: Any, session_meta: dict[str, Any]) -> None:
    """Dimension scales, CF attributes and the temperature mapping (see the module docstring)."""
    from thermcap.recorder.radiometry import LinearModel, model_from_dict

    _, h, w = frames.shape
    time = f.create_dataset("time", data=times[...], dtype="<i8")
    time.attrs.update(units="nanoseconds since 1970-01-01T00:00:00Z", calendar="standard", standard_name="time",
                      long_name="capture time (UTC)", axis="T")
    # y is the row with 0 at the top, as in every other array of a session (the served Zarr store,
    # to_xarray, the bucket's references): ds.sel(y=0) is the first stored row everywhere.
    y = f.create_dataset("y", data=np.arange(h, dtype="<i4"))
    y.attrs.update(long_name="row, 0 at the top", units="1", axis="Y")
    x = f.create_dataset("x", data=np.arange(w, dtype="<i4"))
    x.attrs.update(long_name="pixel column, from the left", units="1", axis="X")
    for scale, name in ((time, "time"), (y, "y"), (x, "x")):
        scale.make_scale(name)
    for i, scale in enumerate((time, y, x)):
        frames.dims[i].attach_scale(scale)
    times.dims[0].attach_scale(time)
    meta.dims[0].attach_scale(time)
    times.attrs.update(long_name="capture time, integer ns since the Unix epoch (as recorded)", units="ns")
    meta.attrs["long_name"] = "ICD sidecar of each frame, JSON, exactly as recorded"
    f.attrs.update(Conventions="CF-1.10", title=f"thermcap session {f.attrs['session_id']}",
                   source="thermcap radiometric thermal recording",
                   comment="frames holds the sensor counts bit-exact; temperature per the radiometric_model")
    try:
        model = model_from_dict(session_meta.get("radiometric_model") or {})
    except (ValueError, TypeError, KeyError):
        model = None
    # An archive is written once: versions `thermcap radiometry` adds later are not in it. Say so
    # where a reader of the file meets the temperatures, rather than let them pass for the latest.
    frames.attrs["model_version"] = ("0: the model recorded with the session (radiometric_model); versions added "
                                     "with `thermcap radiometry` are not applied here (thermcap.open applies "
                                     "them); the session's bad pixels are not masked")
    if isinstance(model, LinearModel):
        # CF packing: unpacked = counts * scale_factor + add_offset, in degC
        frames.attrs.update(scale_factor=np.float64(model.scale_c_per_count), add_offset=np.float64(model.offset_c),
                            units="degC", long_name="apparent temperature (stored as sensor counts)")
        return
    frames.attrs.update(long_name="sensor counts (temperature: temperature_lut[frames])", units="1")
    if model is None:
        return
    bits = int(getattr(model, "bit_depth", 16) or 16)
    counts = np.arange(1 << min(bits, 16), dtype=np.uint16)
    try:
        lut = np.asarray(model.to_celsius(counts), dtype=np.float32)
    except Exception:  # a model that cannot say (constants missing): no table rather than a wrong one
        return
    c = f.create_dataset("counts", data=counts.astype("<i4"))
    c.attrs.update(long_name="sensor count", units="1")
    c.make_scale("counts")
    table = f.create_dataset("temperature_lut", data=np.where(np.isfinite(lut), lut, np.nan).astype("<f4"))
    table.dims[0].attach_scale(c)
    table.attrs.update(units="degC", long_name="apparent temperature of each sensor count",
                       _FillValue=np.float32(np.nan))
