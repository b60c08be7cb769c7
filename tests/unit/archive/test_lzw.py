"""archive.lzw writes TIFF LZW that every reader decodes: the bytes libtiff itself writes."""

from __future__ import annotations

import io

import imagecodecs
import numpy as np
import pytest
import tifffile

from thermcap.archive.formats.tiff_lzw import encode_page, write_page
from thermcap.archive.lzw import lzw_encode, lzw_encode_strips


def _cases() -> list[bytes]:
    rng = np.random.default_rng(1)
    cases = [b"", b"a", b"ab", b"aaa", bytes(100_000), bytes(range(256)) * 400,
             rng.integers(0, 256, 200_000, dtype=np.uint8).tobytes(),  # clears at 4094 many times
             rng.integers(0, 4, 300_000, dtype=np.uint8).tobytes()]
    # every length around the code-width steps (511, 1023, 2047) and the Clear at 4094
    cases += [rng.integers(0, 256, n, dtype=np.uint8).tobytes() for n in (253, 254, 255, 256, 257, 765, 766,
                                                                           767, 1790, 1791, 1792, 3836, 3837,
                                                                           3838, 3839, 3840)]
    cases += [rng.integers(0, 3, n, dtype=np.uint8).tobytes() for n in range(0, 2000, 13)]
    return cases


@pytest.mark.parametrize("data", _cases(), ids=lambda d: f"{len(d)}B")
def test_imagecodecs_decodes_every_stream(data: bytes) -> None:
    assert imagecodecs.lzw_decode(lzw_encode(data)) == data


def test_strips_are_independent_streams_of_the_given_size() -> None:
    data = np.random.default_rng(2).integers(0, 5, 100_003, dtype=np.uint8).tobytes()
    parts = lzw_encode_strips(data, 777)
    assert len(parts) == -(-len(data) // 777)
    assert [imagecodecs.lzw_decode(p) for p in parts] == [data[i:i + 777] for i in range(0, len(data), 777)]
    assert parts[3] == lzw_encode(data[3 * 777:4 * 777])  # no state leaks from one strip to the next
    with pytest.raises(ValueError, match="strip_bytes"):
        lzw_encode_strips(data, 0)


def _pillow_libtiff():
    pil = pytest.importorskip("PIL")
    from PIL import Image, TiffImagePlugin, features

    if not features.check("libtiff"):
        pytest.skip("this Pillow is built without libtiff")
    return pil, Image, TiffImagePlugin


@pytest.mark.parametrize("kind", ["smooth", "noise", "low-noise"])
def test_strips_are_the_bytes_libtiff_writes(kind: str) -> None:
    """libtiff (through Pillow) writes an LZW TIFF; each of its strips, encoded here from the
    same rows, is byte for byte the same stream."""
    _, Image, TiffImagePlugin = _pillow_libtiff()
    rng = np.random.default_rng(0)
    frame = {"smooth": (np.add.outer(np.arange(200), np.arange(300)) // 3),
             "noise": rng.integers(0, 16384, (200, 300)),
             "low-noise": 1000 + rng.integers(0, 4, (200, 300))}[kind].astype("<u2")
    buf = io.BytesIO()
    old = TiffImagePlugin.WRITE_LIBTIFF
    TiffImagePlugin.WRITE_LIBTIFF = True
    try:
        Image.frombytes("I;16", (frame.shape[1], frame.shape[0]), frame.tobytes()).save(
            buf, format="TIFF", compression="tiff_lzw")
    finally:
        TiffImagePlugin.WRITE_LIBTIFF = old
    buf.seek(0)
    with tifffile.TiffFile(buf) as tif:
        page = tif.pages[0]
        assert page.compression == 5
        for k, (offset, count) in enumerate(zip(page.dataoffsets, page.databytecounts, strict=True)):
            buf.seek(offset)
            rows = frame[k * page.rowsperstrip:(k + 1) * page.rowsperstrip]
            assert lzw_encode(rows.tobytes()) == buf.read(count), f"strip {k}"


def test_a_page_libtiff_and_tifffile_read_back_exactly() -> None:
    """A page written as the archive writes it (predictor 2, 64-row strips, a short last strip)
    reads back bit-exact in tifffile and in libtiff."""
    _, Image, _ = _pillow_libtiff()
    frame = np.random.default_rng(3).integers(0, 1 << 14, (150, 96)).astype("<u2")
    buf = io.BytesIO()
    with tifffile.TiffWriter(buf, byteorder="<") as writer:
        writer.write(iter(encode_page(frame, 64)), shape=frame.shape, dtype="<u2", compression="lzw",
                     predictor=True, photometric="minisblack", rowsperstrip=64)
    buf.seek(0)
    with tifffile.TiffFile(buf) as tif:
        assert (tif.pages[0].predictor, len(tif.pages[0].dataoffsets)) == (2, 3)
        assert np.array_equal(tif.pages[0].asarray(), frame)
    buf.seek(0)
    assert np.array_equal(np.array(Image.open(buf)), frame)
    with pytest.raises(ValueError, match="little-endian uint16"):
        encode_page(frame.astype(np.int32), 64)
    # a big-endian frame is the same counts (written little-endian); any other dtype is refused,
    # never cast (an int32 count above 65535 would wrap)
    buf = io.BytesIO()
    with tifffile.TiffWriter(buf, byteorder="<") as writer:
        write_page(writer, frame.astype(">u2"), 64)
        with pytest.raises(ValueError, match="little-endian uint16"):
            write_page(writer, frame.astype(np.int32) + 70_000, 64)
    buf.seek(0)
    with tifffile.TiffFile(buf) as tif:
        assert len(tif.pages) == 1 and np.array_equal(tif.pages[0].asarray(), frame)


def test_a_second_process_loads_the_compiled_loops_from_numba_s_cache() -> None:
    """Compiled as closures, the loops were compiled again in every process: 1.1 s holding the
    GIL in each archive run. At module level numba's cache serves them from the second run on."""
    import subprocess
    import sys

    probe = ("import numpy as np; from archive.lzw import lzw_encode, lzw_encode_strips; "
             "lzw_encode(b'abcabc'); lzw_encode_strips(np.zeros((4, 8), '<u2'), 16); "
             "from archive import lzw_kernels as k; "
             "print(sum(sum(f.stats.cache_misses.values()) for f in (k.encode_strips, k.strip, k.put)))")
    runs = [subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=300)
            for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), runs[-1].stderr[-2000:]
    assert runs[1].stdout.strip() == "0", f"compiled again: {runs[1].stdout!r}"


def test_threads_encoding_at_once_each_get_their_own_string_table() -> None:
    """Formats (and the Dask tasks of a segmented archive) encode on several threads at once;
    the kernel runs without the GIL on a per-thread table. A shared table would mix two strips'
    strings and give streams that decode to other bytes."""
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(5)
    pages = [rng.integers(0, 1 << 14, (256, 320)).astype("<u2") for _ in range(16)]
    alone = [encode_page(p, 64) for p in pages]
    with ThreadPoolExecutor(4) as pool:
        together = list(pool.map(lambda p: encode_page(p, 64), pages * 4))
    assert together == alone * 4
