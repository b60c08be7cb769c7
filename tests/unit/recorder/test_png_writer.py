"""``recorder.exports.png`` writes the PNGs thermcap makes (previews, heatmaps, png16): libpng
and Pillow must read back every sample, the text chunks must be where readers find them."""

from __future__ import annotations

import io

import imagecodecs
import numpy as np
import pytest
from PIL import Image

from thermcap.recorder.exports.colorbar import png_text
from thermcap.recorder.exports.png import encode_png

RNG = np.random.default_rng(5)


@pytest.mark.parametrize("pixels", [
    RNG.integers(0, 256, (37, 53), dtype=np.uint8),
    RNG.integers(0, 65536, (37, 53), dtype=np.uint16),
    RNG.integers(0, 256, (37, 53, 3), dtype=np.uint8),
    np.full((1, 1), 7, np.uint16),
], ids=["gray8", "gray16", "rgb", "one pixel"])
@pytest.mark.parametrize("level", [1, 6])
def test_libpng_and_pillow_read_every_sample(pixels, level):
    png = encode_png(pixels, level, {"thermcap:units": "degC", "thermcap:range_min": "-1.5000"})
    assert np.array_equal(imagecodecs.png_decode(png), pixels)
    with Image.open(io.BytesIO(png)) as im:
        assert np.array_equal(np.asarray(im), pixels)
        assert im.text == {"thermcap:units": "degC", "thermcap:range_min": "-1.5000"}
    assert png_text(png) == {"thermcap:units": "degC", "thermcap:range_min": "-1.5000"}


@pytest.mark.parametrize("bad", [np.zeros((4, 4), np.float32), np.zeros((4, 4, 4), np.uint8),
                                 np.zeros((4, 4, 3), np.uint16), np.zeros((0, 4), np.uint8), np.zeros(4, np.uint8)])
def test_what_it_cannot_write_is_refused(bad):
    with pytest.raises(ValueError):
        encode_png(bad)


def test_every_chunk_carries_the_crc_of_its_type_and_data():
    """Each chunk's CRC-32 is PNG's (zlib's, over the type and the data), ancillary text chunks and
    the empty IEND included: readers that skip a bad ancillary chunk would not say so."""
    import struct
    import zlib

    png = encode_png(RNG.integers(0, 65536, (40, 30), dtype=np.uint16), 4, {"thermcap:units": "degC"})
    pos, kinds = 8, []
    while pos < len(png):
        (length,) = struct.unpack(">I", png[pos:pos + 4])
        kind, data = png[pos + 4:pos + 8], png[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", png[pos + 8 + length:pos + 12 + length])
        assert crc == zlib.crc32(kind + data), kind
        kinds.append(kind)
        pos += 12 + length
    assert kinds == [b"IHDR", b"tEXt", b"IDAT", b"IEND"]
