"""tpred's version 4 key frames: a spatial predictor and five rANS contexts.

A key frame is coded alone, once every ``key_interval`` frames, and costs about 1.3x a predicted
frame. Versions 1-3 coded the vertical differences with pcodec (3.66 bits a pixel on the
simulator's frames). Here each pixel is predicted from the four decoded neighbours
above and to its left, and its residual is coded with the rANS table of its context. That takes
3.38 bits a pixel on the same frames (JPEG XL effort 2: 3.37), 5.91 on the TERRA-REF FLIR frame and
4.15 on the FLIR Duo TIFF.

Layout, stable (after the version 4 key record's defect list):

    5 x (u32 count, u32 length, length bytes)   context k's values as one ``archive.rans`` stream

Neighbours of pixel ``(r, c)``, in the frame being decoded: ``a`` left, ``b`` up, ``c`` up-left,
``d`` up-right; where one is outside the frame: in row 0, ``b = c = d = a``, and ``a`` of pixel
``(0, 0)`` is 0; in column 0, ``a = b`` (the pixel above) and ``c = b``; in the last column,
``d = b``. The prediction is ``(2a + 2b - c + d) >> 2`` (floor), the residual ``F - P``, and the
context the gradient ``g = |a - c| + |b - c| + |d - b|`` against 6, 12, 24 and 48: 0 below 6, ...,
4 from 48 up. Each context's residuals, in raster order, are one stream.
"""

from __future__ import annotations

import struct
from typing import Any

import numba
import numpy as np

from thermcap.archive import rans

__all__ = ["KeyFrameError", "decode_key", "encode_key"]

EDGES = (6, 12, 24, 48)
CONTEXTS = len(EDGES) + 1
_U32x2 = struct.Struct("<II")


class KeyFrameError(ValueError):
    """A key frame payload that does not decode, with the reason."""


@numba.njit(cache=True, nogil=True, inline="always")
def _predict(img: np.ndarray, r: int, col: int) -> tuple[Any, int]:  # pragma: no cover
    """Pixel ``(r, col)``'s prediction and context from its decoded neighbours in ``img`` (the
    rule in this module's docstring); the one place both sides take it from."""
    w = img.shape[1]
    if r == 0:
        a = np.int64(img[0, col - 1]) if col > 0 else np.int64(0)
        b = a
        c = a
        d = a
    else:
        b = np.int64(img[r - 1, col])
        if col > 0:
            a = np.int64(img[r, col - 1])
            c = np.int64(img[r - 1, col - 1])
        else:
            a = b
            c = b
        d = np.int64(img[r - 1, col + 1]) if col < w - 1 else b
    g = abs(a - c) + abs(b - c) + abs(d - b)
    return (2 * a + 2 * b - c + d) >> 2, 0 if g < 6 else 1 if g < 12 else 2 if g < 24 else 3 if g < 48 else 4


@numba.njit(cache=True, nogil=True)
def _residuals(f: np.ndarray, resid: np.ndarray, ctx: np.ndarray) -> None:  # pragma: no cover
    """Each pixel's residual and context, from the frame's own neighbours."""
    h, w = f.shape
    for r in range(h):
        for col in range(w):
            p, k = _predict(f, r, col)
            ctx[r, col] = k
            resid[r, col] = np.int64(f[r, col]) - p


def encode_key(frame: np.ndarray) -> bytes:
    resid = np.empty(frame.shape, np.int32)
    ctx = np.empty(frame.shape, np.uint8)
    _residuals(np.ascontiguousarray(frame), resid, ctx)
    parts = []
    for k in range(CONTEXTS):
        vals = resid[ctx == k]
        stream = rans.encode(vals)
        parts += [_U32x2.pack(vals.size, len(stream)), stream]
    return b"".join(parts)


@numba.njit(cache=True, nogil=True)
def _rebuild(h: int, w: int, values: np.ndarray, starts: np.ndarray, counts: np.ndarray, out: np.ndarray,
             used: np.ndarray) -> int:  # pragma: no cover
    """The frame from its context streams, pixel by pixel; -1 where a stream runs out."""
    for r in range(h):
        for col in range(w):
            p, k = _predict(out, r, col)
            i = used[k]
            if i >= counts[k]:
                return -1
            used[k] = i + 1
            out[r, col] = p + values[starts[k] + i]
    return 0


def decode_key(payload: bytes | memoryview, shape: tuple[int, int]) -> np.ndarray:
    """The frame (int64) of a key payload, or a ``KeyFrameError`` naming what is wrong."""
    view = memoryview(payload)
    pos = 0
    streams = []
    counts = []
    for k in range(CONTEXTS):
        if pos + _U32x2.size > len(view):
            raise KeyFrameError(f"the key frame ends before context {k}'s stream")
        n, length = _U32x2.unpack_from(view, pos)
        pos += _U32x2.size
        if n > shape[0] * shape[1] or pos + length > len(view):
            raise KeyFrameError(f"context {k} says {n} values in {length} bytes, which the frame cannot hold")
        try:
            streams.append(rans.decode(view[pos:pos + length], n).astype(np.int64))
        except rans.RansError as exc:
            raise KeyFrameError(f"context {k}: {exc}") from None
        counts.append(n)
        pos += length
    if pos != len(view):
        raise KeyFrameError(f"{len(view) - pos} bytes follow the key frame's streams")
    if sum(counts) != shape[0] * shape[1]:
        raise KeyFrameError(f"the contexts hold {sum(counts)} values for {shape[0] * shape[1]} pixels")
    out = np.empty(shape, np.int64)
    used = np.zeros(CONTEXTS, np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    if (_rebuild(shape[0], shape[1], np.concatenate(streams), starts, np.asarray(counts, np.int64), out, used)
            or not np.array_equal(used, counts)):
        raise KeyFrameError("the pixels' contexts do not use each stream's values exactly: damaged")
    return out
