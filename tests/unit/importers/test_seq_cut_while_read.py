"""A SEQ/CSQ cut (or unreadable) while it is imported fails naming the file; it never kills the
process. The importer once mapped the file: a mapped page past the new end (a copy overwritten
in the inbox, an SD card pulled, a network share's read error) raised SIGBUS, and ``thermcap
import`` or the inbox's watcher died with no word of which file, where the frames already
written could not be reported."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

_CUT_WHILE_READING = """
import os, sys
from thermcap.recorder.importers import ImportFileError, iter_file
path, cut = sys.argv[1], int(sys.argv[2])
got = 0
try:
    for frame in iter_file(path):
        got += 1
        if got == 1:
            os.truncate(path, cut)  # another process cuts the file under the importer
except ImportFileError as exc:
    print(f"ImportFileError after {got} frames: {exc}")
else:
    print(f"no error after {got} frames")
"""


def test_a_seq_cut_while_it_is_imported_fails_naming_it(samples, tmp_path):
    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    seq = tmp_path / "flight.seq"
    seq.write_bytes(fff * 12)  # a 12-image SEQ, several MB: most of it beyond the cut
    cut = len(fff) * 2 + len(fff) // 2  # inside the third image
    run = subprocess.run([sys.executable, "-c", _CUT_WHILE_READING, str(seq), str(cut)], capture_output=True,
                         text=True, timeout=300)
    assert run.returncode == 0, f"the importer died (signal {-run.returncode}): {run.stderr[-2000:]}"
    assert run.stdout.startswith("ImportFileError after 2 frames") and "flight.seq" in run.stdout, run.stdout


def test_a_whole_seq_reads_every_image_from_the_file(samples, tmp_path):
    from thermcap.recorder.importers import iter_file, read_file

    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    seq = tmp_path / "flight.seq"
    seq.write_bytes(fff + b"\x00" * 3000 + fff * 2)  # padding between images is skipped to the next header
    streamed = list(iter_file(seq))
    whole = read_file(seq)
    assert len(streamed) == len(whole) == 3
    assert all(np.array_equal(a.pixels, b.pixels) for a, b in zip(streamed, whole, strict=True))


def test_a_header_across_two_windows_of_padding_is_found(monkeypatch):
    from thermcap.recorder.importers import flir

    monkeypatch.setattr(flir, "_GAP_WINDOW", 16)
    data = bytes(30) + b"AFF\x00" + bytes(5) + b"FFF\x00"  # the first header spans bytes 30-33: two windows
    assert [flir._next_header(data, s, len(data))[0] for s in (0, 17, 30, 31, 40)] == [30, 30, 30, 39, 43]
    assert flir._next_header(bytes(50), 0, 50) == (50, True)
    # whether the bytes skipped are all zero, taken on the same windows
    assert [flir._next_header(data, s, len(data))[1] for s in (0, 17, 30, 31, 40)] == [True, True, True, False,
                                                                                        False]
    odd = b"\x01" + bytes(40) + b"FFF\x00"  # a non-zero byte in the first window, the header in the third
    assert flir._next_header(odd, 0, len(odd)) == (41, False)
    assert flir._next_header(odd, 1, len(odd)) == (41, True)


def test_padding_before_an_aff_header_does_not_hide_the_images_after_it(samples, tmp_path):
    """The walker accepts 'AFF\\0' as a header as well as 'FFF\\0'; skipping padding, it looked for
    'FFF\\0' alone, so every image of an AFF sequence after a padded gap was silently dropped."""
    from thermcap.recorder.importers import iter_file, read_file

    aff = b"AFF\x00" + (samples / "flir" / "frame_000000.fff").read_bytes()[4:]
    seq = tmp_path / "aff.seq"
    seq.write_bytes(aff + bytes(3000) + aff + aff)
    assert len(read_file(seq)) == len(list(iter_file(seq))) == 3


def test_bytes_skipped_between_images_are_kept_with_the_next_image(samples, tmp_path):
    """Padding is skipped to the next header; what was skipped, and whether it was all zero (it
    may be an image whose header is damaged), is recorded with the image after it."""
    from thermcap.recorder.importers import iter_file

    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    seq = tmp_path / "gaps.seq"
    seq.write_bytes(fff + bytes(512) + fff + b"\x07" * 3000 + fff + fff)
    frames = list(iter_file(seq))
    assert len(frames) == 4
    assert [f.vendor_metadata.get("skipped_before") for f in frames] == [
        None, {"byte": len(fff), "bytes": 512, "all_zero": True},
        {"byte": 2 * len(fff) + 512, "bytes": 3000, "all_zero": False}, None]


def test_bytes_after_the_last_image_are_kept_with_it(samples, tmp_path):
    from thermcap.recorder.importers import iter_file

    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    for tail, all_zero in ((b"\x05" * 100, False), (bytes(10), True), (b"FFF\x00" + bytes(8), False)):
        seq = tmp_path / "tail.seq"
        seq.write_bytes(fff * 2 + tail)
        frames = list(iter_file(seq))
        assert len(frames) == 2 and "skipped_after" not in frames[0].vendor_metadata
        assert frames[1].vendor_metadata["skipped_after"] == {"byte": 2 * len(fff), "bytes": len(tail),
                                                              "all_zero": all_zero}
    seq.write_bytes(fff * 2)
    assert all("skipped_after" not in f.vendor_metadata for f in iter_file(seq))


def test_a_complete_first_image_is_kept_when_the_second_is_cut(samples, tmp_path):
    """The walker looked at the second image before handing on the first: a two-image SEQ whose
    second image was cut reported one image kept and recorded none."""
    from thermcap.recorder.importers import TruncatedImageError, iter_file
    from thermcap.recorder.importers.run import import_paths

    fff = (samples / "flir" / "frame_000000.fff").read_bytes()
    seq = tmp_path / "cut.seq"
    seq.write_bytes(fff + fff[:-3000])
    got = []
    with pytest.raises(TruncatedImageError):
        for f in iter_file(seq):
            got.append(f)
    assert len(got) == 1 and got[0].format == "flir-seq"
    report = import_paths([str(seq)], str(tmp_path / "root"), session="s", analysis=False)
    assert report.truncated[0]["kept_images"] == 1
    assert report.sessions[0].frames_written == 1
