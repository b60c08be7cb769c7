"""Frame codecs: one class per lossless image codec, numcodecs-style.

Contract (as numcodecs' ``abc.py``): ``codec_id`` names the format and never changes once files
carry it; ``encode(frame) -> bytes`` and ``decode(buf) -> frame`` round-trip a (H, W) uint16
frame bit-exactly; ``get_config()`` is JSON-safe and includes ``id``; ``from_config`` rebuilds
the codec; codecs compare equal when their configs do. ``get_codec(config)`` looks one up in
the registry. The encoders are imagecodecs', which release the GIL, so frames encode on two
threads at once.
"""

from __future__ import annotations

import struct
import threading
from abc import ABC, abstractmethod
from typing import Any, ClassVar, cast

import imagecodecs
import numpy as np

from thermcap.archive.exceptions import UnknownCodecError
from thermcap.recorder.exports.png import encode_png
from thermcap.recorder.registry import Registry

__all__ = [
    "FrameCodec",
    "Htj2k",
    "JpegLs",
    "JpegXl",
    "Png16",
    "codec_registry",
    "decode_up_png",
    "get_codec",
    "library_versions",
    "register_codec",
]


class FrameCodec(ABC):
    codec_id: ClassVar[str]
    extension: ClassVar[str]
    media_type: ClassVar[str]

    @abstractmethod
    def encode(self, frame: np.ndarray) -> bytes: ...

    @abstractmethod
    def decode(self, buf: bytes) -> np.ndarray: ...

    def get_config(self) -> dict[str, Any]:
        return {"id": self.codec_id, **{k: v for k, v in vars(self).items() if not k.startswith("_")}}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> FrameCodec:
        return cls(**{k: v for k, v in config.items() if k != "id"})

    def __eq__(self, other: object) -> bool:
        return isinstance(other, FrameCodec) and self.get_config() == other.get_config()

    def __hash__(self) -> int:
        return hash(tuple(sorted(self.get_config().items())))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_config().items() if k != "id")
        return f"{type(self).__name__}({args})"

    @staticmethod
    def _check(frame: np.ndarray) -> np.ndarray:
        if frame.dtype != np.uint16 or frame.ndim != 2:
            raise ValueError(f"expected a 2-D uint16 frame, got {frame.dtype} {frame.shape}")
        return np.ascontiguousarray(frame)

    @staticmethod
    def _as_frame(out: np.ndarray) -> np.ndarray:
        if out.dtype != np.uint16 or out.ndim != 2:
            raise ValueError(f"decoded to {out.dtype} {out.shape}, not a 2-D uint16 frame")
        return out


class Png16(FrameCodec):
    """16-bit grayscale PNG. thermcap writes it itself: every row with PNG's "Up" filter (the
    row above subtracted, vectorised in numpy) and one zlib stream from libdeflate at ``level``
    (4 by default), written by ``recorder.exports.png``. That is a standard PNG (libpng, Pillow
    and browsers read it; decoding here uses libpng) at libpng-level-1 speed with a 6% better
    ratio than libpng level 1; libpng's own level 6 gains little more and is 7x slower.
    ``writer="libpng"`` uses libpng instead."""

    codec_id = "png16"
    extension = ".png"
    media_type = "image/png"

    def __init__(self, level: int = 4, writer: str = "up-libdeflate") -> None:
        if writer not in ("up-libdeflate", "libpng"):
            raise ValueError(f"png16 writer must be up-libdeflate or libpng, got {writer!r}")
        self.level = level
        self.writer = writer

    def encode(self, frame: np.ndarray) -> bytes:
        frame = self._check(frame)
        if self.writer == "libpng":
            return cast(bytes, imagecodecs.png_encode(frame, level=self.level))
        return encode_png(frame, self.level)

    def decode(self, buf: bytes) -> np.ndarray:
        return self._as_frame(imagecodecs.png_decode(buf))


def decode_up_png(buf: bytes) -> np.ndarray | None:
    """The counts of a PNG as ``Png16`` writes it (16-bit gray, not interlaced, every row
    filtered Up), or None for any other PNG. libdeflate inflates the IDAT stream and the Up
    filter is undone as a prefix sum down the columns, blocked so numpy does it in a few dozen
    calls: about 2.5x faster than libpng, which is why raw frames are served from it. It checks
    the chunk layout and each row's filter byte but not the chunks' CRCs: a caller serving its
    output proves it first (against the frame summary's band CRC-32s or the frame's digest);
    verification keeps using libpng."""
    view = memoryview(buf)
    if len(buf) < 45 or bytes(view[:16]) != b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR":
        return None
    w, h, depth, color, comp, filt, interlace = struct.unpack(">IIBBBBB", view[16:29])
    if (depth, color, comp, filt, interlace) != (16, 0, 0, 0, 0) or not (w and h):
        return None
    parts, pos = [], 33
    while pos + 12 <= len(buf):
        (length,) = struct.unpack(">I", view[pos:pos + 4])
        kind = bytes(view[pos + 4:pos + 8])
        if kind == b"IDAT":
            parts.append(view[pos + 8:pos + 8 + length])
        elif kind == b"IEND":
            break
        elif not kind[:1].islower():  # a critical chunk this reader does not know
            return None
        pos += 12 + length
    if not parts:
        return None
    stride = 2 * w + 1
    try:
        raw = imagecodecs.deflate_decode(cast(Any, parts[0] if len(parts) == 1 else b"".join(parts)), out=h * stride)
    except Exception:
        return None
    rows = np.frombuffer(raw, np.uint8)
    if rows.size != h * stride:
        return None
    rows = rows.reshape(h, stride)
    if not (rows[:, 0] == 2).all():
        return None
    px = _prefix_sum_rows(rows[:, 1:])
    px.view(">u2").byteswap(inplace=True)  # PNG's big-endian samples, now little-endian in place
    return px.view("<u2")


def _prefix_sum_rows(filtered: np.ndarray, block: int = 16) -> np.ndarray:
    """Each row plus every row above it, modulo 256 (undoing PNG's Up filter), into a new
    array: within blocks of ``block`` rows, then each block's last row carried into the blocks
    below. That is a few dozen numpy calls where a row at a time would be ``h``."""
    h = filtered.shape[0]
    px = np.empty(filtered.shape, np.uint8)
    full = h - h % block
    if full:
        src = filtered[:full].reshape(full // block, block, -1)
        b = px[:full].reshape(src.shape)
        b[:, 0] = src[:, 0]
        for j in range(1, block):
            np.add(b[:, j - 1], src[:, j], out=b[:, j])
        ends = b[:, -1].copy()
        for i in range(1, len(ends)):
            np.add(ends[i - 1], ends[i], out=ends[i])
        b[1:] += ends[:-1, None, :]
    for i in range(full, h):
        if i == 0:
            px[0] = filtered[0]
        else:
            np.add(px[i - 1], filtered[i], out=px[i])
    return px


class JpegXl(FrameCodec):
    """JPEG XL, lossless (modular mode). Effort 2: ~1.5x PNG16's ratio, 2 threads keep 60 fps."""

    codec_id = "jxl"
    extension = ".jxl"
    media_type = "image/jxl"

    def __init__(self, effort: int = 2) -> None:
        self.effort = effort

    def encode(self, frame: np.ndarray) -> bytes:
        return cast(bytes, imagecodecs.jpegxl_encode(self._check(frame), lossless=True, effort=self.effort))

    def decode(self, buf: bytes) -> np.ndarray:
        return self._as_frame(imagecodecs.jpegxl_decode(buf))


class Htj2k(FrameCodec):
    """High-throughput JPEG 2000 (OpenJPH), reversible: the fastest codec near the best ratio.

    Serialised by a lock: two threads decoding at once made imagecodecs 2026.3.6 / OpenJPH 0.26.3
    print "ojph error" and return wrong pixels *without raising* (seen in ``bench archive``).
    A codec that can be silently wrong must not run concurrently."""

    codec_id = "htj2k"
    extension = ".j2c"
    media_type = "image/j2c"

    def encode(self, frame: np.ndarray) -> bytes:
        with _OJPH_LOCK:
            return cast(bytes, imagecodecs.htj2k_encode(self._check(frame), level=0))

    def decode(self, buf: bytes) -> np.ndarray:
        with _OJPH_LOCK:
            return self._as_frame(imagecodecs.htj2k_decode(buf))


class JpegLs(FrameCodec):
    """JPEG-LS (CharLS), lossless."""

    codec_id = "jpegls"
    extension = ".jls"
    media_type = "image/jls"

    def encode(self, frame: np.ndarray) -> bytes:
        return cast(bytes, imagecodecs.jpegls_encode(self._check(frame)))

    def decode(self, buf: bytes) -> np.ndarray:
        return self._as_frame(imagecodecs.jpegls_decode(buf))


_OJPH_LOCK = threading.Lock()

codec_registry: Registry[FrameCodec] = Registry("codec", UnknownCodecError)


def register_codec(cls: type[FrameCodec], codec_id: str | None = None) -> type[FrameCodec]:
    codec_registry.register(codec_id or cls.codec_id, cls)
    return cls


def get_codec(config: dict[str, Any] | str) -> FrameCodec:
    return codec_registry.build(config)


for _cls in (Png16, JpegXl, Htj2k, JpegLs):
    register_codec(_cls)


def library_versions() -> dict[str, str]:
    """Versions of everything that touches archived bytes, for the manifest."""
    import h5py
    import tifffile

    v = imagecodecs.version(dict)
    keep = ("imagecodecs", "libpng", "libjxl", "openjph", "charls", "zlib", "libdeflate", "libaec", "zstd")
    out = {k: str(v[k]) for k in keep if k in v}
    out.update(tifffile=tifffile.__version__, h5py=h5py.__version__, hdf5=h5py.version.hdf5_version,
               numpy=np.__version__)
    return out
