"""``tpred``: a lossless codec that uses the time axis, for sequences of uint16 thermal frames.

Every codec before it was intra-only, and a thermal camera's frames differ mostly by noise. A
frame here is predicted from the mean of up to ``window`` (16) frames before it, each aligned to
it by the view's global motion (a pan), and only the residual is stored, entropy-coded by
pcodec (``pco``), which reaches within 1% of the residual's zeroth-order entropy. A key frame
every ``key_interval`` (64, about a second at 60 fps) frames is coded alone (pcodec of its vertical differences), so any
frame decodes in at most ``key_interval`` steps from its key.

Bitstream, version 1 (stable: files written with it decode forever; golden files in
``tests/fixture/bitstreams/tpred-v<N>``). Each frame is one record, little-endian:

    offset size  field
    0      4     magic b"TPF1"
    4      1     kind: 0 key, 1 predicted
    5      1     window: the number of earlier frames averaged (0 for a key)
    6      2     width  (uint16)
    8      2     height (uint16)
    10     2     dx (int16): columns the picture moved right since the previous frame
    12     2     dy (int16): rows it moved down
    14     1     payload type: 1 int16 residuals, 2 int32 residuals
    15     1     reserved, 0
    16     4     payload length (uint32)
    20     n     payload: one pcodec chunk of the (height, width) array, row-major

Key frame: the payload is ``D`` with ``D[0] = F[0]`` and ``D[r] = F[r] - F[r-1]`` (as int32);
the frame is its cumulative sum down the rows.

Predicted frame: the decoder keeps ``S``, the sum of the last ``w`` decoded frames (``w`` =
``window`` in the record), aligned to the previous frame. For a record with shift ``(dx, dy)`` it
shifts ``S`` by it, rows and columns that enter the view taking the values at the edge they
enter from (edge replication), and predicts ``P = (S + w // 2) // w`` (floor division, int64). The
frame is ``P + residual``. Then the frame is added to ``S``, and once ``S`` holds more than
``window`` frames, the oldest of them, shifted by the total motion since it was decoded (edge
replicated in one step), is subtracted. The encoder does exactly the same, so ``S`` and ``P`` are
bit-identical on both sides whatever the edges do.

Bitstream, version 2 (magic ``b"TPF2"``, the same record layout): the
same key frames, and a better prediction where the view moves. Version 1 shifts the sum of the
window with edge replication, so in a pan the columns that entered over the last ``w`` frames
are predicted from copies of the edge, and a sweep pays for a band as wide as the window's whole
motion. Version 2 predicts each pixel only from the frames that saw its part of the scene.
Each frame ``j`` of the window has a cumulative motion ``(cx_j, cy_j)`` since its key frame (the
sum of the records' ``dx``, ``dy``; 0 for the key) and saw scene point ``(y, x)`` at its pixel
``(y + cy_j, x + cx_j)`` when that lies inside it. For pixel ``(r, c)`` of a record whose
cumulative motion is ``(cx, cy)``, the scene point is ``(r - cy, c - cx)``; ``S`` is the sum of the
window frames' values at that point and ``N`` the number of frames that saw it. The prediction
is ``P = (S + N // 2) // N`` (floor division, int64) where ``N > 0``, and otherwise the previous
frame moved by the record's ``(dx, dy)`` with edge replication (content no frame has seen). The
window is kept and trimmed as in version 1. A decoder reads both versions; a sequence keeps the
version of its key frame.

Bitstream, version 3 (magic ``b"TPF3"``): version 2's key frames and
scene window, and two more things both sides compute the same way, in integers, from the
frames already decoded since the key frame. Values in 1/64 counts are written ``x64``.

- The window holds each frame less the pattern estimate ``E`` at the time it was added
  (``64 * F - E``). Its mean ``M`` is ``S / N`` truncated toward zero where frames saw the
  scene point (``S``, ``N`` as in version 2), and otherwise the last of those values moved by
  the record's ``(dx, dy)`` with edge replication. So ``M`` is the scene without the sensor's
  pattern. The key frame enters as ``64 * F``, and ``E`` starts at 0.
- The pattern estimate ``E`` (``_Pattern``): after each predicted frame, its residual against
  the scene ``R = 64 * F - M``, clipped to +-512, and set to 0 at the pixels not predicted from
  the scene (block modes, unseen points), is added to a per-pixel sum ``A`` and per column to
  ``Cs`` (with ``Cn``, the number of pixels that were predicted from the scene). With ``n`` the
  number of frames learned since the key, ``C = (Cs + Cn // 2) // Cn`` (0 where ``Cn`` is 0)
  and ``E = C + (A - n * C) // (n + 16)`` (floor division).
- The prediction is ``P = (M + E + 32) >> 6`` (floor), except in blocks with a mode.

A predicted record's payload is, in order: ``u32`` length ``L`` and ``L`` bytes, the zlib stream
of the block-mode map (one ``uint8`` per 16x16 block, row-major, ``ceil(h/16) x ceil(w/16)``;
``L = 0``: no block has a mode). A block with mode ``k`` (1..25) is predicted by the previous
decoded frame moved by ``(vx, vy) = VECTORS[k - 1]``, which is ``(k - 1) % 5 - 2`` columns right
and ``(k - 1) // 5 - 2`` rows down, with edge replication, in the block's pixels inside the frame.
Then two residual streams, each a ``u32`` length and one pcodec chunk of its values (length 0
for a stream with no pixel), each listing its pixels in row-major order: first the pixels
predicted from the scene, then the others (block modes and unseen points, whose residuals are
larger). The frame is ``P + residual``. Payload type 1 or 2 says whether both streams hold
int16 or int32.

Bitstream, version 4 (magic ``b"TPF4"``): version 3 with three changes.

- A key record's payload starts with the sensor's defect list: ``u32`` length ``L`` and ``L``
  bytes, the zlib stream of the defects' flat pixel indices (``r * width + c``) as ``u32``,
  strictly increasing (``L = 0``: none). The frame follows, coded by ``archive.codecs.tpred.key`` (a
  four-neighbour spatial predictor and five rANS contexts, specified there) instead of
  pcodec's vertical differences; the header's payload type is 2 and says nothing.
- Until the next key, each defect is predicted by its own value in the previous frame and is
  one of the "others" (second residual stream, out of the pattern's learning). The window
  holds it as 0 and counts it 0 towards ``N`` (the key frame too), so no scene point is
  predicted from a defect; where only defects saw a point, it is unseen.
- Both residual streams are ``archive.codecs.tpred.rans`` streams (specified there) instead of pcodec
  chunks; the payload type is the residuals' range as before.

Bitstream, version 5 (magic ``b"TPF5"``): version 4 and one more record
kind, 2 (intra), for the mode decision every video codec makes. An intra record has version 4's
predicted header (``window``, ``dx``, ``dy`` as a predicted record would have them; payload type
2) and its payload is the frame coded alone, as a version 4 key frame codes it (``archive.
tpred_key``) without the defect list. The decoder takes the frame from the payload, then does
what it does after a predicted record with no block modes: the prediction's scene part ``M``
and unseen pixels are computed from ``(dx, dy)`` as for a predicted record, and the frame is
learned and pushed with them. So the sequence goes on (the window, the pattern, the defects)
and the next key stays where the key interval puts it. The encoder writes an intra record when
the frame coded alone is smaller than its predicted record (it tries once the predicted record
reaches ``INTRA_TRY`` of the last frame it coded alone, a key or a trial): a shutter (NUC)
frame, a gain step, a cut, or temporal noise above the scene's detail, where real uncooled
cameras made every predicted frame 15-43 % larger than the key frame.

Bitstream, version 6 (magic ``b"TPF6"``): version 5, and a predicted
record's payload starts with three ``int8``: ``sx`` and ``sy``, how far the picture moved since
the window's frames in sixteenths of a pixel (less than a pixel, ``|s| < 16``: a camera that
shakes; whole pixels are the header's ``dx``, ``dy``), and ``sl`` (``|sl| <= 16``), the weight
of the scene mean's Laplacian in sixteenths (the window's mean of shaken frames is blurred, and
carries 1/16 of the noise). The decoder computes version 4's ``p``, ``m64`` and ``other``; then
at every pixel not in ``other`` and not on the frame's edge, with ``gx = (m64[r, c+1] -
m64[r, c-1]) >> 1``, ``gy = (m64[r+1, c] - m64[r-1, c]) >> 1`` and ``lap = (4 m64[r, c] -
m64[r, c-1] - m64[r, c+1] - m64[r-1, c] - m64[r+1, c]) >> 2`` (all from the uncorrected mean;
0 on the edge), where all three are below ``SUBPEL_LIMIT`` (64 counts, in 1/64 counts) in
magnitude: ``m64 += (sx * gx + sy * gy + sl * lap) >> 4`` (floor), and at every pixel not in
``other``, ``p = (m64 + E + 32) >> 6``. The block modes, the residual streams and the learning
(against this ``m64``) follow as in version 4. An intra record is version 5's, and learns
against the uncorrected ``m64``. The encoder fits the three weights by least squares to the
residual (pixels within ``SUBPEL_LIMIT`` and with residuals within 8 counts), and writes 0, 0, 0
where the fit does not lower the residual: a sub-pixel shake of 0.5 px had made every predicted
frame miss by a share of each edge's slope, and half of them coded alone.

Bitstream, version 7 (magic ``b"TPF7"``): version 6, and every frame coded
alone (a key record's frame after its defect list, an intra record's payload) is
``archive.codecs.tpred.key``'s version 7 layout: a rule byte, then the streams; rule 1 predicts a pixel
that continues a run of equal values along its row by the run (specified there). Real FLIR CSQ
sequences hold such runs in most of their pixels and code every frame alone (their temporal noise
is above the scene's detail); version 6 lost to JPEG XL effort 2 on them (0.95x), version 7 wins
(1.22x).

Bitstream, version 8 (magic ``b"TPF8"``; what thermcap writes): version 7, and a predicted
record's three terms are followed by its filters: one byte ``n``, 0 (none) or 2, and ``n``
filters, each one byte ``q`` (4 <= q <= 9) and 24 ``int8`` coefficients ``k`` in units of
``2**-q``, in the order of ``archive.codecs.tpred.filter.TAPS`` (the 5x5 neighbours ``(dy, dx)`` row by
row, without the centre). A record with filters has terms 0, 0, 0. The decoder computes version
4's ``p``, ``m64`` and ``other``; then at every pixel not in ``other``, with ``d_i = m64[r + dy_i,
c + dx_i] - m64[r, c]`` (uncorrected; rows and columns outside the frame replicate its edge) and
``span = max |d_i|``, where ``span < FILTER_LIMIT`` (64 counts, in 1/64 counts): the first filter
where ``span < FILTER_SPLIT`` (8 counts), else the second, gives ``m64 += (sum(k[i] * d_i) >> q)``
(floor) and ``p = (m64 + E + 32) >> 6``. The block modes, the streams and the learning (against
this ``m64``) follow as in version 4. The encoder fits each filter by least squares to the
residual of its pixels (residuals within 8 counts, on every other row and every 7th column) when
the frame's version 6 fit moved the picture or while the camera shakes, writes the finest ``q``
in which each filter's coefficients fit, and keeps the filters where they lower the residual
below the three terms': a bilinear move by a fraction of a pixel blurs by that fraction as well,
and the window's mean of frames at other fractions is blurred differently, which a first-order
shift does not follow; where the scene is flat the best filter mostly averages the mean's noise
away, where it has detail it mostly moves it.

The encoder alone estimates the motion: the shift of the previous frame that best matches this
one (least mean absolute difference, each difference clipped at 16 counts, on every 8th line;
candidates from the lines' median profiles), columns over +-``max_shift`` (32) pixels, then
rows over +-8, kept only when it lowers the (clipped) residual. In version 3 it also picks the
block modes: blocks whose residual against the scene is well above the frame's typical block
try every vector on the previous frame and keep the best when clearly better (a vehicle that
moves across a panned view). In version 4 it also watches for defects (``_StuckPixels``): a
pixel whose value has not changed for 15 frames is listed at the next key frame.
"""

from __future__ import annotations

import struct
import zlib
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import TypeVar

import imagecodecs
import numpy as np

from thermcap.recorder.frame_heap import keep_frame_blocks

# the rans, kernels and key modules beside this one are compiled by numba, which takes
# 0.35 s to import: they are imported inside the functions that use them, so every ``thermcap``
# command does not pay for it at start-up.

__all__ = ["BITSTREAM_VERSION", "HEADER", "TemporalDecoder", "TemporalEncoder", "TpredError", "decode_gops",
           "decode_records", "encode_gops", "parse_header"]

BITSTREAM_VERSION = 8  # what the encoder writes by default; every earlier version decodes
MAGICS = {1: b"TPF1", 2: b"TPF2", 3: b"TPF3", 4: b"TPF4", 5: b"TPF5", 6: b"TPF6", 7: b"TPF7", 8: b"TPF8"}
_VERSION_OF = {m: v for v, m in MAGICS.items()}
T = TypeVar("T")
HEADER = struct.Struct("<4sBBHHhhBBI")  # 20 bytes
KEY, PREDICTED, INTRA = 0, 1, 2
_INT16, _INT32 = 1, 2
#: A predicted record at least this share of the last frame coded alone (a key, or the last
#: trial) is compared with the frame coded alone (version 5's mode decision). Below it, coding
#: alone was never smaller on any sequence measured (``thermcap bench temporal``); skipping
#: the trial there keeps the encoder fast where prediction wins narrowly (heavy noise).
INTRA_TRY = 0.97


class TpredError(ValueError):
    """A record that is not a tpred frame, or one that does not follow from the ones before."""


@dataclass(frozen=True)
class RecordHeader:
    version: int
    kind: int
    window: int
    width: int
    height: int
    dx: int
    dy: int
    payload_type: int
    payload_len: int


def parse_header(buf: bytes | memoryview) -> RecordHeader:
    if len(buf) < HEADER.size:
        raise TpredError(f"a tpred record needs {HEADER.size} header bytes, got {len(buf)}")
    magic, kind, window, w, h, dx, dy, ptype, _, n = HEADER.unpack_from(buf)
    version = _VERSION_OF.get(bytes(magic))
    if version is None:
        raise TpredError(f"not a tpred record of version 1..{BITSTREAM_VERSION} (magic {bytes(magic)!r})")
    kinds = (KEY, PREDICTED, INTRA) if version >= 5 else (KEY, PREDICTED)
    if kind not in kinds or ptype not in (_INT16, _INT32) or (kind != KEY and window == 0):
        raise TpredError(f"a tpred record with kind {kind}, window {window}, payload type {ptype}")
    if len(buf) != HEADER.size + n:
        raise TpredError(f"a tpred record says {n} payload bytes and holds {len(buf) - HEADER.size}")
    return RecordHeader(version, kind, window, w, h, dx, dy, ptype, n)


def _shift(a: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``a`` moved ``dx`` columns right and ``dy`` rows down; what enters takes the edge's values."""
    if dx == 0 and dy == 0:
        return a
    h, w = a.shape
    cols = np.clip(np.arange(w) - dx, 0, w - 1)
    rows = np.clip(np.arange(h) - dy, 0, h - 1)
    return a[rows[:, None], cols[None, :]]


def _payload_type(arr: np.ndarray) -> tuple[int, type]:
    """The record's payload type and dtype: int16 when every value fits, else int32."""
    lo, hi = int(arr.min()), int(arr.max())
    return (_INT16, np.int16) if lo >= -32768 and hi <= 32767 else (_INT32, np.int32)


def _decode_chunk(ptype: int, chunk: bytes | memoryview, shape: tuple[int, ...], what: str) -> np.ndarray:
    """One pcodec chunk of ``shape`` values of the payload type, or a ``TpredError`` naming ``what``."""
    try:
        out = imagecodecs.pcodec_decode(bytes(chunk), shape=shape, dtype=np.int16 if ptype == _INT16 else np.int32)
    except Exception as exc:  # a damaged payload may fail anywhere inside the decoder
        raise TpredError(f"{what} does not decode ({type(exc).__name__}: {exc})") from None
    return np.asarray(out)


def _pack(arr: np.ndarray) -> tuple[int, bytes]:
    ptype, dtype = _payload_type(arr)
    return ptype, bytes(imagecodecs.pcodec_encode(arr.astype(dtype), level=8))


def _pack_vertical(f: np.ndarray) -> tuple[int, bytes]:
    """A version 1-3 key frame: its vertical differences, one pcodec chunk."""
    d = f.copy()
    d[1:] -= f[:-1]
    return _pack(d)


def _unpack(ptype: int, payload: bytes | memoryview, shape: tuple[int, int]) -> np.ndarray:
    return _decode_chunk(ptype, payload, shape, "the payload").astype(np.int64)


class _Window:
    """The sum of the last frames, aligned to the newest: the state both sides keep."""

    def __init__(self) -> None:
        self.frames: deque[tuple[np.ndarray, int, int]] = deque()  # (frame int64, cum dx, cum dy)
        self.sum: np.ndarray | None = None
        self.cx = self.cy = 0

    def reset(self) -> None:
        self.frames.clear()
        self.sum = None
        self.cx = self.cy = 0

    def predict(self, dx: int, dy: int) -> tuple[np.ndarray, int]:
        assert self.sum is not None
        self.sum = _shift(self.sum, dx, dy)
        self.cx += dx
        self.cy += dy
        w = len(self.frames)
        return (self.sum + w // 2) // w, w

    def push(self, frame: np.ndarray) -> None:
        f = frame.astype(np.int64)
        self.sum = f.copy() if self.sum is None else self.sum + f
        self.frames.append((f, self.cx, self.cy))

    def trim(self, keep: int) -> None:
        """Drop the oldest frames until ``keep`` remain (the encoder right after a push; the
        decoder lazily, before the next prediction, at the same motion state)."""
        while len(self.frames) > keep:
            assert self.sum is not None
            old, ox, oy = self.frames.popleft()
            self.sum -= _shift(old, self.cx - ox, self.cy - oy)


class _SceneWindow:
    """Version 2's state: the window's frames summed on a canvas in scene coordinates, with
    the number of frames that saw each scene point. Placing and removing a frame are slice
    additions (no shifted copies of the sum), and the canvas is rebuilt larger, from the
    frames, when the view leaves it: how large it is never changes a prediction."""

    MARGIN = 128  # pixels of scene around the window's frames when the canvas is (re)built
    DTYPE: type = np.int64  # of the frames it keeps and the predictions it makes
    CANVAS: tuple[type, type] = (np.float64, np.float64)  # of the sum and the count

    def __init__(self) -> None:
        self.frames: deque[tuple[np.ndarray, int, int]] = deque()  # (frame int64, cum dx, cum dy)
        self.sum: np.ndarray | None = None
        self.count: np.ndarray | None = None
        self.oy = self.ox = 0  # the scene point of canvas[0, 0]
        self.cx = self.cy = 0
        self.last: np.ndarray | None = None
        # how much each pixel of a frame counts towards N (version 4: 0 at the listed defects);
        # None: every pixel counts 1
        self.weight: np.ndarray | None = None

    def reset(self) -> None:
        self.frames.clear()
        self.sum = self.count = self.last = self.weight = None
        self.oy = self.ox = self.cx = self.cy = 0

    def _counted(self) -> np.ndarray | int:
        return 1 if self.weight is None else self.weight

    def _at(self, shape: tuple[int, int], cx: int, cy: int) -> tuple[slice, slice] | None:
        """The canvas slices a frame with cumulative motion (cx, cy) covers, or None if it
        does not fit (its pixel (r, c) sees scene point (r - cy, c - cx))."""
        assert self.sum is not None
        r0, c0 = -cy - self.oy, -cx - self.ox
        if r0 < 0 or c0 < 0 or r0 + shape[0] > self.sum.shape[0] or c0 + shape[1] > self.sum.shape[1]:
            return None
        return slice(r0, r0 + shape[0]), slice(c0, c0 + shape[1])

    def _fit(self, shape: tuple[int, int], cx: int, cy: int) -> tuple[slice, slice]:
        where = self._at(shape, cx, cy) if self.sum is not None else None
        if where is not None:
            return where
        spots = [(-fy, -fx) for _, fx, fy in self.frames] + [(-cy, -cx)]
        m = self.MARGIN
        self.oy, self.ox = min(y for y, _ in spots) - m, min(x for _, x in spots) - m
        size = (max(y for y, _ in spots) - self.oy + shape[0] + m, max(x for _, x in spots) - self.ox + shape[1] + m)
        # float64 holds these sums exactly (below 2**31 in version 3), and divides 4x faster than int64
        self.sum, self.count = np.zeros(size, self.CANVAS[0]), np.zeros(size, self.CANVAS[1])
        for f, fx, fy in self.frames:
            sl = self._at(f.shape, fx, fy)
            assert sl is not None
            self.sum[sl] += f
            self.count[sl] += self._counted()
        where = self._at(shape, cx, cy)
        assert where is not None
        return where

    def predict(self, dx: int, dy: int) -> tuple[np.ndarray, int]:
        pred, _ = self.scene_mean(dx, dy)
        return pred, len(self.frames)

    def scene_mean(self, dx: int, dy: int) -> tuple[np.ndarray, np.ndarray | None]:
        """The prediction for a record moving ``(dx, dy)``, and where no frame saw the scene
        (None: everywhere was seen)."""
        assert self.last is not None
        self.cx += dx
        self.cy += dy
        sl = self._fit(self.last.shape, self.cx, self.cy)
        assert self.sum is not None and self.count is not None
        s, n = self.sum[sl], self.count[sl]
        zero = n == 0
        unseen = zero if zero.any() else None
        with np.errstate(divide="ignore", invalid="ignore"):  # 0/0 where unseen: replaced below
            pred = self._mean(s, n)
        if unseen is not None:  # content no frame has seen: the previous frame, moved, edge replicated
            rows, cols = np.nonzero(unseen)
            h, w = self.last.shape
            pred[rows, cols] = self.last[np.clip(rows - dy, 0, h - 1), np.clip(cols - dx, 0, w - 1)]
        return pred, unseen

    @staticmethod
    def _mean(s: np.ndarray, n: np.ndarray) -> np.ndarray:
        # (S + N // 2) // N exactly, in float64: 0 <= S < 2**24 and N < 256, so a quotient just
        # below an integer stays below it after rounding, and truncation is floor
        return ((s + np.floor(n * 0.5)) / n).astype(np.int64)

    def push(self, frame: np.ndarray) -> None:
        # kept, not copied: callers hand over a frame they no longer change
        f: np.ndarray = np.asarray(frame, self.DTYPE)
        sl = self._fit(f.shape, self.cx, self.cy)
        assert self.sum is not None and self.count is not None
        self.sum[sl] += f
        self.count[sl] += self._counted()
        self.frames.append((f, self.cx, self.cy))
        self.last = f

    def trim(self, keep: int) -> None:
        while len(self.frames) > keep:
            assert self.sum is not None and self.count is not None
            old, ox, oy = self.frames.popleft()
            sl = self._at(old.shape, ox, oy)
            assert sl is not None  # a rebuilt canvas holds every frame of the window
            self.sum[sl] -= old
            self.count[sl] -= self._counted()


class _SceneWindow3(_SceneWindow):
    """Version 3's window: frames in 1/64 counts, as int32 (half the memory traffic), and the
    mean ``S / N`` truncated toward zero: at 1/64 of a count its rounding does not matter, and
    that is one division and a cast."""

    DTYPE = np.int32

    @staticmethod
    def _mean(s: np.ndarray, n: np.ndarray) -> np.ndarray:
        # float64 holds S exactly (|S| < 2**31) and N < 256, so the correctly rounded quotient
        # never crosses the integer the exact one truncates to
        return (s / n).astype(np.int32)


class _SceneWindow4(_SceneWindow3):
    """Version 4's window: the same sums, held as int32 and uint8 (|S| < 2**31, N < 256), which
    the compiled steps read and write at a third of float64's memory traffic."""

    CANVAS = (np.int32, np.uint8)


# Version 3: the sensor-fixed pattern learned, and blocks that move on their own. Fixed point:
# 1/64 of a count.
SCALE_BITS = 6
_HALF = 1 << (SCALE_BITS - 1)
BLOCK = 16
#: Version 6: gradients of the scene mean at or beyond this (64 counts a pixel, in 1/64 counts)
#: are an edge no sub-pixel shift follows linearly (or a defect's neighbour): left as they are.
SUBPEL_LIMIT = 64 << SCALE_BITS
_SUBPEL_CLIP = 8 << SCALE_BITS  # residuals the encoder's fit leaves out: something moving on its own
_SUBPEL = struct.Struct("<bbb")  # sx, sy, sl
#: The encoder averages ``SHAKE_WINDOW`` frames, not ``window``, while its last ``SHAKE_FRAMES``
#: fits moved the picture by more than ``SHAKE_RMS`` sixteenths of a pixel (``TemporalEncoder._keep``).
SHAKE_WINDOW, SHAKE_FRAMES, SHAKE_RMS = 4, 8, 5
VECTORS = tuple((vx, vy) for vy in range(-2, 3) for vx in range(-2, 3))  # block mode k >= 1 uses VECTORS[k - 1]
_VECTOR_ARRAY = np.asarray(VECTORS, np.int64)
_U32 = struct.Struct("<I")


class _Pattern:
    """Version 3's estimate of the sensor-fixed pattern (what stays put on the sensor while the
    scene pans: column offsets and each pixel's offset), learned since the key frame from every
    decoded frame's residual against the scene prediction, in 1/64 counts. Integer arithmetic
    only, so both sides hold the same estimate on any machine. Under a pan the scene canvas mixes
    many sensor columns, so without this the pattern is paid for again in every frame.

    After ``n`` frames, with ``E`` the sum of a pixel's residuals (clipped to +-8 counts, 0
    where the pixel was not predicted from the scene) and ``C`` its column's mean residual over
    the pixels that were (rounded half up), the estimate is ``C + (E - n * C) // (n + SHRINK)``."""

    CLIP = 8 << SCALE_BITS  # a residual beyond 8 counts is the scene, not the sensor
    SHRINK = 16  # a pixel's own estimate is pulled toward its column's, as if 16 frames had said 0

    def __init__(self, shape: tuple[int, int]) -> None:
        self.n = 0
        self.colsum = np.zeros(shape[1], np.int64)
        self.colcnt = np.zeros(shape[1], np.int64)
        self.pixsum = np.zeros(shape, np.int32)  # |sum| <= 512 a frame: int32 holds 4 million frames
        self.est = np.zeros(shape, np.int32)

    def learn(self, e64: np.ndarray, off_scene: np.ndarray | None) -> None:
        """Add one frame's residuals against the scene (``e64``, consumed); ``off_scene`` marks
        the pixels not predicted from the scene (None: there are none)."""
        h = e64.shape[0]
        e = np.clip(e64, -self.CLIP, self.CLIP, out=e64)
        cnt = np.full(e.shape[1], h, np.int64)
        if off_scene is not None:
            e[off_scene] = 0
            cnt -= np.count_nonzero(off_scene, axis=0)
        self.n += 1
        self.colsum += e.sum(axis=0, dtype=np.int64)
        self.colcnt += cnt
        self.pixsum += e
        col = np.zeros_like(self.colsum)
        have = self.colcnt > 0
        col[have] = (self.colsum[have] + self.colcnt[have] // 2) // self.colcnt[have]
        col32 = col.astype(np.int32)
        est = self.pixsum - self.n * col32
        est //= self.n + self.SHRINK
        est += col32
        self.est = est


class _State3:
    """Everything version 3 carries from frame to frame, the same on both sides. Frames are
    int32 here (counts, or 1/64 counts), which halves the memory traffic of every step."""

    def __init__(self) -> None:
        self.window = _SceneWindow3()
        self.pattern: _Pattern | None = None
        self.prev: np.ndarray | None = None  # the last frame, int32 counts

    @property
    def frames(self) -> deque:
        return self.window.frames

    def reset(self) -> None:
        self.window.reset()
        self.pattern = None
        self.prev = None

    def trim(self, keep: int) -> None:
        self.window.trim(keep)

    def key(self, f: np.ndarray) -> None:
        """Start the sequence at key frame ``f`` (after ``reset``)."""
        f = f.astype(np.int32)
        self.pattern = _Pattern(f.shape)
        self.window.push(f << SCALE_BITS)
        self.prev = f

    def predict(self, dx: int, dy: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(prediction in counts, its scene part in 1/64 counts, the pixels not predicted from the
        scene or None) before any block mode: ``with_modes`` then changes the moving blocks. The
        scene part is the window's mean where the scene was seen, the previous frame moved where
        it was not (both less the pattern)."""
        assert self.pattern is not None
        m64, other = self.window.scene_mean(dx, dy)
        p = m64 + self.pattern.est
        p += _HALF
        p >>= SCALE_BITS
        return p, m64, other

    def with_modes(self, modes: np.ndarray, pred: np.ndarray, other: np.ndarray | None) -> np.ndarray:
        """Each block with mode ``k`` predicted by the previous frame moved by ``VECTORS[k - 1]``
        (edge replicated), its pixels in the second stream and out of the pattern's learning.
        Returns the pixels not predicted from the scene."""
        from thermcap.archive.codecs.tpred import kernels as tpred_kernels

        assert self.prev is not None
        if other is None:
            other = np.zeros(pred.shape, bool)
        tpred_kernels.apply_modes(modes, pred, self.prev.astype(pred.dtype, copy=False), other, BLOCK,
                                  _VECTOR_ARRAY)
        return other

    def push(self, f: np.ndarray, m64: np.ndarray, other: np.ndarray | None) -> None:
        """Learn from decoded frame ``f`` (int32 counts) and add it to the window."""
        assert self.pattern is not None
        f64 = f << SCALE_BITS
        self.pattern.learn(f64 - m64, other)
        f64 -= self.pattern.est
        self.window.push(f64)
        self.prev = f


class _State4(_State3):
    """Version 4: version 3 with the sensor's defects left out of the scene. A dead or stuck
    pixel stays put on the sensor while the view pans, so in version 3 it wrote its value into
    every scene point it crossed and the window's mean carried it there for ``window`` frames
    (about 140 polluted pixels a frame for 12 defects). Here the key frame lists the defects;
    each is predicted by its own previous value, counts 0 towards ``N`` in the scene window,
    and stays out of the pattern's learning. Each per-pixel step is one compiled pass
    (``archive.codecs.tpred.kernels``) instead of version 3's dozen numpy calls."""

    def __init__(self) -> None:
        super().__init__()
        self.window = _SceneWindow4()
        self.defects = np.empty(0, np.int64)  # flat pixel indices, increasing
        self._defect = np.zeros((0, 0), bool)  # the mask, all False when nothing is listed
        self._ones = np.zeros((0, 0), np.uint8)  # stands in for a weight when there is none

    def reset(self) -> None:
        super().reset()
        self.defects = np.empty(0, np.int64)

    def key(self, f: np.ndarray, defects: np.ndarray | None = None) -> None:
        f = f.astype(np.int32)
        self._defect = np.zeros(f.shape, bool)
        if defects is not None and defects.size:
            self.defects = defects.astype(np.int64)
            self._defect.ravel()[self.defects] = True
            self.window.weight = (~self._defect).astype(np.uint8)
        self.pattern = _Pattern(f.shape)
        f64 = f << SCALE_BITS
        f64.ravel()[self.defects] = 0
        self.window.push(f64)
        self.prev = f

    def predict(self, dx: int, dy: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        from thermcap.archive.codecs.tpred import kernels as tpred_kernels
        win, pat = self.window, self.pattern
        assert win.last is not None and pat is not None and self.prev is not None
        win.cx += dx
        win.cy += dy
        shape = win.last.shape
        sl = win._fit(shape, win.cx, win.cy)
        assert win.sum is not None and win.count is not None
        p = np.empty(shape, np.int32)
        m64 = np.empty(shape, np.int32)
        other = np.empty(shape, bool)
        tpred_kernels.predict(win.sum, win.count, sl[0].start, sl[1].start, win.last, dx, dy, pat.est, self.prev,
                              self.defects, p, m64, other)
        return p, m64, other  # the mask even where it is all False: every later step takes it as it is

    def push(self, f: np.ndarray, m64: np.ndarray, other: np.ndarray | None) -> None:
        from thermcap.archive.codecs.tpred import kernels as tpred_kernels
        win, pat = self.window, self.pattern
        assert pat is not None
        sl = win._at(f.shape, win.cx, win.cy)  # predict fitted the canvas to this frame
        assert sl is not None and win.sum is not None and win.count is not None
        pat.n += 1
        kept = np.empty(f.shape, np.int32)
        tpred_kernels.learn_and_push(
            f, m64, np.zeros(f.shape, bool) if other is None else other, self._defect, pat.pixsum, pat.colsum,
            pat.colcnt, pat.n, pat.SHRINK, pat.est, win.sum, win.count, sl[0].start, sl[1].start, *self._weight(),
            kept)
        win.frames.append((kept, win.cx, win.cy))
        win.last = kept
        self.prev = f

    def trim(self, keep: int) -> None:
        from thermcap.archive.codecs.tpred import kernels as tpred_kernels
        win = self.window
        while len(win.frames) > keep:
            old, ox, oy = win.frames.popleft()
            sl = win._at(old.shape, ox, oy)
            assert sl is not None and win.sum is not None and win.count is not None
            tpred_kernels.trim(win.sum, win.count, sl[0].start, sl[1].start, old, *self._weight())

    def _weight(self) -> tuple[np.ndarray, bool]:
        w = self.window.weight
        return (self._ones, False) if w is None else (w, True)


class _StuckPixels:
    """The encoder's watch for defects (version 4): pixels whose value has not changed for
    ``RUN`` frames in a row. A pixel with the simulator's 1.4 counts of noise stays equal
    that long about once in 10**8 frames; a dead, hot or stuck one always does. Listed at
    the next key frame (so a stream's first key lists none), at most one pixel in ``CAP``:
    beyond that the view is still or saturated and leaving pixels out would buy nothing.
    Only the encoder runs this: the record says which pixels are excluded, so the decoder
    never guesses."""

    RUN = 15
    CAP = 256

    def __init__(self) -> None:
        self.last: np.ndarray | None = None
        self.run: np.ndarray | None = None

    def see(self, f: np.ndarray) -> None:
        if self.last is None or self.last.shape != f.shape or self.run is None:
            self.run = np.zeros(f.shape, np.uint8)
        else:
            from thermcap.archive.codecs.tpred import kernels as tpred_kernels

            tpred_kernels.count_runs(f, self.last, self.run)
        self.last = f

    def listed(self) -> np.ndarray:
        assert self.run is not None
        idx = np.flatnonzero(self.run >= self.RUN)
        return idx if idx.size <= self.run.size // self.CAP else idx[:0]


def _pack_defects(defects: np.ndarray) -> bytes:
    blob = zlib.compress(defects.astype("<u4").tobytes(), 9) if defects.size else b""
    return _U32.pack(len(blob)) + blob


def _unpack_defects(payload: memoryview, shape: tuple[int, int]) -> tuple[np.ndarray, int]:
    if len(payload) < _U32.size:
        raise TpredError("the key frame ends before its defect list")
    (n,) = _U32.unpack_from(payload, 0)
    if n == 0:
        return np.empty(0, np.int64), _U32.size
    try:
        raw = zlib.decompress(bytes(payload[_U32.size:_U32.size + n]))
    except zlib.error as exc:
        raise TpredError(f"the defect list does not decode ({exc})") from None
    if len(raw) % 4:
        raise TpredError(f"the defect list holds {len(raw)} bytes, not whole uint32 values")
    idx = np.frombuffer(raw, "<u4").astype(np.int64)
    if idx.size and (int(idx[-1]) >= shape[0] * shape[1] or (np.diff(idx) <= 0).any()):
        raise TpredError(f"the defect list is not increasing pixel indices below {shape[0] * shape[1]}")
    return idx, _U32.size + n


def _choose_modes(f: np.ndarray, pred: np.ndarray, prev: np.ndarray, most: int = 128) -> np.ndarray | None:
    """The encoder's choice of blocks that move on their own (a vehicle crossing a panned
    view): blocks whose residual against the scene is well above the frame's typical block are
    tried against the previous frame moved by each of ``VECTORS``, and take the best when it
    is clearly better. None when no block does."""
    from thermcap.archive.codecs.tpred import kernels as tpred_kernels
    h, w = f.shape
    hb, wb = -(-h // BLOCK), -(-w // BLOCK)
    # which blocks to try: their residual on every other row and column (a quarter of the work)
    sad = tpred_kernels.block_sads(f, pred, hb, wb, BLOCK)
    cand = np.flatnonzero(sad > 1.5 * float(np.median(sad)) + 16)
    if not cand.size:
        return None
    cand = cand[np.argsort(-sad[cand], kind="stable")[:most]]
    choice = tpred_kernels.block_choices(f, pred, prev, cand, wb, BLOCK, _VECTOR_ARRAY)
    if not choice.any():
        return None
    modes = np.zeros(hb * wb, np.uint8)
    modes[cand] = choice
    return modes.reshape(hb, wb)


def _subpel(f: np.ndarray, pred: np.ndarray, m64: np.ndarray, est: np.ndarray,
            other: np.ndarray) -> tuple[tuple[int, int, int], int | None]:
    """Version 6's encoder side, measured: ``((sx, sy, sl), cost)``, the shift and the
    Laplacian's weight in sixteenths fitted by least squares to the residual against the scene
    mean's gradients and Laplacian; zeros where the fit is degenerate or does not lower the
    residual's absolute sum (on every other row and column). The cost is that sum for the terms
    returned (``None`` where the fit was degenerate and nothing was measured). The correction is
    measured on those pixels alone and applied by ``_corrected`` only where the record keeps it:
    version 8's filters replace it on most shaking frames."""
    from thermcap.archive.codecs.tpred import kernels as tpred_kernels

    sums = tpred_kernels.subpel_sums(f, m64, est, other, SUBPEL_LIMIT, _SUBPEL_CLIP)
    a, rhs = sums[:, :3], sums[:, 3]
    scale = float(np.prod(a.diagonal()))
    if scale <= 0 or abs(float(np.linalg.det(a))) <= 1e-9 * scale:  # a flat frame, or too few pixels
        return (0, 0, 0), None
    fit = np.linalg.solve(a, rhs) * 16
    sx, sy = (max(-15, min(15, round(v))) for v in fit[:2])  # less than a pixel: a whole one is dx, dy
    sl = max(-16, min(16, round(fit[2])))
    if sx == 0 and sy == 0 and sl == 0:
        return (0, 0, 0), None
    before, after = tpred_kernels.subpel_costs(f, m64, est, other, pred, sx, sy, sl, SUBPEL_LIMIT)
    if after >= before:
        return (0, 0, 0), before
    return (sx, sy, sl), after


def _corrected(pred: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray,
               terms: tuple[int, int, int]) -> np.ndarray:
    """Version 6's correction by ``terms``, the encoder's and the decoder's alike: ``pred``
    corrected in place; returns the corrected scene mean (``m64`` itself where the terms are
    zeros)."""
    if terms == (0, 0, 0):
        return m64
    from thermcap.archive.codecs.tpred import kernels as tpred_kernels

    m64c = np.empty_like(m64)
    tpred_kernels.subpel_apply(pred, m64, est, other, pred, *terms, SUBPEL_LIMIT, False,
                               pred, m64c)  # nothing measured: pred stands in for the frame
    return m64c


def _filtered(f: np.ndarray, pred: np.ndarray, m64: np.ndarray, est: np.ndarray, other: np.ndarray,
              cost: int | None) -> tuple[bytes, np.ndarray, np.ndarray] | None:
    """Version 8's encoder side: the record's filter bytes, the prediction and the scene mean,
    with the filters fitted to ``f`` on the uncorrected ``pred`` and ``m64``; ``None`` where they
    do not lower the residual's absolute sum below ``cost`` (version 6's terms'; the uncorrected
    prediction's where that is ``None``)."""
    from thermcap.archive.codecs.tpred import filter as tpred_filter

    fitted = tpred_filter.fit(f, pred, m64, est, other)
    if fitted is None:
        return None
    coefs, precisions, p, m64c, before, after = fitted
    if after >= (before if cost is None else cost):
        return None
    body = b"".join(bytes([int(q)]) + c.tobytes() for q, c in zip(precisions, coefs, strict=True))
    return bytes([len(coefs)]) + body, p, m64c


def _pack_streams(modes: np.ndarray | None, resid: np.ndarray, other: np.ndarray | None) -> tuple[int, bytes]:
    ptype, dtype = _payload_type(resid)
    r: np.ndarray = resid.astype(dtype)
    chunks = [bytes(imagecodecs.pcodec_encode(v, level=8)) if v.size else b""
              for v in ((r.ravel(), r[:0, 0]) if other is None else (r[~other], r[other]))]
    return ptype, _with_lengths(modes, chunks)


def _with_lengths(modes: np.ndarray | None, chunks: list[bytes]) -> bytes:
    """The block-mode map, then each stream, each behind its ``u32`` length."""
    mode_bytes = b"" if modes is None else zlib.compress(modes.tobytes(), 9)
    parts = [_U32.pack(len(mode_bytes)), mode_bytes]
    for chunk in chunks:
        parts += [_U32.pack(len(chunk)), chunk]
    return b"".join(parts)


def _pack_streams4(modes: np.ndarray | None, f: np.ndarray, pred: np.ndarray,
                   other: np.ndarray | None) -> tuple[int, bytes]:
    """Version 4: the same two streams, split in one pass and each coded by ``archive.codecs.tpred.rans``."""
    from thermcap.archive.codecs.tpred import kernels as tpred_kernels
    from thermcap.archive.codecs.tpred import rans
    scene = np.empty(f.size, np.int32)
    rest = np.empty(f.size, np.int32)
    n0, n1, lo, hi = tpred_kernels.split_residuals(f, pred, np.zeros(f.shape, bool) if other is None else other,
                                                   scene, rest)
    ptype = _INT16 if lo >= -32768 and hi <= 32767 else _INT32
    return ptype, _with_lengths(modes, [rans.encode(scene[:n0]) if n0 else b"", rans.encode(rest[:n1]) if n1 else b""])


def _unpack_modes(payload: memoryview, shape: tuple[int, int]) -> tuple[np.ndarray | None, int]:
    (n,) = _U32.unpack_from(payload, 0)
    if n == 0:
        return None, _U32.size
    hb, wb = -(-shape[0] // BLOCK), -(-shape[1] // BLOCK)
    try:
        modes = np.frombuffer(zlib.decompress(bytes(payload[_U32.size:_U32.size + n])), np.uint8)
    except zlib.error as exc:
        raise TpredError(f"the block modes do not decode ({exc})") from None
    if modes.size != hb * wb or int(modes.max()) > len(VECTORS):
        raise TpredError(f"the block modes hold {modes.size} values up to {int(modes.max())}, "
                         f"{hb * wb} up to {len(VECTORS)} expected")
    return modes.reshape(hb, wb), _U32.size + n


def _stream_chunks(payload: memoryview, pos: int, counts: tuple[int, int]) -> list[memoryview]:
    """The two residual streams' bytes, each checked against the values it must hold."""
    chunks = []
    for k, count in enumerate(counts):
        if pos + _U32.size > len(payload):
            raise TpredError("the payload ends before its residual streams do")
        (n,) = _U32.unpack_from(payload, pos)
        pos += _U32.size
        if bool(n) != bool(count):
            raise TpredError(f"residual stream {k} holds {n} bytes for {count} values")
        chunks.append(payload[pos:pos + n])
        pos += n
    if pos != len(payload):
        raise TpredError(f"the payload holds {len(payload) - pos} bytes after its residual streams")
    return chunks


def _unpack_streams4(payload: memoryview, pos: int, pred: np.ndarray, other: np.ndarray | None) -> np.ndarray:
    """Version 4: the frame, from the prediction and the two ``archive.codecs.tpred.rans`` streams."""
    from thermcap.archive.codecs.tpred import kernels as tpred_kernels
    from thermcap.archive.codecs.tpred import rans
    n_other = int(np.count_nonzero(other)) if other is not None else 0
    counts = (pred.size - n_other, n_other)
    streams = []
    for k, (chunk, count) in enumerate(zip(_stream_chunks(payload, pos, counts), counts, strict=True)):
        try:
            streams.append(rans.decode(chunk, count))
        except rans.RansError as exc:
            raise TpredError(f"residual stream {k}: {exc}") from None
    f = np.empty(pred.shape, np.int32)
    status = tpred_kernels.merge_residuals(pred, np.zeros(pred.shape, bool) if other is None else other,
                                           streams[0], streams[1], f)
    if status:
        raise TpredError("the record decodes outside uint16: damaged, or not from this sequence")
    return f


def _unpack_streams(ptype: int, payload: memoryview, pos: int, other: np.ndarray | None,
                    shape: tuple[int, int]) -> np.ndarray:
    """The residuals, from the scene's stream and the others' (each in row-major order)."""
    n_other = int(np.count_nonzero(other)) if other is not None else 0
    counts = (shape[0] * shape[1] - n_other, n_other)
    streams = [_decode_chunk(ptype, chunk, (count,), f"residual stream {k}") if count else np.empty(0, np.int16)
               for k, (chunk, count) in enumerate(zip(_stream_chunks(payload, pos, counts), counts, strict=True))]
    out = np.empty(shape, np.int32 if ptype == _INT16 else np.int64)  # int16 + int32 prediction cannot overflow
    if other is None:
        out.ravel()[:] = streams[0]
    else:
        out[~other] = streams[0]
        out[other] = streams[1]
    return out


def _window_for(version: int) -> _Window | _SceneWindow | _State3:
    """The state a sequence of ``version`` carries (versions 4 to 8 share version 4's)."""
    return _Window() if version == 1 else _SceneWindow() if version == 2 else _State3() if version == 3 else _State4()



def _best_shift(cur: np.ndarray, prev: np.ndarray, axis: int, max_shift: int, other: int = 0) -> int:
    """The shift along ``axis`` (1: columns, dx; 0: rows, dy) that best maps ``prev`` onto
    ``cur``: the least mean absolute difference (each clipped at ``_CLIP``) over the overlap, on
    every 8th line across it (the other axis shifted by ``other``). The candidates come from the
    frames' profiles along the axis (the median of those lines): every shift is tried on the
    profiles, and only the best few on the lines themselves, which is 1/10 of trying every shift
    on the lines."""
    from thermcap.archive.codecs.tpred import kernels as tpred_kernels
    # for rows (axis 0), the transposes' lines; np.roll(prev, other, axis=0)[::8] for the columns
    c = tpred_kernels.sampled_lines(cur, axis, 8, 0)
    p = tpred_kernels.sampled_lines(prev, axis, 8, other)
    n = c.shape[1]
    shifts = [s for s in range(-max_shift, max_shift + 1) if n - abs(s) >= max(1, n // 2)]
    if not shifts:
        return 0

    # medians, not means, and clipped differences: a hot target that moves on its own (fixed on
    # the sensor while the view pans) must not outvote the scene
    cp, pp = tpred_kernels.column_medians(c), tpred_kernels.column_medians(p)
    by_profile = tpred_kernels.shift_costs(cp[None, :], pp[None, :], np.asarray(shifts), _CLIP)
    order = np.argsort(by_profile, kind="stable")[:_CANDIDATES]
    tried = np.asarray(sorted({shifts[i] for i in order} | {0}))
    costs = tpred_kernels.line_shift_costs(c, p, tried, _CLIP)
    best, best_cost = 0, np.inf
    for s, k in zip(tried.tolist(), costs.tolist(), strict=True):
        if k < best_cost - 1e-9:
            best, best_cost = s, k
    return best


_CANDIDATES = 3  # shifts the profiles propose, each then measured on the lines
_CLIP = 16  # counts: a difference beyond it is something moving on its own, not the view


class TemporalEncoder:
    def __init__(self, window: int = 16, key_interval: int = 64, max_shift: int = 32,
                 bitstream: int = BITSTREAM_VERSION, defects: np.ndarray | None = None) -> None:
        """``defects`` (version 4): the sensor's defects as the caller knows them (``encode_gops``
        keeps one watch for the whole sequence); every key frame lists them and the encoder keeps
        no watch of its own. Otherwise its own watch lists them."""
        if not 1 <= window <= 255 or key_interval < 1:
            raise ValueError(f"tpred: window 1..255 and key_interval >= 1, got {window}, {key_interval}")
        if bitstream not in MAGICS:
            raise ValueError(f"tpred writes bitstream versions {sorted(MAGICS)}, got {bitstream}")
        keep_frame_blocks()  # its per-frame temporaries: see recorder.frame_heap
        self.window, self.key_interval, self.max_shift = window, key_interval, max_shift
        self.bitstream, self._magic = bitstream, MAGICS[bitstream]
        self._state = _window_for(bitstream)
        self._prev: np.ndarray | None = None
        self._since_key = 0
        self._known_defects = defects
        self._stuck = _StuckPixels() if bitstream >= 4 and defects is None else None
        self._alone = 0  # bytes of the last frame coded alone (a key, or a trial): what it costs here
        self.intra_decided = 0  # frames written as intra records, being smaller coded alone
        self._shake: deque[int] = deque(maxlen=SHAKE_FRAMES)  # version 6: the last fits' |(sx, sy)|**2
        self._rule = -1 if bitstream >= 7 else None  # version 7: frames coded alone pick their key rule

    def encode(self, frame: np.ndarray) -> bytes:
        """The frame's record. In version 5 a frame is never written larger than coded alone:
        once its predicted record reaches ``INTRA_TRY`` of the last frame coded alone, the frame is
        coded alone too and the smaller written (an intra record, which carries the sequence on
        as a predicted frame does). Where prediction loses: temporal noise above the scene's
        detail, a shutter (NUC) or gain step, a cut."""
        if frame.dtype != np.uint16 or frame.ndim != 2:
            raise ValueError(f"tpred encodes 2-D uint16 frames, got {frame.dtype} {frame.shape}")
        h, w = frame.shape
        f: np.ndarray = frame.astype(np.int32 if isinstance(self._state, _State3) else np.int64)
        if self._stuck is not None:
            self._stuck.see(f)
        if self._prev is None or self._prev.shape != frame.shape or self._since_key >= self.key_interval:
            return self._key(f, *self._intra(f))
        dx, dy = self._motion(f)
        st = self._state
        kind = PREDICTED
        if isinstance(st, _State3):
            used = len(st.frames)
            pred, m64, other = st.predict(dx, dy)
            assert st.prev is not None
            scene_other = other.copy() if other is not None else None  # what an intra record carries on
            scene_m64 = m64  # what an intra record learns against
            shift = b""
            if self.bitstream >= 6:
                assert st.pattern is not None and other is not None
                terms, cost = _subpel(f, pred, m64, st.pattern.est, other)
                self._shake.append(terms[0] ** 2 + terms[1] ** 2)
                filt = b"\0" if self.bitstream >= 8 else b""
                filtered = None
                if self.bitstream >= 8 and (terms[:2] != (0, 0) or self._keep() < self.window):
                    # it moved by a fraction of a pixel: a filter may follow the move's blur too
                    filtered = _filtered(f, pred, m64, st.pattern.est, other, cost)
                if filtered is not None:
                    filt, pred, m64 = filtered
                    terms = (0, 0, 0)
                else:
                    m64 = _corrected(pred, m64, st.pattern.est, other, terms)
                shift = _SUBPEL.pack(*terms) + filt
            modes = _choose_modes(f, pred, st.prev)
            if modes is not None:
                other = st.with_modes(modes, pred, other)
            if isinstance(st, _State4):
                ptype, payload = _pack_streams4(modes, f, pred, other)
                payload = shift + payload
            else:
                ptype, payload = _pack_streams(modes, f - pred, other)
            if self.bitstream >= 5 and HEADER.size + len(payload) >= INTRA_TRY * self._alone:
                from thermcap.archive.codecs.tpred import key as tpred_key

                alone = tpred_key.encode_key(f, rule=self._rule)
                self._alone = HEADER.size + len(alone)
                if len(alone) < len(payload):  # the mode decision: coded alone, it is smaller
                    kind, ptype, payload, other, m64 = INTRA, _INT32, alone, scene_other, scene_m64
                    self.intra_decided += 1
            st.push(f, m64, other)
        else:
            pred, used = st.predict(dx, dy)
            ptype, payload = _pack(f - pred)
            st.push(f)
        st.trim(self._keep())
        self._prev = f
        self._since_key += 1
        return HEADER.pack(self._magic, kind, used, w, h, dx, dy, ptype, 0, len(payload)) + payload

    def _keep(self) -> int:
        """How many frames the next prediction averages: ``window``, or ``SHAKE_WINDOW`` while the
        last ``SHAKE_FRAMES`` fits moved the picture by more than ``SHAKE_RMS`` sixteenths of a
        pixel (root mean square): a shaking camera's older frames sit elsewhere, and the mean of
        16 of them blurs what 4 keep sharp. The record says how many it averaged, so a decoder
        follows whatever the encoder keeps."""
        shake = self._shake
        if len(shake) == shake.maxlen and sum(shake) > SHAKE_RMS ** 2 * len(shake):
            return min(self.window, SHAKE_WINDOW)
        return self.window

    def _intra(self, f: np.ndarray) -> tuple[int, bytes, np.ndarray | None]:
        """(payload type, payload, defects) of ``f`` coded alone, changing no state."""
        from thermcap.archive.codecs.tpred import key as tpred_key

        if isinstance(self._state, _State4):
            defects = self._stuck.listed() if self._stuck is not None else self._known_defects
            assert defects is not None
            return _INT32, _pack_defects(defects) + tpred_key.encode_key(f, rule=self._rule), defects
        ptype, payload = _pack_vertical(f)
        return ptype, payload, None

    def _key(self, f: np.ndarray, ptype: int, payload: bytes, defects: np.ndarray | None) -> bytes:
        """Start the sequence again at ``f``, as a decoder does at a key record."""
        h, w = f.shape
        self._since_key = 0
        self._shake.clear()  # each GOP on its own, as encode_gops encodes them
        self._state.reset()
        if isinstance(self._state, _State4):
            self._state.key(f, defects)
        elif isinstance(self._state, _State3):
            self._state.key(f)
        else:
            self._state.push(f)
        self._state.trim(self.window)
        self._prev = f
        self._since_key += 1
        record = HEADER.pack(self._magic, KEY, 0, w, h, 0, 0, ptype, 0, len(payload)) + payload
        self._alone = len(record)
        return record

    def _motion(self, f: np.ndarray) -> tuple[int, int]:
        assert self._prev is not None
        if self.max_shift <= 0:
            return 0, 0
        dx = _best_shift(f, self._prev, 1, self.max_shift)
        dy = _best_shift(f, self._prev, 0, min(self.max_shift, 8), other=dx)
        if (dx, dy) == (0, 0):
            return 0, 0
        from thermcap.archive.codecs.tpred import kernels as tpred_kernels

        still, moved = tpred_kernels.motion_sums(f, self._prev, dx, dy, 4, _CLIP)  # against _shift(prev)
        return (dx, dy) if moved < still else (0, 0)


class TemporalDecoder:
    def __init__(self) -> None:
        keep_frame_blocks()
        self._state: _Window | _SceneWindow | _State3 = _Window()
        self._version = 0  # of the sequence's key frame; 0 before any
        self._shape: tuple[int, int] | None = None

    @staticmethod
    def _read_terms(payload: memoryview) -> tuple[tuple[int, int, int], memoryview]:
        """Version 6: the record's sub-pixel shift and Laplacian weight, and the rest of the payload."""
        if len(payload) < _SUBPEL.size:
            raise TpredError("a version 6 record ends before its sub-pixel shift")
        sx, sy, sl = _SUBPEL.unpack_from(payload, 0)
        if not (abs(sx) < 16 and abs(sy) < 16 and abs(sl) <= 16):
            raise TpredError(f"a sub-pixel shift of ({sx}, {sy}) sixteenths (a pixel or more), or a Laplacian "
                             f"weight of {sl} sixteenths (beyond 16)")
        return (sx, sy, sl), payload[_SUBPEL.size:]

    @staticmethod
    def _read_filter(payload: memoryview) -> tuple[tuple[np.ndarray, np.ndarray] | None, memoryview]:
        """Version 8: the record's filters, their coefficients and precisions (``None``: no
        filter), and the rest of the payload."""
        from thermcap.archive.codecs.tpred.filter import FILTERS, PRECISIONS, TAPS

        if len(payload) < 1:
            raise TpredError("a version 8 record ends before its filters")
        count = payload[0]
        if count == 0:
            return None, payload[1:]
        if count != FILTERS:
            raise TpredError(f"a record with {count} filters (version 8 has {FILTERS} or none)")
        size = 1 + TAPS.shape[0]
        if len(payload) < 1 + count * size:
            raise TpredError("a version 8 record ends inside its filters")
        body = np.frombuffer(payload[1:1 + count * size], np.uint8).reshape(count, size)
        precisions = body[:, 0].astype(np.int64)
        bad = [int(q) for q in precisions if int(q) not in PRECISIONS]
        if bad:
            raise TpredError(f"a filter in units of 2**-{bad[0]} (version 8 has 2**-{PRECISIONS[0]} to "
                             f"2**-{PRECISIONS[-1]})")
        return (body[:, 1:].view(np.int8).copy(), precisions), payload[1 + count * size:]

    def _apply_filter(self, filters: tuple[np.ndarray, np.ndarray], pred: np.ndarray, m64: np.ndarray,
                      other: np.ndarray | None) -> np.ndarray:
        """Version 8: ``pred`` filtered in place; returns the filtered scene mean."""
        from thermcap.archive.codecs.tpred import filter as tpred_filter

        st = self._state
        assert isinstance(st, _State4) and st.pattern is not None and other is not None
        m64c = np.empty_like(m64)
        tpred_filter.filter_apply(pred, m64, st.pattern.est, other, pred, *filters, tpred_filter.FILTER_SPLIT,
                                  tpred_filter.FILTER_LIMIT, False, pred, m64c)  # pred stands in for the frame
        return m64c

    def _apply_terms(self, terms: tuple[int, int, int], pred: np.ndarray, m64: np.ndarray,
                     other: np.ndarray | None) -> np.ndarray:
        """Version 6: ``pred`` corrected in place; returns the corrected scene mean."""
        st = self._state
        assert isinstance(st, _State4) and st.pattern is not None and other is not None
        return _corrected(pred, m64, st.pattern.est, other, terms)

    def decode(self, record: bytes | memoryview) -> np.ndarray:
        from thermcap.archive.codecs.tpred import key as tpred_key
        hdr = parse_header(record)
        payload = memoryview(record)[HEADER.size:]
        shape = (hdr.height, hdr.width)
        defects = None
        if hdr.kind == KEY:
            if hdr.version >= 4:
                defects, pos = _unpack_defects(payload, shape)
                try:
                    f = tpred_key.decode_key(payload[pos:], shape, ruled=hdr.version >= 7)
                except tpred_key.KeyFrameError as exc:
                    raise TpredError(str(exc)) from None
            else:
                f = np.cumsum(_unpack(hdr.payload_type, payload, shape), axis=0)
            if hdr.version != self._version:
                self._state, self._version = _window_for(hdr.version), hdr.version
            self._state.reset()
        else:
            if self._shape != shape or not self._state.frames:
                raise TpredError("a predicted frame without the frames before it (decode from its key frame)")
            if hdr.version != self._version:
                raise TpredError(f"a version {hdr.version} record in a sequence whose key frame is version "
                                 f"{self._version}")
            self._state.trim(hdr.window)
            if hdr.window != len(self._state.frames):
                raise TpredError(f"the record averages {hdr.window} frames, the decoder holds "
                                 f"{len(self._state.frames)}")
            st = self._state
            if hdr.kind == INTRA:  # coded alone, and carried on as a predicted frame is
                if not isinstance(st, _State4):
                    raise TpredError("an intra record in a sequence of version 3 or older")
                _, m64, other = st.predict(hdr.dx, hdr.dy)
                try:
                    f = tpred_key.decode_key(payload, shape, ruled=hdr.version >= 7).astype(np.int32)
                except tpred_key.KeyFrameError as exc:
                    raise TpredError(str(exc)) from None
            elif isinstance(st, _State3):
                terms, filt = (0, 0, 0), None
                if hdr.version >= 6:
                    terms, payload = self._read_terms(payload)
                if hdr.version >= 8:
                    filt, payload = self._read_filter(payload)
                    if filt is not None and any(terms):
                        raise TpredError("a record with both a sub-pixel shift and filters (version 8 has one or "
                                         "the other)")
                modes, pos = _unpack_modes(payload, shape)
                pred, m64, other = st.predict(hdr.dx, hdr.dy)
                if filt is not None:
                    m64 = self._apply_filter(filt, pred, m64, other)
                elif any(terms):
                    m64 = self._apply_terms(terms, pred, m64, other)
                if modes is not None:
                    other = st.with_modes(modes, pred, other)
                if isinstance(st, _State4):
                    f = _unpack_streams4(payload, pos, pred, other)  # range checked as it is merged
                else:
                    f = pred + _unpack_streams(hdr.payload_type, payload, pos, other, shape)
            else:
                pred, _ = st.predict(hdr.dx, hdr.dy)
                f = pred + _unpack(hdr.payload_type, payload, shape)
        if not (isinstance(self._state, _State4) and hdr.kind == PREDICTED) and (f.min() < 0 or f.max() > 65535):
            raise TpredError("the record decodes outside uint16: damaged, or not from this sequence")
        if not isinstance(self._state, _State3):
            self._state.push(f)
        elif hdr.kind == KEY:
            if isinstance(self._state, _State4):
                self._state.key(f, defects)
            else:
                self._state.key(f)
        else:
            self._state.push(f.astype(np.int32, copy=False), m64, other)
        self._shape = shape
        return f.astype(np.uint16)


def encode_gops(items: Iterable[T], pixels: Callable[[T], np.ndarray], *, workers: int = 2, window: int = 16,
                key_interval: int = 64, max_shift: int = 32,
                bitstream: int = BITSTREAM_VERSION) -> Iterator[tuple[T, bytes]]:
    """Each item with its record, byte for byte what one ``TemporalEncoder`` writes for the
    sequence, each run from a key frame to the next (a GOP) encoded on its own thread: a GOP
    needs nothing from before it but its key's defect list, which this thread's watch keeps.
    At most ``workers`` GOPs are encoding and one being gathered, however long the sequence."""
    watch = _StuckPixels() if bitstream >= 4 else None

    def gops() -> Iterator[tuple[list[T], np.ndarray | None]]:
        gop: list[T] = []
        shape: tuple[int, ...] | None = None
        defects: np.ndarray | None = None
        for item in items:
            f = pixels(item)
            if watch is not None and f.ndim == 2:
                watch.see(f)
            if gop and (len(gop) >= key_interval or f.shape != shape):
                yield gop, defects
                gop = []
            if not gop:
                shape = f.shape
                defects = watch.listed() if watch is not None and watch.run is not None else None
            gop.append(item)
        if gop:
            yield gop, defects

    def encode(job: tuple[list[T], np.ndarray | None]) -> list[tuple[T, bytes]]:
        run, defects = job
        enc = TemporalEncoder(window, key_interval, max_shift, bitstream, defects=defects)
        return [(item, enc.encode(pixels(item))) for item in run]

    from thermcap.archive.parallel import ordered_map

    for done in ordered_map(encode, gops(), workers, window=workers):
        yield from done


def decode_gops(items: Iterable[T], record: Callable[[T], bytes], *, workers: int = 2,
                name: Callable[[T], str] = str) -> Iterator[tuple[T, np.ndarray]]:
    """Each item with its frame, a GOP (a key frame and the records up to the next) on each
    thread; the records are read on this thread. A ``TpredError`` names (``name``) the item it
    arose in."""

    def gops() -> Iterator[list[tuple[T, bytes]]]:
        gop: list[tuple[T, bytes]] = []
        for item in items:
            rec = record(item)
            if gop and len(rec) >= HEADER.size and rec[4] == KEY and rec[:4] in _VERSION_OF:
                yield gop
                gop = []
            gop.append((item, rec))
        if gop:
            yield gop

    def decode(run: list[tuple[T, bytes]]) -> list[tuple[T, np.ndarray]]:
        dec = TemporalDecoder()
        out = []
        for item, rec in run:
            try:
                out.append((item, dec.decode(rec)))
            except TpredError as exc:
                raise TpredError(f"{name(item)}: {exc}") from None
        return out

    from thermcap.archive.parallel import ordered_map

    for done in ordered_map(decode, gops(), workers, window=workers):
        yield from done


def decode_records(records: Iterable[bytes | memoryview]) -> Iterator[np.ndarray]:
    """Frames of a run of records that starts at a key frame."""
    dec = TemporalDecoder()
    for rec in records:
        yield dec.decode(rec)
