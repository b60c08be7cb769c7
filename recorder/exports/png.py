"""PNG writing as thermcap does it everywhere: every row filtered "Up", one zlib stream from
libdeflate, text chunks right after the header.

Why not libpng: it tries filters row by row and compresses with zlib. On a 640x512 colour
preview that took 14 ms at level 1; the Up filter (one vectorised subtraction) and libdeflate
take 3.6 ms and the file is 15% smaller. Thermal pictures are smooth down the columns, so Up is
close to the best filter anyway (archive.codecs.Png16 measured the others on 16-bit frames).
Any PNG reader reads the result: libpng, Pillow, browsers.
"""

from __future__ import annotations

import struct
import zlib
from typing import Any, cast

import imagecodecs
import numpy as np

__all__ = ["encode_png", "png_chunk"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_chunk(kind: bytes, data: bytes) -> bytes:
    """A chunk with its CRC-32 (of the type and the data), by libdeflate's CRC-32 from the type's
    value on: 8x faster than zlib's on a 200 KB IDAT (0.0034 against 0.028 ms), without joining
    the type and the data first just to check them."""
    crc = imagecodecs.deflate_crc32(data, zlib.crc32(kind))
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def encode_png(pixels: np.ndarray, level: int = 4, text: dict[str, str] | None = None) -> bytes:
    """A PNG of ``pixels``: (H, W) uint8 or uint16 gray, or (H, W, 3) uint8 RGB, at libdeflate
    ``level``, with a ``tEXt`` chunk per item of ``text`` (Latin-1)."""
    if pixels.ndim == 2 and pixels.dtype in (np.uint8, np.uint16):
        h, w = pixels.shape
        depth, colour = 8 * pixels.dtype.itemsize, 0
        samples = pixels.astype(">u2").view(np.uint8) if depth == 16 else pixels
    elif pixels.ndim == 3 and pixels.shape[2] == 3 and pixels.dtype == np.uint8:
        h, w = pixels.shape[:2]
        depth, colour, samples = 8, 2, pixels
    else:
        raise ValueError(f"encode_png takes 2-D uint8/uint16 or (H, W, 3) uint8, got {pixels.dtype} {pixels.shape}")
    if not (h and w):
        raise ValueError(f"an image needs pixels, got {pixels.shape}")
    rows = np.empty((h, samples[0].size + 1), np.uint8)
    rows[:, 0] = 2  # filter type Up
    flat = samples.reshape(h, -1)
    rows[0, 1:] = flat[0]
    np.subtract(flat[1:], flat[:-1], out=rows[1:, 1:])  # modulo 256, as PNG defines it
    idat = cast(bytes, imagecodecs.deflate_encode(cast(Any, rows), level=level, raw=False))
    texts = b"".join(png_chunk(b"tEXt", k.encode("latin-1") + b"\x00" + v.encode("latin-1"))
                     for k, v in (text or {}).items())
    return (_SIGNATURE + png_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour, 0, 0, 0)) + texts
            + png_chunk(b"IDAT", idat) + png_chunk(b"IEND", b""))
