"""tpred's version 4 key frames: a spatial predictor and five rANS contexts.

A key frame is coded alone, once every ``key_interval`` frames, and costs about 1.3x a predicted
frame. Versions 1-3 coded the vertical differences with pcodec (3.66 bits a pixel on the
simulator's frames). Here each pixel is predicted from the four decoded neighbours
above and to its left, and its residual is coded with the rANS table of its context. That takes
3.38 bits a pixel on the same frames (JPEG XL effort 2: 3.37), 5.91 on the TERRA-REF FLIR frame and
4.15 on the FLIR Duo TIFF.

Layout, stable (after the version 4 key record's defect list):

    5 x (u32 count, u32 length, length bytes)   context k's values as one ``archive.codecs.tpred.rans`` stream

Neighbours of pixel ``(r, c)``, in the frame being decoded: ``a`` left, ``b`` up, ``c`` up-left,
``d`` up-right; where one is outside the frame: in row 0, ``b = c = d = a``, and ``a`` of pixel
``(0, 0)`` is 0; in column 0, ``a = b`` (the pixel above) and ``c = b``; in the last column,
``d = b``. The prediction is ``(2a + 2b - c + d) >> 2`` (floor), the residual ``F - P``, and the
context the gradient ``g = |a - c| + |b - c| + |d - b|`` against 6, 12, 24 and 48: 0 below 6, ...,
4 from 48 up. Each context's residuals, in raster order, are one stream.

Version 7 (tpred bitstream 7's key and intra records) puts one byte before the streams, the rule:
0 is the layout above; 1 adds the run rule. Under it, a pixel whose two left neighbours are
equal (``col >= 2`` and ``F[r, col-1] == F[r, col-2]``) is predicted by ``a`` and takes a sixth
context, 5; every other pixel is predicted as above; six streams follow. Real FLIR CSQ frames
hold runs of equal values along their rows (44-62 % of the pixels of a 1024x768 sequence repeat
their left neighbour), which the four-neighbour predictor spends 5 bits a pixel on: the run rule
codes them at 0.65-0.79 of that, where JPEG XL effort 2 reached 0.83. The encoder picks the rule
from both rules' estimated cost (``rule_costs``): a frame without runs keeps rule 0 and pays one
byte.
"""

from __future__ import annotations

import struct
from typing import Any

import numba
import numpy as np

from thermcap.archive.codecs.tpred import rans

__all__ = ["KeyFrameError", "decode_key", "encode_key", "rule_costs"]

EDGES = (6, 12, 24, 48)
CONTEXTS = len(EDGES) + 1
RUN = CONTEXTS  # the run rule's context
RULES = (0, 1)  # version 7's rule byte: plain, or with the run rule
_ESTIMATE_ROWS = 64  # about as many rows as the rule's choice measures
RUN_MARGIN = 0.99  # the run rule is taken where its estimate is 1 % below the plain rule's
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


@numba.njit(cache=True, nogil=True, inline="always")
def _in_run(img: np.ndarray, r: int, col: int) -> bool:  # pragma: no cover
    """The run rule's test: the pixel's two left neighbours are equal."""
    return col >= 2 and img[r, col - 1] == img[r, col - 2]


@numba.njit(cache=True, nogil=True, inline="always")
def _predict_rule(img: np.ndarray, r: int, col: int, rule: int) -> tuple[Any, int]:  # pragma: no cover
    """``_predict``, or under the run rule (``rule`` 1) ``a`` in context ``RUN`` where the pixel
    is in a run (``_in_run``)."""
    if rule == 1 and _in_run(img, r, col):
        return np.int64(img[r, col - 1]), RUN
    return _predict(img, r, col)


@numba.njit(cache=True, nogil=True)
def _residuals(f: np.ndarray, resid: np.ndarray, ctx: np.ndarray, rule: int) -> None:  # pragma: no cover
    """Each pixel's residual and context, from the frame's own neighbours."""
    h, w = f.shape
    for r in range(h):
        for col in range(w):
            p, k = _predict_rule(f, r, col, rule)
            ctx[r, col] = k
            resid[r, col] = np.int64(f[r, col]) - p


@numba.njit(cache=True, nogil=True)
def _rule_counts(f: np.ndarray, step: int, counts: np.ndarray, extra: np.ndarray) -> None:  # pragma: no cover
    """Every ``step``-th row's tokens per rule and context into ``counts[rule, context, token]``,
    their extra bits into ``extra[rule]``."""
    h, w = f.shape
    for r in range(0, h, step):
        for col in range(w):
            x = np.int64(f[r, col])
            p, k = _predict(f, r, col)
            t, e, _ = rans.token(x - p)
            counts[0, k, t] += 1
            extra[0] += e
            if _in_run(f, r, col):
                t, e, _ = rans.token(x - np.int64(f[r, col - 1]))
                k = RUN
            counts[1, k, t] += 1
            extra[1] += e


def rule_costs(frame: np.ndarray, step: int | None = None) -> tuple[float, float]:
    """Each rule's estimated bits: the tokens' zeroth-order entropy in their context and the extra
    bits (what rANS reaches within about 0.2 %) on every ``step``-th row, scaled to the frame,
    and each stream's table. ``step`` by default keeps about 64 rows: a 640x512 frame measures
    every 8th (0.4 ms), a small one every row. The sample's error is about 1 %, more than the
    two rules differ by on a frame whose runs are chance (0.2 %), so ``encode_key`` takes the
    run rule only where its estimate is ``RUN_MARGIN`` below (real runs win 6-35 %)."""
    h = frame.shape[0]
    step = max(1, h // _ESTIMATE_ROWS) if step is None else step
    counts = np.zeros((2, CONTEXTS + 1, rans.MAX_TOKENS), np.int64)
    extra = np.zeros(2, np.int64)
    _rule_counts(np.ascontiguousarray(frame), step, counts, extra)
    totals = counts.sum(axis=2, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        bits = np.where(counts > 0, counts * np.log2(np.maximum(totals, 1) / np.maximum(counts, 1)), 0.0)
    scale = h / len(range(0, h, step))
    tables = 8 * ((totals[..., 0] > 0) * (_U32x2.size + 9) + 1.5 * (counts > 0).sum(axis=2)).sum(axis=1)
    cost = (bits.sum(axis=(1, 2)) + extra) * scale + tables
    return float(cost[0]), float(cost[1])


def encode_key(frame: np.ndarray, *, rule: int | None = None) -> bytes:
    """The key payload. ``rule=None``: version 4's layout (no rule byte). Version 7 passes
    ``rule=-1`` (the cheaper rule by ``rule_costs``), or a rule to force it."""
    f = np.ascontiguousarray(frame)
    if rule is not None and rule < 0:
        plain, runs = rule_costs(f)
        rule = 1 if runs < RUN_MARGIN * plain else 0
    if rule not in (None, *RULES):
        raise ValueError(f"tpred key frames have rules {RULES}, got {rule}")
    resid = np.empty(frame.shape, np.int32)
    ctx = np.empty(frame.shape, np.uint8)
    _residuals(f, resid, ctx, rule or 0)
    parts = [] if rule is None else [bytes([rule])]
    for k in range(CONTEXTS + (rule == 1)):
        vals = resid[ctx == k]
        stream = rans.encode(vals)
        parts += [_U32x2.pack(vals.size, len(stream)), stream]
    return b"".join(parts)


@numba.njit(cache=True, nogil=True)
def _rebuild(h: int, w: int, values: np.ndarray, starts: np.ndarray, counts: np.ndarray, out: np.ndarray,
             used: np.ndarray, rule: int) -> int:  # pragma: no cover
    """The frame from its context streams, pixel by pixel; -1 where a stream runs out."""
    for r in range(h):
        for col in range(w):
            p, k = _predict_rule(out, r, col, rule)
            i = used[k]
            if i >= counts[k]:
                return -1
            used[k] = i + 1
            out[r, col] = p + values[starts[k] + i]
    return 0


def decode_key(payload: bytes | memoryview, shape: tuple[int, int], *, ruled: bool = False) -> np.ndarray:
    """The frame (int64) of a key payload, or a ``KeyFrameError`` naming what is wrong. ``ruled``:
    the payload starts with version 7's rule byte."""
    view = memoryview(payload)
    pos = 0
    rule = 0
    if ruled:
        if not view:
            raise KeyFrameError("the key frame ends before its rule byte")
        rule = view[0]
        if rule not in RULES:
            raise KeyFrameError(f"the key frame's rule is {rule}; tpred knows rules {RULES}")
        pos = 1
    streams = []
    counts = []
    for k in range(CONTEXTS + (rule == 1)):
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
    used = np.zeros(len(counts), np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    if (_rebuild(shape[0], shape[1], np.concatenate(streams), starts, np.asarray(counts, np.int64), out, used, rule)
            or not np.array_equal(used, counts)):
        raise KeyFrameError("the pixels' contexts do not use each stream's values exactly: damaged")
    return out
