"""The real ``thermcap`` process: raw input, kill -9 and recover, disk full, info."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from tests.conftest import run_cli, wait_for
from thermcap.recorder.icd.topics import decode_image
from thermcap.recorder.storage.recover import recover_segment

W, H = 96, 80


def _frames_in(session: Path) -> list[np.ndarray]:
    out = []
    for seg in sorted(session.glob("*.mcap")):
        with open(seg, "rb") as f:
            for _, _, msg in make_reader(f).iter_messages(topics=["/thermal/image"]):
                out.append(decode_image(msg.data)[1].copy())
    return out


def _session(root: Path) -> Path:
    (s,) = list((root / "sessions").iterdir())
    return s


def test_raw_file_records_bit_exact(tmp_path):
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 65536, size=(7, H, W), dtype=np.uint16)  # all 16 bits, not just 14
    raw = tmp_path / "in.gray16"
    frames.astype("<u2").tofile(raw)
    r = run_cli("record", "--source", f"raw:{raw}", "--width", str(W), "--height", str(H), "--root",
                str(tmp_path / "d"),
                "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["frames_written"] == 7
    assert out["frames_dropped"] == 0
    got = _frames_in(_session(tmp_path / "d"))
    assert len(got) == 7
    assert all(np.array_equal(a, b) for a, b in zip(got, frames, strict=True))


def test_raw_stdin_with_truncated_last_frame_keeps_the_rest(tmp_path):
    rng = np.random.default_rng(1)
    frames = rng.integers(0, 16384, size=(5, H, W), dtype=np.uint16)
    payload = frames.astype("<u2").tobytes() + b"\x01" * 1001
    r = run_cli("record", "--source", "raw:-", "--width", str(W), "--height", str(H), "--root", str(tmp_path / "d"),
                input=payload)
    assert r.returncode != 0
    assert "frame 5 is truncated: got 1001 bytes, expected 15360" in r.stderr
    assert "<stdin>" in r.stderr
    session = _session(tmp_path / "d")
    got = _frames_in(session)
    assert len(got) == 5
    assert all(np.array_equal(a, b) for a, b in zip(got, frames, strict=True))
    assert not list(session.glob("*.active"))


def test_raw_source_missing_file_is_a_clear_error(tmp_path):
    r = run_cli("record", "--source", f"raw:{tmp_path / 'nope.raw'}", "--width", "4", "--height", "4",
                "--root", str(tmp_path / "d"))
    assert r.returncode == 1
    assert "nope.raw: no such file" in r.stderr


def test_unknown_source_is_a_usage_error(tmp_path):
    r = run_cli("record", "--source", "camera9", "--root", str(tmp_path))
    assert r.returncode == 1
    assert "unknown source 'camera9'" in r.stderr




def test_recorder_recovers_leftovers_when_it_starts(tmp_path):
    root = tmp_path / "d"
    proc = subprocess.Popen([sys.executable, "-m", "thermcap", "record", "--duration", "60", "--width", "160",
                             "--height", "128", "--root", str(root), "--session", "old"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    active = root / "sessions" / "old" / "0000.mcap.active"
    try:
        assert wait_for(lambda: active.exists() and active.stat().st_size > 100_000)
    finally:
        proc.kill()
        proc.wait()
    r = run_cli("record", "--duration", "0.2", "--width", "64", "--height", "64", "--root", str(root))
    assert r.returncode == 0, r.stderr
    assert f"recovered leftover segment {active}" in r.stdout
    assert (root / "sessions" / "old" / "0000.mcap").is_file()
    assert not active.exists()


@pytest.fixture
def small_disk(tmp_path):
    """A real 4 MiB filesystem (tmpfs) that fills up; needs root, as on CI."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(mnt)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here (needs root): {r.stderr.decode().strip()}")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_disk_full_stops_cleanly_and_keeps_closed_segments(small_disk):
    root = small_disk / "d"
    proc = run_cli("record", "--duration", "30", "--no-pace", "--width", "320", "--height", "256",
                   "--segment-duration", "0.25", "--root", str(root), "--session", "f")
    assert proc.returncode == 1
    assert "error:" in proc.stderr
    assert "No space left on device" in proc.stderr
    session = root / "sessions" / "f"
    closed = sorted(session.glob("*.mcap"))
    assert closed, "segments closed before the disk filled must survive"
    for seg in closed:
        with open(seg, "rb") as f:
            assert make_reader(f).get_summary().statistics.message_count > 0
    # With the disk full even the summary may not fit; the old one is still whole (atomic writes).
    meta = json.loads((session / "session.json").read_text())
    assert meta["status"] in ("failed", "recording")


def test_info_on_a_truncated_file_names_it(tmp_path):
    bad = tmp_path / "0000.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 40)
    r = run_cli("info", str(bad))
    assert r.returncode == 1
    assert str(bad) in r.stderr


def test_recover_refuses_a_non_mcap(tmp_path):
    junk = tmp_path / "0001.mcap.active"
    junk.write_bytes(b"hello world")
    r = run_cli("recover", str(junk))
    assert r.returncode == 1
    assert "not an MCAP file" in r.stderr
    assert junk.read_bytes() == b"hello world"


def test_recover_of_a_file_cut_anywhere_keeps_a_readable_prefix(tmp_path):
    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.capture.sources.sim import SimSource
    from thermcap.recorder.storage.segments import SegmentPolicy

    Recorder(SimSource(width=64, height=48, frames=40, paced=False), tmp_path, session_id="c",
             policy=SegmentPolicy(chunk_size=20_000)).run()
    whole = (tmp_path / "sessions" / "c" / "0000.mcap").read_bytes()
    counts = []
    for cut in (100, len(whole) // 3, len(whole) // 2, len(whole) - 30):
        src = tmp_path / f"cut{cut}.mcap.active"
        src.write_bytes(whole[:cut])
        res = recover_segment(src)
        with open(res.output, "rb") as f:
            assert make_reader(f).get_summary().statistics.message_count == res.messages
        counts.append(res.frames)
    assert counts == sorted(counts)
    assert counts[-1] == 40
