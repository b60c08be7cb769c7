"""tiff-lzw's reader: tags from tifffile, pixels from libtiff in batches on two threads.

Every page must come back with its own counts, sidecar and time, across batch boundaries, in
files whose pages differ in shape, and a damaged file must fail naming it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import tifffile

from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.formats import tiff_lzw
from thermcap.archive.formats.tiff_lzw import LOG_TIME_TAG, TiffLzw, write_page


def _write(path: Path, frames: list[np.ndarray], bigtiff: bool = False) -> list[tuple[bytes, int]]:
    tags = []
    with tifffile.TiffWriter(path, byteorder="<", bigtiff=bigtiff) as w:
        for i, px in enumerate(frames):
            sidecar, t = f'{{"capture":{{"frame_index":{i}}}}}', 1_700_000_000_000_000_000 + i * 16_666_667
            write_page(w, px, 64, description=sidecar, metadata=None, software="thermcap",
                       extratags=[(LOG_TIME_TAG, "s", 0, str(t), True)])
            tags.append((sidecar.encode(), t))
    return tags


def _frames(n: int, shapes: list[tuple[int, int]]) -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    return [rng.integers(0, 1 << 14, shapes[i % len(shapes)], dtype=np.uint16) for i in range(n)]


@pytest.mark.parametrize("bigtiff", [False, True], ids=["classic", "BigTIFF"])  # a segment over 3.5 GB is BigTIFF
@pytest.mark.parametrize("shapes", [[(48, 64)], [(48, 64), (32, 96)]], ids=["one shape", "two shapes"])
def test_every_page_comes_back_across_batches(tmp_path, monkeypatch, shapes, bigtiff):
    monkeypatch.setattr(tiff_lzw, "PAGES_PER_CALL", 4)  # 11 pages: two full batches and a short one
    frames = _frames(11, shapes)
    tags = _write(tmp_path / "0000.tif", frames, bigtiff)
    got = list(TiffLzw().read(tmp_path, ["0000.tif"]))
    assert len(got) == len(frames)
    for k, (frame, want, (sidecar, t)) in enumerate(zip(got, frames, tags, strict=True)):
        assert frame.pixels.dtype == np.uint16 and frame.pixels.shape == want.shape, k
        assert np.array_equal(frame.pixels, want), k
        assert (frame.sidecar, frame.log_time) == (sidecar, t), k


def test_pixels_are_decoded_from_the_file(tmp_path, monkeypatch):
    """A changed byte inside page 6's strip reaches the pixels (or fails the read): nothing is
    taken from tifffile's view of another page or from a neighbour in the batch."""
    monkeypatch.setattr(tiff_lzw, "PAGES_PER_CALL", 4)
    frames = _frames(9, [(48, 64)])
    path = tmp_path / "0000.tif"
    _write(path, frames)
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[6]
        at = page.dataoffsets[0] + page.databytecounts[0] // 2
    data = bytearray(path.read_bytes())
    data[at] ^= 0x5A
    path.write_bytes(bytes(data))
    try:
        got = list(TiffLzw().read(tmp_path, ["0000.tif"]))
    except ArchiveError as exc:
        assert "0000.tif" in str(exc)
        return
    assert not np.array_equal(got[6].pixels, frames[6])
    assert all(np.array_equal(got[k].pixels, frames[k]) for k in range(9) if k != 6)


def test_a_truncated_file_fails_naming_it(tmp_path):
    path = tmp_path / "0000.tif"
    _write(path, _frames(5, [(48, 64)]))
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(ArchiveError, match=r"0000\.tif"):
        list(TiffLzw().read(tmp_path, ["0000.tif"]))


def test_an_empty_file_fails_naming_it(tmp_path):
    (tmp_path / "0000.tif").write_bytes(b"")
    with pytest.raises(ArchiveError, match=r"0000\.tif"):
        list(TiffLzw().read(tmp_path, ["0000.tif"]))


def test_big_pages_are_decoded_fewer_a_call(tmp_path, monkeypatch):
    """However large the sensor, a call holds at most BYTES_PER_CALL of decoded pages (at least
    one page): here three 48x64 pages a call, and every page still comes back as written."""
    seen: list[int] = []
    decode = tiff_lzw.imagecodecs.tiff_decode

    def counting(view, index):
        seen.append(index.stop - index.start if isinstance(index, slice) else 1)
        return decode(view, index=index)

    monkeypatch.setattr(tiff_lzw, "BYTES_PER_CALL", 3 * 48 * 64 * 2 + 5)
    monkeypatch.setattr(tiff_lzw.imagecodecs, "tiff_decode", counting)
    frames = _frames(10, [(48, 64)])
    _write(tmp_path / "0000.tif", frames)
    got = list(TiffLzw().read(tmp_path, ["0000.tif"]))
    assert seen == [3, 3, 3, 1]
    assert all(np.array_equal(g.pixels, f) for g, f in zip(got, frames, strict=True))


_CUT_WHILE_READING = """
import os, sys
from pathlib import Path
import numpy as np
import imagecodecs
from thermcap.archive.exceptions import ArchiveError
from thermcap.archive.formats import tiff_lzw
from thermcap.archive.formats.tiff_lzw import TiffLzw

folder, cut = Path(sys.argv[1]), int(sys.argv[2])
path = folder / "0000.tif"
decode = imagecodecs.tiff_decode
calls = []

class CutAfterTags:
    # the file is cut inside the second batch's strips once tifffile has read that batch's
    # tags, before libtiff decodes it: as a bad sector or another process would cut it
    def __getattr__(self, name):
        return getattr(imagecodecs, name)

    def tiff_decode(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            os.truncate(path, cut)
        return decode(*args, **kwargs)

tiff_lzw.imagecodecs = CutAfterTags()
tiff_lzw.PAGES_PER_CALL = 4
try:
    n = sum(1 for _ in TiffLzw().read(folder, ["0000.tif"], workers=1))
    print("read", n)
except ArchiveError as exc:
    print("ArchiveError", exc)
"""


def test_a_file_cut_while_it_is_read_fails_naming_it_and_never_kills_the_process(tmp_path):
    """libtiff decodes from the file's bytes as reads brought them, never from a mapping of the
    file: a mapped page the disk cannot give back (a bad sector, which scrub is there to find) or
    that is cut off meanwhile raises SIGBUS, and the whole process dies instead of reporting a
    damaged copy."""
    import subprocess
    import sys

    _write(tmp_path / "0000.tif", _frames(24, [(256, 320)]))
    with tifffile.TiffFile(tmp_path / "0000.tif") as tif:
        cut = tif.pages[5].dataoffsets[0]  # page 5: inside the second batch of four
    run = subprocess.run([sys.executable, "-c", _CUT_WHILE_READING, str(tmp_path), str(cut)], capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, f"the reader died (signal {-run.returncode}): {run.stderr[-2000:]}"
    assert run.stdout.startswith("ArchiveError") and "0000.tif" in run.stdout, run.stdout
