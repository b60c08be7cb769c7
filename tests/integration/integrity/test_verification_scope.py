"""Defect 5: verification checked pixels only. A flipped bit renamed the sidecar channel; the
archive 'verified', wrote empty sidecars and deleted the source."""

from __future__ import annotations

import json
import zipfile

import pytest

from tests.conftest import run_cli
from thermcap.archive.archiver import archive_session, verify_format_dir
from thermcap.archive.formats import get_format
from thermcap.archive.manifest import FrameProof, bytes_digest, frame_proof, load_manifest
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource


def _session(tmp_path, n=60):
    Recorder(SimSource(width=64, height=48, frames=n, paced=False, start_time_ns=1_800_000_000_000_000_000),
             tmp_path, session_id="s", analysis=False).run()
    return tmp_path / "sessions" / "s"


@pytest.mark.parametrize("which", ["first", "last"])
def test_a_renamed_sidecar_channel_is_refused_and_the_source_kept(tmp_path, which):
    session = _session(tmp_path)
    seg = session / "0000.mcap"
    data = bytearray(seg.read_bytes())
    needle = b"/thermal/metadata"
    at = data.find(needle) if which == "first" else data.rfind(needle)
    assert at > 0
    data[at + 4] ^= 0x08  # 'e' -> 'm': /thmrmal/metadata
    seg.write_bytes(bytes(data))
    r = run_cli("archive", str(session), "--formats", "png16", "--delete-source")
    assert r.returncode == 1
    assert "0000.mcap" in r.stderr
    assert seg.exists()
    assert not (session / "archive" / "png16").exists()


def test_manifest_holds_a_sidecar_hash_and_time_for_every_frame(tmp_path):
    session = _session(tmp_path, 30)
    archive_session(session, ["png16", "tiff-lzw", "hdf5"])
    m = load_manifest(session)
    assert len(m["frames"]["sidecar_blake3"]) == 30
    assert len(m["frames"]["timestamps_ns"]) == 30
    assert all(len(h) == 64 for h in m["frames"]["sidecar_blake3"])
    for fid in ("png16", "tiff-lzw", "hdf5"):
        assert "sidecars and times" in m["formats"][fid]["verification"]


def test_round_trip_compares_sidecars_and_times(tmp_path):
    """An archive whose pixels are right but whose sidecar or time is not must fail verification."""
    session = _session(tmp_path, 10)
    archive_session(session, ["png16"])
    m = load_manifest(session)
    files = m["formats"]["png16"]["files"]
    fmt = get_format(m["formats"]["png16"]["config"])
    adir = session / "archive" / "png16"
    proof = frame_proof(m["frames"])
    problems, _ = verify_format_dir(fmt, adir, files, proof, where="png16", times=m["frames"]["timestamps_ns"])
    assert problems == []
    bad_sidecars = list(proof.sidecars)
    bad_sidecars[3] = bytes_digest(b"{}", proof.name)
    problems, _ = verify_format_dir(fmt, adir, files, FrameProof(proof.name, proof.pixels, bad_sidecars),
                                    where="png16", times=m["frames"]["timestamps_ns"])
    assert any("frame 3" in p and "sidecar" in p for p in problems)
    bad_times = list(m["frames"]["timestamps_ns"])
    bad_times[5] += 1
    problems, _ = verify_format_dir(fmt, adir, files, proof, where="png16", times=bad_times)
    assert any("frame 5" in p and "time" in p for p in problems)


def test_archived_sidecars_are_the_recorded_bytes(tmp_path):
    session = _session(tmp_path, 5)
    archive_session(session, ["png16"])
    with zipfile.ZipFile(session / "archive" / "png16" / "0000.zip") as zf:
        sidecars = [zf.read(n) for n in zf.namelist() if n.endswith(".json")]
    assert len(sidecars) == 5
    assert all(json.loads(s)["capture"]["frame_index"] == i for i, s in enumerate(sidecars))
