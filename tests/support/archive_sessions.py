"""A recorded session (48 frames, several segments) and its archive in every format, shared by
the archive tests of each tier."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.segments import SegmentPolicy

W, H = 160, 120
ALL = ["png16", "tiff-lzw", "hdf5", "jxl", "htj2k", "jpegls"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("rec")
    Recorder(SimSource(width=W, height=H, frames=48, paced=False, seed=4, start_time_ns=1_800_000_000_000_000_000),
             root, session_id="s", policy=SegmentPolicy(max_duration_s=0.2)).run()
    return root / "sessions" / "s"


@pytest.fixture
def session(recorded, tmp_path) -> Path:
    d = tmp_path / "s"
    shutil.copytree(recorded, d)
    return d


@pytest.fixture(scope="module")
def archived(recorded, tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("arch") / "s"
    shutil.copytree(recorded, d)
    archive_session(d, ALL)
    return d


def flip_in_image_entry(path: Path) -> None:
    """Flip one bit inside the first PNG entry of a png16 ZIP: the ZIP stays readable, the frame
    does not decode to its counts (damage verification must find)."""
    import zipfile

    with zipfile.ZipFile(path) as zf:
        info = next(i for i in zf.infolist() if i.filename.endswith(".png"))
    data = bytearray(path.read_bytes())
    data[info.header_offset + 30 + len(info.filename) + 40] ^= 0x20
    path.write_bytes(bytes(data))
