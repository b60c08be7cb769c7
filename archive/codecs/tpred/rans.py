"""A static rANS entropy coder for integer residuals: tpred's version 4 residual streams.

pcodec coded tpred's residuals within 0.6-0.9% of their zeroth-order entropy; on a residual that
is nearly all sensor noise that gap is most of what is left to win. This coder gets within
about 0.2% (the frequency table included): each stream sends its own table of token
frequencies and is coded against it exactly.

Stream format, stable (tpred's golden records in ``tests/fixture/bitstreams/tpred-v4`` hold it):

    u8           T: the number of tokens in the table (1..86)
    T x varint   the frequency of tokens 0..T-1 (LEB128, 7 bits a byte, low first); they sum to
                 4096 (12-bit probabilities), and a token of frequency 0 never occurs
    2 x u32      the two rANS states the decoder starts from, x0 then x1 (little-endian)
    bytes        the renormalisation bytes of both, in the order the decoder reads them

Values become tokens as JPEG XL's hybrid integers do (split 32, one mantissa bit in the token):
``u = 2v`` for ``v >= 0`` and ``-2v - 1`` otherwise; ``u < 32`` is token ``u``; otherwise, with
``k = floor(log2 u)``, the token is ``32 + 2 (k - 5) + (bit k-1 of u)`` and the ``k - 1`` low bits
of ``u`` follow it, coded as uniform symbols of at most 8 bits, lowest chunk first.

The coder is ryg_rans's byte-wise rANS, two states interleaved (value ``i`` and its extra bits
use state ``x0`` for even ``i``, ``x1`` for odd), so a decoder's two dependency chains overlap.
A state ``x`` is in ``[2**23, 2**31)``. Decoding a token:
``s = x & 4095``, the token ``t`` whose cumulative range holds ``s``, ``x = f[t] * (x >> 12) + s -
c[t]``; a uniform chunk of ``k`` bits: ``bits = x & (2**k - 1)``, ``x >>= k``. After each, while
``x < 2**23``: ``x = (x << 8) | next byte`` (the one byte stream both states share). The encoder
starts both at ``2**23`` and works backwards, so a decoder that has read every byte ends with both
at ``2**23``: a stream that does not is damaged, and says so.

The loops are compiled by numba (nogil), so two sequences code on two cores at once.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

__all__ = ["RansError", "decode", "encode"]

PROB_BITS = 12
PROB_SCALE = 1 << PROB_BITS
RANS_L = 1 << 23
DIRECT = 32  # tokens 0..31 are the value itself (zigzagged)
MAX_TOKENS = DIRECT + 2 * (32 - 5)  # k = 5..31, two tokens each: 86


class RansError(ValueError):
    """A stream that is not one this coder wrote, or one that was damaged."""


@numba.njit(cache=True, nogil=True, inline="always")
def token(v: Any) -> tuple[Any, Any, Any]:  # pragma: no cover
    """A value's token, its count of extra bits and those bits (the rule in this module's
    docstring); ``tpred_key`` estimates a rule's cost with it too."""
    u = 2 * v if v >= 0 else -2 * v - 1
    if u < DIRECT:
        return u, 0, 0
    k = 5
    while (u >> (k + 1)) != 0:
        k += 1
    return DIRECT + 2 * (k - 5) + ((u >> (k - 1)) & 1), k - 1, u & ((np.int64(1) << (k - 1)) - 1)


@numba.njit(cache=True, nogil=True)
def _counts(values: np.ndarray, counts: np.ndarray) -> int:  # pragma: no cover
    """The tokens' counts; returns the extra bits' total. Four partial counts, so consecutive
    equal tokens do not wait on each other's increments."""
    bits = 0
    part = np.zeros((4, MAX_TOKENS), np.int64)
    for i in range(values.size):
        t, nb, _ = token(np.int64(values[i]))
        bits += nb
        part[i & 3, t] += 1
    for j in range(4):
        for t in range(MAX_TOKENS):
            counts[t] += part[j, t]
    return bits


@numba.njit(cache=True, nogil=True, inline="always")
def _put(x: Any, t: Any, nb: Any, e: Any, x_max: np.ndarray, rcp: np.ndarray, rshift: np.ndarray, bias: np.ndarray,
         cmpl: np.ndarray, out: np.ndarray, pos: int) -> tuple[Any, int]:  # pragma: no cover
    """One value (token ``t``, ``nb`` extra bits ``e``) onto state ``x``, backwards, its bytes
    before ``out[pos]``: (the new state, the new position; -1 if ``out`` was too small)."""
    if nb:  # the extra bits, last chunk first (the decoder reads the lowest chunk first)
        shift = ((nb - 1) // 8) * 8
        while shift >= 0:
            k = 8 if nb - shift > 8 else nb - shift
            v = (e >> np.uint64(shift)) & np.uint64((1 << k) - 1)
            xm = np.uint64((RANS_L >> k) << 8)
            while x >= xm:
                if pos == 8:  # never: the buffer is sized for the worst case
                    return x, -1
                pos -= 1
                out[pos] = np.uint8(x & np.uint64(0xFF))
                x >>= np.uint64(8)
            x = (x << np.uint64(k)) | v
            shift -= 8
    xm = x_max[t]
    # at most two bytes out (x < 2**31, x_max >= 2**19), without a branch: both written, the
    # position moved by how many count (the next value's bytes overwrite the rest)
    if pos < 10:
        return x, -1
    nout = int(x >= xm) + int(x >= (xm << np.uint64(8)))
    out[pos - 1] = np.uint8(x & np.uint64(0xFF))
    out[pos - 2] = np.uint8((x >> np.uint64(8)) & np.uint64(0xFF))
    pos -= nout
    x >>= np.uint64(8 * nout)
    q = ((x * rcp[t]) >> np.uint64(32)) >> rshift[t]
    return x + bias[t] + q * cmpl[t], pos


@numba.njit(cache=True, nogil=True)
def _encode(values: np.ndarray, freq: np.ndarray, cum: np.ndarray,
            out: np.ndarray) -> int:  # pragma: no cover
    """rANS-encode backwards into the tail of ``out``; returns where the stream starts (-1 if
    ``out`` was too small, which its sizing rules out). The division by a token's frequency is a
    multiplication by its reciprocal (ryg_rans's exact method), which is what makes the encoder as
    fast as pcodec. The values go a pair at a time, the odd one on ``x1`` then the even one on
    ``x0``, with no choice of state a value: the two states' chains overlap in the CPU, as the
    decoder's do (0.80-0.87x the time of one value a turn, 2026-12-07). A value's token is
    worked out again here rather than stored by ``_counts``, and a state's bytes go out without
    a branch (``_put``): whether a value sends out a byte is as random as the noise it codes, and
    the mispredicted loop cost more than the rest (2.06 -> 1.55 ms for a 640x512 frame's two
    streams, the bytes unchanged, 2026-12-07)."""
    nt = freq.size
    x_max = np.empty(nt, np.uint64)
    rcp = np.empty(nt, np.uint64)
    rshift = np.empty(nt, np.uint64)
    bias = np.empty(nt, np.uint64)
    cmpl = np.empty(nt, np.uint64)
    for t in range(nt):
        f = np.uint64(freq[t])
        x_max[t] = np.uint64((RANS_L >> PROB_BITS) << 8) * f
        cmpl[t] = np.uint64(PROB_SCALE) - f
        if f < 2:
            rcp[t] = np.uint64(0xFFFFFFFF)
            rshift[t] = 0
            bias[t] = np.uint64(cum[t] + PROB_SCALE - 1)
        else:
            sh = np.uint64(0)
            while f > (np.uint64(1) << sh):
                sh += np.uint64(1)
            rcp[t] = ((np.uint64(1) << (sh + np.uint64(31))) + f - np.uint64(1)) // f
            rshift[t] = sh - np.uint64(1)
            bias[t] = np.uint64(cum[t])
    x0 = np.uint64(RANS_L)
    x1 = np.uint64(RANS_L)
    pos = out.size
    i = values.size - 1
    if i % 2 == 0:  # an odd count: the last value, even, has no partner
        t, nb, e = token(np.int64(values[i]))
        x0, pos = _put(x0, t, nb, np.uint64(e), x_max, rcp, rshift, bias, cmpl, out, pos)
        if pos < 0:
            return -1
        i -= 1
    while i > 0:
        t, nb, e = token(np.int64(values[i]))
        x1, pos = _put(x1, t, nb, np.uint64(e), x_max, rcp, rshift, bias, cmpl, out, pos)
        if pos < 0:
            return -1
        t, nb, e = token(np.int64(values[i - 1]))
        x0, pos = _put(x0, t, nb, np.uint64(e), x_max, rcp, rshift, bias, cmpl, out, pos)
        if pos < 0:
            return -1
        i -= 2
    for x in (x1, x0):  # written backwards: the stream starts with x0, then x1
        for b in range(3, -1, -1):
            pos -= 1
            out[pos] = np.uint8((x >> np.uint64(8 * b)) & np.uint64(0xFF))
    return pos


@numba.njit(cache=True, nogil=True, inline="always")
def _decode_value(x: Any, pos: int, buf: np.ndarray, slot: np.ndarray, slot_freq: np.ndarray,
                  slot_off: np.ndarray) -> tuple[Any, Any, int]:  # pragma: no cover
    """One value from state ``x``: (value, new state, new position; -1 if the bytes ran out)."""
    n = buf.size
    s = x & (PROB_SCALE - 1)
    t = slot[s]
    x = slot_freq[s] * (x >> PROB_BITS) + slot_off[s]
    while x < RANS_L:
        if pos >= n:
            return 0, x, -1
        x = (x << 8) | buf[pos]
        pos += 1
    u = np.int64(t)
    if t >= DIRECT:
        k = (t - DIRECT) // 2 + 5
        nb = k - 1
        u = (np.int64(1) << k) | (np.int64((t - DIRECT) & 1) << nb)
        shift = 0
        while shift < nb:
            kk = 8 if nb - shift > 8 else nb - shift
            u |= (x & ((1 << kk) - 1)) << shift
            x >>= kk
            while x < RANS_L:
                if pos >= n:
                    return 0, x, -1
                x = (x << 8) | buf[pos]
                pos += 1
            shift += 8
    return ((u >> 1) if (u & 1) == 0 else -((u + 1) >> 1)), x, pos


@numba.njit(cache=True, nogil=True)
def _decode(buf: np.ndarray, start: int, freq: np.ndarray, cum: np.ndarray, slot: np.ndarray,
            out: np.ndarray) -> int:  # pragma: no cover
    """Fill ``out``; returns 0, or -1 if the bytes ran out, -2 if the state does not end where the
    encoder began, -3 if bytes are left over."""
    n = buf.size
    if start + 8 > n:
        return -1
    x0 = (np.int64(buf[start]) | (np.int64(buf[start + 1]) << 8) | (np.int64(buf[start + 2]) << 16)
          | (np.int64(buf[start + 3]) << 24))
    x1 = (np.int64(buf[start + 4]) | (np.int64(buf[start + 5]) << 8) | (np.int64(buf[start + 6]) << 16)
          | (np.int64(buf[start + 7]) << 24))
    pos = start + 8
    slot_freq = np.empty(PROB_SCALE, np.int64)  # per slot: its token's frequency, and the slot less
    slot_off = np.empty(PROB_SCALE, np.int64)  # the token's cumulative start: one lookup a value
    for j in range(PROB_SCALE):
        slot_freq[j] = freq[slot[j]]
        slot_off[j] = j - cum[slot[j]]
    i = 0
    count = out.size
    while i + 1 < count:  # two independent states: the CPU overlaps their dependency chains
        v0, x0, pos = _decode_value(x0, pos, buf, slot, slot_freq, slot_off)
        if pos < 0:
            return -1
        v1, x1, pos = _decode_value(x1, pos, buf, slot, slot_freq, slot_off)
        if pos < 0:
            return -1
        out[i] = v0
        out[i + 1] = v1
        i += 2
    if i < count:
        v0, x0, pos = _decode_value(x0, pos, buf, slot, slot_freq, slot_off)
        if pos < 0:
            return -1
        out[i] = v0
    if x0 != RANS_L or x1 != RANS_L:
        return -2
    if pos != n:
        return -3
    return 0


def _normalise(counts: np.ndarray) -> np.ndarray:
    """Token counts scaled to sum to ``PROB_SCALE``, every token seen keeping at least 1."""
    total = int(counts.sum())
    freq = np.where(counts > 0, np.maximum(1, np.rint(counts * (PROB_SCALE / total))), 0).astype(np.int64)
    while (diff := PROB_SCALE - int(freq.sum())) != 0:
        if diff > 0:
            freq[int(np.argmax(freq))] += diff
        else:  # take from the largest frequencies that can spare it
            order = np.argsort(-freq, kind="stable")
            for t in order:
                if diff == 0:
                    break
                take = min(-diff, int(freq[t]) - 1)
                freq[t] -= take
                diff += take
    return freq


def _varints(values: np.ndarray) -> bytes:
    out = bytearray()
    for v in values.tolist():
        while v >= 0x80:
            out.append((v & 0x7F) | 0x80)
            v >>= 7
        out.append(v)
    return bytes(out)


def encode(values: np.ndarray) -> bytes:
    """One stream of integer values (any integer dtype, each within int32)."""
    vals = np.ascontiguousarray(values).ravel()
    if vals.size == 0:
        return b""
    n = vals.size
    counts = np.zeros(MAX_TOKENS, np.int64)
    extra_bits = _counts(vals, counts)
    freq = _normalise(counts[:int(np.flatnonzero(counts)[-1]) + 1])
    cum = np.zeros(freq.size, np.int64)
    np.cumsum(freq[:-1], out=cum[1:])
    # a token costs at most 12 bits plus a byte of renormalisation slack, then the extra bits
    out = np.empty(3 * n + extra_bits // 8 + 72, np.uint8)
    start = _encode(vals, freq, cum, out)
    if start < 0:
        raise RuntimeError("rans: the output buffer was too small (a bug)")
    return bytes([freq.size]) + _varints(freq) + out[start:].tobytes()


def decode(buf: bytes | memoryview, count: int) -> np.ndarray:
    """``count`` int32 values from one stream, or a ``RansError`` saying what is wrong."""
    data = np.frombuffer(buf, np.uint8)
    if count == 0:
        if data.size:
            raise RansError(f"an empty stream holds {data.size} bytes")
        return np.empty(0, np.int32)
    if data.size < 1 or not 1 <= int(data[0]) <= MAX_TOKENS:
        raise RansError(f"a table of {int(data[0]) if data.size else 0} tokens (1..{MAX_TOKENS} expected)")
    t_count, pos = int(data[0]), 1
    freq = np.zeros(t_count, np.int64)
    for t in range(t_count):
        v = shift = 0
        while True:
            if pos >= data.size or shift > 14:
                raise RansError("the frequency table is cut short or malformed")
            b = int(data[pos])
            pos += 1
            v |= (b & 0x7F) << shift
            shift += 7
            if b < 0x80:
                break
        freq[t] = v
    if int(freq.sum()) != PROB_SCALE:
        raise RansError(f"the frequencies sum to {int(freq.sum())}, not {PROB_SCALE}")
    cum = np.zeros(t_count, np.int64)
    np.cumsum(freq[:-1], out=cum[1:])
    slot = np.repeat(np.arange(t_count, dtype=np.uint8), freq)
    out = np.empty(count, np.int32)
    status = _decode(data, pos, freq, cum, slot, out)
    if status:
        raise RansError({-1: "the stream ends before its values do",
                         -2: "the stream does not end in the state it began with: damaged",
                         -3: "bytes are left after the stream's values"}[status])
    return out
