"""Issue 36: a FLIR SEQ/CSQ image whose directory promises a few bytes more than the file holds,
but whose image is complete, is a complete frame (kept, the short trailer noted); only an image
whose pixels are cut is truncated. Built from the real Duo Pro R FFF: two images back to back,
the second laid out as CSQ writers do (its raw record last)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from thermcap.recorder.exceptions import TruncatedImageError
from thermcap.recorder.importers.flir import _byteorder, iter_fff_file


def _dir(fff: bytes):
    order = _byteorder("x", fff)
    dir_off, count = struct.unpack(order + "II", fff[0x18:0x20])
    return order, dir_off, [list(struct.unpack(order + "HHIIII", fff[dir_off + 32 * i:dir_off + 32 * i + 20]))
                            for i in range(count)]


def _raw_last(fff: bytes, promise_more: int) -> bytes:
    """The same image with its raw record moved to the end, its length promising more bytes."""
    order, dir_off, entries = _dir(fff)
    raw = next(e for e in entries if e[0] == 1)
    others = [e for e in entries if e[0] not in (0, 1)]
    head = bytearray(fff[: min(e[4] for e in entries if e[0])])
    body = bytearray()
    pos = len(head)
    for e in others:
        body += fff[e[4]:e[4] + e[5]]
        e[4] = pos
        pos += e[5]
    raw_bytes = fff[raw[4]:raw[4] + raw[5]]
    raw[4], raw[5] = pos, raw[5] + promise_more
    for i, e in enumerate([raw, *others]):
        at = dir_off + 32 * i
        head[at:at + 20] = struct.pack(order + "HHIIII", *e)
    for i in range(len([raw, *others]), len(entries)):
        head[dir_off + 32 * i:dir_off + 32 * i + 32] = bytes(32)
    return bytes(head + body + raw_bytes)


@pytest.fixture
def fff(samples):
    return (samples / "flir" / "frame_000000.fff").read_bytes()


def test_an_image_short_of_its_promised_trailer_is_kept(fff):
    seq = fff + _raw_last(fff, promise_more=8)
    frames = list(iter_fff_file("x.seq", seq))
    assert len(frames) == 2
    assert np.array_equal(frames[0].pixels, frames[1].pixels)
    assert "promises 8 bytes more" in frames[1].vendor_metadata["short_trailer"]
    assert "short_trailer" not in frames[0].vendor_metadata


def test_a_cut_trailing_record_is_left_out_and_named(fff):
    seq = fff + fff[:-10]  # the GPS record, last in this layout, loses 10 bytes
    frames = list(iter_fff_file("x.seq", seq))
    assert len(frames) == 2 and np.array_equal(frames[0].pixels, frames[1].pixels)
    assert "0x2B" in frames[1].vendor_metadata["short_trailer"]


def test_an_image_whose_pixels_are_cut_is_truncated(fff):
    seq = fff + _raw_last(fff, promise_more=0)[:-1000]
    got = []
    with pytest.raises(TruncatedImageError) as exc:
        for f in iter_fff_file("x.seq", seq):
            got.append(f)
    assert len(got) == 1 and exc.value.image == 1
