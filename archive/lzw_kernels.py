"""The compiled loops of ``archive.lzw`` (numba, no GIL), in a module of their own so numba's
on-disk cache finds them (a closure's functions are compiled again in every process) and so
``import archive.lzw`` does not pay for importing numba."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["encode_strips"]


@njit(nogil=True, cache=True)
def put(out, pos, acc, held):
    held -= 32
    v = acc >> np.uint64(held)
    out[pos] = np.uint8((v >> np.uint64(24)) & np.uint64(255))
    out[pos + 1] = np.uint8((v >> np.uint64(16)) & np.uint64(255))
    out[pos + 2] = np.uint8((v >> np.uint64(8)) & np.uint64(255))
    out[pos + 3] = np.uint8(v & np.uint64(255))
    return pos + 4, held


@njit(nogil=True, cache=True)
def strip(src, out, pos, table, used):
    acc = np.uint64(256)  # Clear opens every strip
    held = 9
    nbits = 9
    free = 258
    maxcode = 511
    nused = 0
    n = src.shape[0]
    if n > 0:
        ent = np.uint64(src[0])
        for i in range(1, n):
            c = np.uint64(src[i])
            idx = (c << np.uint64(12)) | ent  # by byte first: see archive.lzw
            nxt = table[idx]
            if nxt != 0:
                ent = np.uint64(nxt)
                continue
            acc = (acc << np.uint64(nbits)) | ent
            held += nbits
            if held >= 32:
                pos, held = put(out, pos, acc, held)
            table[idx] = np.uint16(free)
            used[nused] = idx
            nused += 1
            free += 1
            if free == 4094:  # the table is full: Clear, and start again at 9 bits
                acc = (acc << np.uint64(nbits)) | np.uint64(256)
                held += nbits
                if held >= 32:
                    pos, held = put(out, pos, acc, held)
                for j in range(nused):
                    table[used[j]] = 0
                nused = 0
                nbits = 9
                free = 258
                maxcode = 511
            elif free > maxcode:
                nbits += 1
                maxcode = (1 << nbits) - 1
            ent = c
        acc = (acc << np.uint64(nbits)) | ent
        held += nbits
        if held >= 32:
            pos, held = put(out, pos, acc, held)
        free += 1  # as libtiff's LZWPostEncode: the last code's entry counts before End
        if free == 4094:
            acc = (acc << np.uint64(nbits)) | np.uint64(256)
            held += nbits
            if held >= 32:
                pos, held = put(out, pos, acc, held)
            nbits = 9
        elif free > maxcode:
            nbits += 1
    for j in range(nused):
        table[used[j]] = 0
    acc = (acc << np.uint64(nbits)) | np.uint64(257)
    held += nbits
    while held >= 8:
        held -= 8
        out[pos] = np.uint8((acc >> np.uint64(held)) & np.uint64(255))
        pos += 1
    if held > 0:
        out[pos] = np.uint8((acc << np.uint64(8 - held)) & np.uint64(255))
        pos += 1
    return pos


@njit(nogil=True, cache=True)
def encode_strips(src, size, out, ends, table, used):
    pos = 0
    k = 0
    for start in range(0, max(src.shape[0], 1), max(size, 1)):
        pos = strip(src[start:start + size], out, pos, table, used)
        ends[k] = pos
        k += 1
    return k
