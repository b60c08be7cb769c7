"""Every frame codec round-trips bit-exact, has a JSON config, and is registered."""

from __future__ import annotations

import json

import imagecodecs
import numpy as np
import pytest

from thermcap.archive import codecs as C
from thermcap.archive.codecs import FrameCodec, codec_registry, get_codec
from thermcap.archive.exceptions import UnknownCodecError
from thermcap.recorder.capture.sources.sim import SimSource

CODECS = [get_codec(cid) for cid in sorted(codec_registry)]


def _frames():
    rng = np.random.default_rng(0)
    yield "sim-640x512", next(iter(SimSource(paced=False, frames=1).frames())).pixels
    yield "sim-1280x1024", next(iter(SimSource(paced=False, frames=1, width=1280, height=1024).frames())).pixels
    yield "odd-160x120", next(iter(SimSource(paced=False, frames=1, width=160, height=120).frames())).pixels
    yield "odd-97x61-16bit", rng.integers(0, 65536, (61, 97), dtype=np.uint16)
    yield "extremes", np.array([[0, 65535, 1, 65534], [32768, 16383, 16384, 255]] * 8, dtype=np.uint16)


@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.codec_id)
@pytest.mark.parametrize("name,frame", list(_frames()), ids=lambda x: x if isinstance(x, str) else "")
def test_roundtrip_is_bit_exact(codec, name, frame):
    out = codec.decode(codec.encode(frame))
    assert out.dtype == np.uint16
    assert out.shape == frame.shape
    assert np.array_equal(out, frame)


@pytest.mark.parametrize("codec", CODECS, ids=lambda c: c.codec_id)
def test_config_roundtrips_through_json(codec):
    config = json.loads(json.dumps(codec.get_config()))
    assert config["id"] == codec.codec_id
    assert get_codec(config) == codec
    assert repr(codec).startswith(type(codec).__name__ + "(")


def test_every_codec_class_is_registered():
    subclasses = {cls for cls in vars(C).values() if isinstance(cls, type) and issubclass(cls, FrameCodec)
                  and cls is not FrameCodec}
    assert subclasses == set(codec_registry.values())


def test_unknown_codec_names_the_known_ones():
    with pytest.raises(UnknownCodecError, match=r"known: .*png16"):
        get_codec("gif")


def test_codecs_refuse_non_gray16():
    with pytest.raises(ValueError, match="uint16"):
        get_codec("png16").encode(np.zeros((4, 4), np.uint8))


def test_real_sample_frames_roundtrip(samples):
    bin_path = next((samples / "terraref").glob("*_ir.bin"))
    frames = [np.fromfile(bin_path, "<u2").reshape(480, 640)]
    tifffile = pytest.importorskip("tifffile")
    frames.append(tifffile.imread(samples / "flir" / "example_radiometric.tiff"))
    for frame in frames:
        for codec in CODECS:
            assert np.array_equal(codec.decode(codec.encode(frame)), frame), codec.codec_id




@pytest.mark.parametrize("name,frame", list(_frames()), ids=lambda x: x if isinstance(x, str) else "")
def test_the_up_png_reader_gives_libpngs_counts(name, frame):
    png = get_codec("png16").encode(frame)
    assert np.array_equal(C.decode_up_png(png), imagecodecs.png_decode(png))


@pytest.mark.parametrize("h", [1, 2, 15, 16, 17, 33])
def test_the_up_png_reader_at_every_block_remainder(h):
    frame = np.random.default_rng(h).integers(0, 65536, (h, 7), dtype=np.uint16)
    assert np.array_equal(C.decode_up_png(get_codec("png16").encode(frame)), frame)


def test_the_up_png_reader_declines_what_it_does_not_read():
    frame = next(iter(SimSource(paced=False, frames=1, width=160, height=120).frames())).pixels
    png = get_codec("png16").encode(frame)
    assert C.decode_up_png(imagecodecs.png_encode(frame, level=6)) is None  # libpng's own filters
    assert C.decode_up_png(imagecodecs.png_encode(frame.astype(np.uint8))) is None  # 8-bit
    assert C.decode_up_png(png[:60]) is None  # truncated IDAT
    assert C.decode_up_png(b"GIF89a" + png[6:]) is None
    broken = bytearray(png)
    broken[41 + 5] ^= 0xFF  # inside the deflate stream: an error or wrong counts, never a crash
    got = C.decode_up_png(bytes(broken))
    assert got is None or not np.array_equal(got, frame)
