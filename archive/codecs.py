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
import zlib
from abc import ABC, abstractmethod
from typing import Any, ClassVar, cast

import imagecodecs
import numpy as np

from archive.exceptions import UnknownCodecError
from recorder.registry import Registry

__all__ = [
    "FrameCodec",
    "Htj2k",
    "JpegLs",
    "JpegXl",
    "Png16",
    "codec_registry",
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
    (4 by default). That is a standard PNG (libpng, Pillow and browsers read it; decoding here
    uses libpng) at libpng-level-1 speed with a 6% better ratio than libpng level 1; libpng's
    own level 6 gains little more and is 7x slower. ``writer="libpng"`` uses libpng instead."""

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
        h, w = frame.shape
        be = frame.astype(">u2").view(np.uint8).reshape(h, 2 * w)
        rows = np.empty((h, 2 * w + 1), np.uint8)
        rows[:, 0] = 2  # filter type Up
        rows[0, 1:] = be[0]
        np.subtract(be[1:], be[:-1], out=rows[1:, 1:])  # modulo 256, as PNG defines it
        idat = cast(bytes, imagecodecs.deflate_encode(cast(Any, rows), level=self.level, raw=False))
        return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
                + _png_chunk(b"IDAT", idat) + _png_chunk(b"IEND", b""))

    def decode(self, buf: bytes) -> np.ndarray:
        return self._as_frame(imagecodecs.png_decode(buf))


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


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
