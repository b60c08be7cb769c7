"""Truncated, bit-flipped and foreign files: a clean, named error every time, never a crash."""

from __future__ import annotations

import json

from tests.conftest import run_cli

SAMPLE_FILES = ["dji/DJI_H20T.jpg", "dji/M2EA_DJI_0001_R.JPG", "dji/M30T_DJI_0001_R.JPG", "dji/M30T_DJI_0003_R.JPG",
                "dji/M4T_DJI_0003_R.JPG", "flir/FLIR_E40.jpg", "flir/FLIR_T640.jpg", "flir/DJI_XT2.jpg",
                "flir/frame_000000.fff", "flir/example_radiometric.tiff"]


def _import_peak_rss_mb(args: list[str]) -> float:
    """Peak RSS of one ``thermcap import`` process (a fresh parent, so the children's maximum is its)."""
    import subprocess
    import sys

    code = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
    out = subprocess.run([sys.executable, "-c", code, sys.executable, "-m", "thermcap", "import", *args],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return int(out.stdout.strip()) / 1024


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


def test_a_long_seq_imports_in_bounded_memory(samples, tmp_path):
    """Ten times the frames must not mean ten times the memory: frames are decoded one at a time
    and nothing of a recorded frame is kept (300 frames are 200 MB of pixels)."""
    one = (samples / "flir" / "frame_000000.fff").read_bytes()
    (tmp_path / "short.seq").write_bytes(one * 30)
    (tmp_path / "long.seq").write_bytes(one * 300)
    short = _import_peak_rss_mb([str(tmp_path / "short.seq"), "--root", str(tmp_path / "a"), "--no-analysis"])
    long = _import_peak_rss_mb([str(tmp_path / "long.seq"), "--root", str(tmp_path / "b"), "--no-analysis"])
    assert long - short < 60, (short, long)


