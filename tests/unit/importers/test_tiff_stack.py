"""A multi-page radiometric TIFF (a stack, as ResearchIR, flirpy or tifffile save a sequence) is
every page's frame, not its first page's alone: the importer once read page 0 and left the
rest out without a word. Pages that are not frames of the stack (a reduced-resolution preview,
a colour page, a page of another size) are left out by name, in the first frame's metadata."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile

from thermcap.recorder.importers import ImportFileError, iter_file, read_file


def _stack(n: int) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    return [rng.integers(0, 1 << 14, (48, 64), dtype=np.uint16) for _ in range(n)]


def test_every_page_of_a_stack_is_a_frame(tmp_path):
    frames = _stack(5)
    path = tmp_path / "stack.tif"
    tifffile.imwrite(path, np.stack(frames), photometric="minisblack")  # one series of 5 pages
    for got in (read_file(path), list(iter_file(path))):
        assert len(got) == 5
        assert [f.frame_index for f in got] == list(range(5))
        assert all(np.array_equal(f.pixels, want) for f, want in zip(got, frames, strict=True))
        assert "pages_left_out" not in got[0].vendor_metadata


def test_pages_that_are_not_frames_are_left_out_by_name(tmp_path):
    frames = _stack(3)
    path = tmp_path / "mixed.tif"
    with tifffile.TiffWriter(path) as w:
        w.write(frames[0])
        w.write(frames[0][::4, ::4], subfiletype=1)  # a reduced-resolution preview
        w.write(np.zeros((48, 64, 3), np.uint8), photometric="rgb")  # the visual camera's page
        w.write(frames[1])
        w.write(np.zeros((10, 10), np.uint16))  # another size
        w.write(frames[2])
    got = read_file(path)
    assert len(got) == 3 and all(np.array_equal(f.pixels, want) for f, want in zip(got, frames, strict=True))
    left = got[0].vendor_metadata["pages_left_out"]
    assert [p["page"] for p in left] == [1, 2, 4]
    assert "reduced" in left[0]["why"] and "uint8" in left[1]["why"] and "10x10" in left[2]["why"]


def test_a_damaged_later_page_fails_the_file_naming_the_page(tmp_path):
    frames = _stack(3)
    path = tmp_path / "damaged.tif"
    tifffile.imwrite(path, np.stack(frames), photometric="minisblack", compression="zlib")
    with tifffile.TiffFile(path) as tif:
        at = tif.pages[2].dataoffsets[0]
    raw = bytearray(path.read_bytes())
    raw[at:at + 64] = bytes(64)
    path.write_bytes(bytes(raw))
    with pytest.raises(ImportFileError, match="page 2"):
        read_file(path)


def test_the_import_report_names_the_pages_left_out(tmp_path):
    from thermcap.recorder.importers.run import import_paths

    frames = _stack(2)
    path = tmp_path / "mixed.tif"
    with tifffile.TiffWriter(path) as w:
        w.write(frames[0])
        w.write(np.zeros((48, 64, 3), np.uint8), photometric="rgb")
        w.write(frames[1])
    report = import_paths([str(path)], str(tmp_path / "root"), session="s", analysis=False)
    assert [f["frame_index"] for f in report.files] == [0, 1]
    why = "3 sample(s) of uint8 a pixel, not Gray16"
    assert report.files[0]["notes"]["pages_left_out"] == [{"page": 1, "why": why}]
    assert "notes" not in report.files[1]
    assert report.sessions[0].frames_written == 2
