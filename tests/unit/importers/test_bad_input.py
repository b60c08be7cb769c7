"""Truncated, bit-flipped and foreign files: a clean, named error every time, never a crash."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from thermcap.recorder.importers import ImportFileError, read_file

SAMPLE_FILES = ["dji/DJI_H20T.jpg", "dji/M2EA_DJI_0001_R.JPG", "dji/M30T_DJI_0001_R.JPG", "dji/M30T_DJI_0003_R.JPG",
                "dji/M4T_DJI_0003_R.JPG", "flir/FLIR_E40.jpg", "flir/FLIR_T640.jpg", "flir/DJI_XT2.jpg",
                "flir/frame_000000.fff", "flir/example_radiometric.tiff"]


def _try(path):
    try:
        return read_file(path)
    except ImportFileError as exc:
        assert str(path) in str(exc)
        return None


@pytest.mark.parametrize("name", SAMPLE_FILES)
def test_truncated_and_bit_flipped_samples_fail_cleanly(samples, tmp_path, name):
    data = (samples / name).read_bytes()
    rng = np.random.default_rng(len(name))
    t0 = time.monotonic()
    for cut in (10, 100, len(data) // 7, len(data) // 2, len(data) - 3):
        p = tmp_path / ("cut_" + name.replace("/", "_"))
        p.write_bytes(data[:cut])
        _try(p)
    for _ in range(25):
        buf = bytearray(data)
        for pos in rng.integers(0, len(buf), size=4):
            buf[pos] ^= 1 << int(rng.integers(0, 8))
        p = tmp_path / ("flip_" + name.replace("/", "_"))
        p.write_bytes(bytes(buf))
        frames = _try(p)
        for f in frames or []:
            assert f.pixels.dtype == np.uint16
            assert f.pixels.ndim == 2
    assert time.monotonic() - t0 < 60, "a corrupt file must not hang the importer"


def test_plain_jpeg_png_and_wrong_sized_bin_are_named(tmp_path, samples):
    import imagecodecs

    jpg = tmp_path / "holiday.jpg"
    jpg.write_bytes(imagecodecs.jpeg8_encode(np.zeros((16, 16, 3), np.uint8)))
    png = tmp_path / "scan.png"
    png.write_bytes(imagecodecs.png_encode(np.zeros((8, 8), np.uint16)))
    with pytest.raises(ImportFileError, match="no thermal data"):
        read_file(jpg)
    with pytest.raises(ImportFileError, match="a PNG image"):
        read_file(png)
    src = next((samples / "terraref").glob("*_ir.bin"))
    short = tmp_path / (src.name)
    short.write_bytes(src.read_bytes()[:-2])
    (tmp_path / src.name.replace("_ir.bin", "_metadata.json")).write_bytes(
        src.with_name(src.name.replace("_ir.bin", "_metadata.json")).read_bytes())
    with pytest.raises(ImportFileError, match="614400 bytes, this one is 614398"):
        read_file(short)


def test_icd_raw_needs_the_right_size_and_a_sidecar(tmp_path):
    from tests.unit.recorder.test_data_standard import ICD_EXAMPLE

    raw = tmp_path / "thermal_20260111T153045Z_BOSON640_N40_P60.raw"
    raw.write_bytes(np.arange(640 * 512, dtype="<u2").tobytes())
    with pytest.raises(ImportFileError, match="sidecar"):
        read_file(raw)
    raw.with_suffix(".json").write_text(json.dumps(ICD_EXAMPLE))
    (f,) = read_file(raw)
    assert f.pixels.shape == (512, 640)
    assert f.model.scale_c_per_count == 0.036
    assert f.sensor_id == "BOSON640"
    raw.write_bytes(b"\x00" * 1000)
    with pytest.raises(ImportFileError, match="1000 bytes, but the sidecar's 640x512 Gray16 frame needs 655360"):
        read_file(raw)


def test_seq_walks_records_not_magic_strings(samples, tmp_path):
    """Three FFF frames back to back, one with 'FFF\\0' inside its pixels: three frames, no more."""
    one = (samples / "flir" / "frame_000000.fff").read_bytes()
    (orig,) = read_file(samples / "flir" / "frame_000000.fff")
    trap = bytearray(one)
    idx = trap.find(orig.pixels[100:101, :].astype("<u2").tobytes()[:8])
    assert idx > 0
    trap[idx:idx + 4] = b"FFF\x00"
    seq = tmp_path / "flight.seq"
    seq.write_bytes(one + bytes(trap) + one)
    frames = read_file(seq)
    assert len(frames) == 3
    assert all(f.format == "flir-seq" for f in frames)
    assert np.array_equal(frames[0].pixels, frames[2].pixels)
    assert not np.array_equal(frames[0].pixels, frames[1].pixels)  # the trap is data, not a header
