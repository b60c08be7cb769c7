"""Truncated, bit-flipped and foreign files: a clean, named error every time, never a crash."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from recorder.importers import ImportError_, read_file
from tests.conftest import run_cli

SAMPLE_FILES = ["dji/DJI_H20T.jpg", "dji/M2EA_DJI_0001_R.JPG", "dji/M30T_DJI_0001_R.JPG", "dji/M30T_DJI_0003_R.JPG",
                "dji/M4T_DJI_0003_R.JPG", "flir/FLIR_E40.jpg", "flir/FLIR_T640.jpg", "flir/DJI_XT2.jpg",
                "flir/frame_000000.fff", "flir/example_radiometric.tiff"]


def _try(path):
    try:
        return read_file(path)
    except ImportError_ as exc:
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
    with pytest.raises(ImportError_, match="no thermal data"):
        read_file(jpg)
    with pytest.raises(ImportError_, match="a PNG image"):
        read_file(png)
    src = next((samples / "terraref").glob("*_ir.bin"))
    short = tmp_path / (src.name)
    short.write_bytes(src.read_bytes()[:-2])
    (tmp_path / src.name.replace("_ir.bin", "_metadata.json")).write_bytes(
        src.with_name(src.name.replace("_ir.bin", "_metadata.json")).read_bytes())
    with pytest.raises(ImportError_, match="614400 bytes, this one is 614398"):
        read_file(short)


def test_icd_raw_needs_the_right_size_and_a_sidecar(tmp_path):
    from tests.recorder.test_data_standard import ICD_EXAMPLE

    raw = tmp_path / "thermal_20260111T153045Z_BOSON640_N40_P60.raw"
    raw.write_bytes(np.arange(640 * 512, dtype="<u2").tobytes())
    with pytest.raises(ImportError_, match="sidecar"):
        read_file(raw)
    raw.with_suffix(".json").write_text(json.dumps(ICD_EXAMPLE))
    (f,) = read_file(raw)
    assert f.pixels.shape == (512, 640)
    assert f.model.scale_c_per_count == 0.036
    assert f.sensor_id == "BOSON640"
    raw.write_bytes(b"\x00" * 1000)
    with pytest.raises(ImportError_, match="1000 bytes, but the sidecar's 640x512 Gray16 frame needs 655360"):
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


def test_import_cli_keeps_going_and_reports(samples, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "cut.jpg").write_bytes((samples / "flir" / "FLIR_E40.jpg").read_bytes()[:5000])
    r = run_cli("import", str(samples / "flir"), str(bad), "--root", str(tmp_path / "root"), "--json")
    assert r.returncode == 1
    out = json.loads(r.stdout)
    assert [f["path"] for f in out["failed"]] == [str(bad / "cut.jpg")]
    assert len(out["files"]) == 5
    assert all(s["ok"] for s in out["sessions"])
    assert not list((tmp_path / "root").rglob("*.active"))


def test_a_seq_cut_part_way_keeps_its_complete_images_and_reports_the_cut_one(samples, tmp_path):
    """A SEQ that ends inside an image (a copy cut short, a camera that lost power): every
    complete image is imported, the cut one is reported by its byte count, the exit status is 1."""
    one = (samples / "flir" / "frame_000000.fff").read_bytes()
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "cut.seq").write_bytes(one * 3 + one[: len(one) // 2])
    (folder / "good.seq").write_bytes(one * 40)
    root = tmp_path / "root"
    r = run_cli("import", str(folder), "--root", str(root), "--json", "--no-analysis")
    assert r.returncode == 1
    out = json.loads(r.stdout)
    assert out["failed"] == []
    assert [f["path"] for f in out["truncated"]] == [str(folder / "cut.seq")]
    assert out["truncated"][0]["kept_images"] == 3
    assert out["truncated"][0]["got_bytes"] == len(one) // 2
    assert "is cut" in out["truncated"][0]["error"]
    assert len(out["files"]) == 43
    (s,) = out["sessions"]
    assert s["frames_written"] == 43


def _import_peak_rss_mb(args: list[str]) -> float:
    """Peak RSS of one ``thermcap import`` process (a fresh parent, so the children's maximum is its)."""
    import subprocess
    import sys

    code = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
    out = subprocess.run([sys.executable, "-c", code, sys.executable, "-m", "recorder", "import", *args],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return int(out.stdout.strip()) / 1024


def test_a_long_seq_imports_in_bounded_memory(samples, tmp_path):
    """Ten times the frames must not mean ten times the memory: frames are decoded one at a time
    and nothing of a recorded frame is kept (300 frames are 200 MB of pixels)."""
    one = (samples / "flir" / "frame_000000.fff").read_bytes()
    (tmp_path / "short.seq").write_bytes(one * 30)
    (tmp_path / "long.seq").write_bytes(one * 300)
    short = _import_peak_rss_mb([str(tmp_path / "short.seq"), "--root", str(tmp_path / "a"), "--no-analysis"])
    long = _import_peak_rss_mb([str(tmp_path / "long.seq"), "--root", str(tmp_path / "b"), "--no-analysis"])
    assert long - short < 60, (short, long)
