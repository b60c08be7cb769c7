"""``thermcap cut``: part of a session by time and topic, bit-exact, from the source or the archive."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from tests.conftest import run_cli
from thermcap.recorder.icd.topics import decode_image
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.integration


def _images(path):
    with open(path, "rb") as f:
        return [(m.log_time, decode_image(m.data)[1].copy())
                for _, c, m in make_reader(f).iter_messages(topics=["/thermal/image"])]


@pytest.fixture
def root(tmp_path):
    root = tmp_path / "root"
    assert run_cli("record", "--root", str(root), "--session", "s", "--duration", "1", "--width", "64",
                   "--height", "48").returncode == 0
    return root


@pytest.mark.parametrize("delete_source", [False, True], ids=["from-source", "from-archive"])
def test_a_cut_holds_exactly_the_frames_in_range(root, tmp_path, delete_source):
    frames = list(iter_session_frames(root / "sessions" / "s"))
    if delete_source:
        r = run_cli("archive", "s", "--root", str(root), "--formats", "png16", "--delete-source")
        assert r.returncode == 0, r.stderr
    t0 = frames[0].log_time
    out = tmp_path / "cut.mcap"
    r = run_cli("cut", "s", "--root", str(root), "--start", "0.25", "--end", "0.5", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    want = [f for f in frames if t0 + 250_000_000 <= f.log_time < t0 + 500_000_000]
    got = _images(out)
    assert [t for t, _ in got] == [f.log_time for f in want] and want
    for (_, px), f in zip(got, want, strict=True):
        assert np.array_equal(px, f.pixels)
    only = tmp_path / "meta.mcap"
    assert run_cli("cut", "s", "--root", str(root), "--topics", "/thermal/metadata", "--out", str(only)).returncode == 0
    assert _images(only) == []


def test_a_cut_never_overwrites_and_says_what_is_wrong(root, tmp_path):
    out = tmp_path / "cut.mcap"
    out.write_bytes(b"mine")
    r = run_cli("cut", "s", "--root", str(root), "--out", str(out))
    assert r.returncode == 1 and "exists" in r.stderr and out.read_bytes() == b"mine"
    r = run_cli("cut", "s", "--root", str(root), "--start", "yesterday", "--out", str(tmp_path / "x.mcap"))
    assert r.returncode == 1 and "--start" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("cut", "s", "--root", str(root), "--start", "2", "--end", "1", "--out", str(tmp_path / "y.mcap"))
    assert r.returncode == 1 and "after" in r.stderr
    assert not (tmp_path / "x.mcap").exists() and not (tmp_path / "y.mcap").exists()


@pytest.mark.parametrize(("args", "said"), [
    (["../../../etc"], "not a session"),
    (["s", "--topics", "/no/such"], "no topic /no/such"),
    (["s", "--start", "2099-01-01T00:00:00Z"], "no frame between"),
], ids=["not-a-session", "unknown-topic", "past-the-end"])
def test_a_cut_of_nothing_is_an_error_not_an_empty_file(root, tmp_path, args, said):
    """Issue 65 (17): these exited 0 with an MCAP holding nothing."""
    out = tmp_path / "c.mcap"
    r = run_cli("cut", *args, "--root", str(root), "--out", str(out))
    assert r.returncode == 1 and said in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not out.exists()


def test_a_cut_never_copies_a_damaged_chunk(tmp_path):
    """Issue 65, defect 4: a chunk whose bytes no longer match its CRC-32 was copied whole into
    the cut (exit 0), where the default reader returned a frame with wrong pixels. The chunk is
    checked as it is copied: the cut stops, names the damaged chunk, and leaves no file."""
    root = tmp_path / "root"
    assert run_cli("record", "--root", str(root), "--session", "d", "--duration", "1", "--width", "64",
                   "--height", "48").returncode == 0
    (segment,) = sorted((root / "sessions" / "d").glob("*.mcap"))
    with open(segment, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunk = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)[0]
    data = bytearray(segment.read_bytes())
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0x40  # inside its compressed records
    segment.write_bytes(bytes(data))
    out = tmp_path / "c.mcap"
    r = run_cli("cut", "d", "--root", str(root), "--out", str(out))
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert f"chunk at byte {chunk.chunk_start_offset}" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not out.exists() and not out.with_name("c.mcap.partial").exists()


@pytest.mark.parametrize("garbage", [b"\x89MCAP0\r\n" + bytes(range(256)) * 40, bytes(reversed(range(256))) * 40],
                         ids=["magic-then-garbage", "no-magic"])
def test_a_cut_of_a_garbage_segment_names_it(tmp_path, garbage):
    """Issue 65, defect 17: garbage MCAP files gave `cut` a Python traceback."""
    root = tmp_path / "root"
    assert run_cli("record", "--root", str(root), "--session", "g", "--duration", "0.5", "--width", "32",
                   "--height", "24").returncode == 0
    (segment,) = sorted((root / "sessions" / "g").glob("*.mcap"))
    segment.write_bytes(garbage)
    r = run_cli("cut", "g", "--root", str(root), "--out", str(tmp_path / "c.mcap"))
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "0000.mcap" in r.stderr and not (tmp_path / "c.mcap").exists()
