"""Archive a real recorded session in every format, read it with stock libraries, break it."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import h5py
import imagecodecs
import numpy as np
import pytest
import tifffile

from archive.archiver import archive_session
from archive.codecs import Png16
from archive.exceptions import ArchiveError, VerificationError
from archive.formats import format_registry, register_format
from archive.formats.zipped import ZippedFrames
from archive.manifest import frame_sha256, load_manifest
from archive.verify import verify_session
from recorder.capture.recorder import Recorder
from recorder.capture.sources.sim import SimSource
from recorder.storage.reader import iter_session_frames
from recorder.storage.segments import SegmentPolicy
from tests.conftest import run_cli

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


def _source_frames(d):
    return [f.pixels.copy() for f in iter_session_frames(d)]


def test_manifest_records_every_format_verified(archived):
    m = load_manifest(archived)
    frames = _source_frames(archived)
    assert m["frames"]["sha256"] == [frame_sha256(f) for f in frames]
    for fid in ALL:
        e = m["formats"][fid]
        assert e["verified"] is True
        assert "bit-exact" in e["verification"]
        assert e["bytes"] == sum(f["bytes"] for f in e["files"])
        assert e["compression_ratio"] > 1.5
        assert e["encode_fps"] > 0
        assert e["decode_fps"] > 0
        assert "imagecodecs" in e["library_versions"]
        assert sum(e["frames_per_file"]) == 48
    assert m["formats"]["png16"]["objects"] == 4  # one ZIP per segment, 4 segments
    assert m["formats"]["hdf5"]["objects"] == 1


def test_png16_zip_is_stored_icd_pairs_readable_by_zipfile(archived):
    frames = _source_frames(archived)
    meta = [f.sidecar_dict() for f in iter_session_frames(archived)]
    zips = sorted((archived / "archive" / "png16").glob("*.zip"))
    assert [z.name for z in zips] == ["0000.zip", "0001.zip", "0002.zip", "0003.zip"]
    i = 0
    for z in zips:
        with zipfile.ZipFile(z) as zf:
            infos = zf.infolist()
            assert all(x.compress_type == zipfile.ZIP_STORED for x in infos)
            names = [x.filename for x in infos]
            assert names[0].startswith("thermal_")
            assert names[0].endswith("Z_SIM640_N40_P550.png")
            assert names[1] == names[0][:-4] + ".json"
            for png, js in zip(names[::2], names[1::2], strict=True):
                img = imagecodecs.png_decode(zf.read(png))
                assert img.dtype == np.uint16
                assert np.array_equal(img, frames[i])
                assert json.loads(zf.read(js)) == meta[i]
                i += 1
    assert i == 48


def test_png16_readable_by_pillow_when_installed(archived):
    PIL = pytest.importorskip("PIL.Image")
    z = next((archived / "archive" / "png16").glob("*.zip"))
    with zipfile.ZipFile(z) as zf:
        import io
        img = PIL.open(io.BytesIO(zf.read(zf.namelist()[0])))
        assert np.array_equal(np.asarray(img).astype(np.uint16), _source_frames(archived)[0])


def test_tiff_has_icd_tags_lzw_predictor_and_sidecars(archived):
    frames = _source_frames(archived)
    i = 0
    for t in sorted((archived / "archive" / "tiff-lzw").glob("*.tif")):
        with tifffile.TiffFile(t) as tif:
            assert tif.byteorder == "<"
            for page in tif.pages:
                tags = {tag.code: tag.value for tag in page.tags}
                assert tags[256] == W
                assert tags[257] == H
                assert tags[258] == 16
                assert tags[277] == 1
                assert tags[259] == 5
                assert tags[317] == 2  # LZW, horizontal predictor
                assert tags[262] == 1
                assert 273 in tags
                assert 278 in tags
                # 284 PlanarConfiguration and 339 SampleFormat: tifffile leaves them at the TIFF 6.0
                # defaults, which are the ICD's values (1 and 1).
                assert tags.get(284, 1) == 1
                assert tags.get(339, 1) == 1
                assert page.planarconfig == 1
                assert page.sampleformat == 1
                assert json.loads(page.description)["capture"]["frame_index"] == i
                assert np.array_equal(page.asarray(), frames[i])
                i += 1
    assert i == 48


def test_hdf5_layout(archived):
    frames = _source_frames(archived)
    (h5,) = list((archived / "archive" / "hdf5").glob("*.h5"))
    with h5py.File(h5, "r") as f:
        d = f["frames"]
        assert d.shape == (48, H, W)
        assert d.dtype == np.uint16
        assert d.chunks == (1, H, W)
        assert d.compression in ("szip", "gzip")
        assert np.array_equal(d[:], np.stack(frames))
        ts = f["timestamps_ns"][:]
        assert ts.dtype == np.int64
        assert np.all(np.diff(ts) > 0)
        meta = [json.loads(s) for s in f["metadata"].asstr()[:]]
        assert meta[5]["capture"]["frame_index"] == 5
        assert json.loads(f.attrs["radiometric_model"])["kind"] == "linear"
        assert json.loads(f.attrs["sensor"])["sensor_id"] == "SIM640"


@pytest.mark.parametrize("fid", ALL)
def test_verify_catches_one_flipped_byte(session, fid):
    archive_session(session, [fid])
    assert verify_session(session)[fid]["ok"]
    files = sorted((session / "archive" / fid).iterdir())
    target = files[len(files) // 2]
    data = bytearray(target.read_bytes())
    data[len(data) // 2] ^= 0x01
    target.write_bytes(bytes(data))
    report = verify_session(session)[fid]
    assert not report["ok"]
    assert any(target.name in p for p in report["problems"])
    r = run_cli("verify", str(session), "--json")
    assert r.returncode == 1


def test_verify_after_delete_source_uses_manifest_alone(session):
    archive_session(session, ["png16", "hdf5"], delete_source=True)
    assert not list(session.glob("*.mcap"))
    assert load_manifest(session)["source"]["deleted"] is True
    report = verify_session(session)
    assert all(r["ok"] for r in report.values())
    assert set(report) == {"png16", "hdf5", "extras"}
    assert report["png16"]["frames"] == report["hdf5"]["frames"] == 48


class _Broken(ZippedFrames):
    """A format whose writer alters one count of one frame: verification must catch it."""

    def __init__(self):
        super().__init__(Png16(), "broken-test")

    def write(self, frames, out_dir, ctx):
        def tamper(stream):
            for f in stream:
                if f.index == 7:
                    px = f.pixels.copy()
                    px[3, 3] ^= 1
                    f.pixels = px
                yield f
        return super().write(tamper(frames), out_dir, ctx)


def test_delete_source_refused_when_verification_fails(session):
    register_format("broken-test", _Broken)
    try:
        with pytest.raises(VerificationError, match="frame 7"):
            archive_session(session, ["png16", "broken-test"], delete_source=True)
    finally:
        format_registry.pop("broken-test")
    assert len(list(session.glob("*.mcap"))) == 4  # the source is untouched
    assert not (session / "archive" / "broken-test").exists()
    assert not list((session / "archive").glob("*.partial"))
    m = load_manifest(session)
    assert m["formats"]["png16"]["verified"]
    assert not m["formats"]["broken-test"]["verified"]


def test_rerun_skips_verified_formats(session):
    archive_session(session, ["png16"])
    before = (session / "archive" / "png16" / "0000.zip").stat().st_mtime_ns
    archive_session(session, ["png16", "tiff-lzw"])
    assert (session / "archive" / "png16" / "0000.zip").stat().st_mtime_ns == before
    assert (session / "archive" / "tiff-lzw").is_dir()


def test_killed_archive_leaves_no_half_archive_and_rerun_finishes(tmp_path):
    root = tmp_path / "d"
    Recorder(SimSource(width=320, height=256, frames=600, paced=False), root, session_id="k",
             policy=SegmentPolicy(max_duration_s=2)).run()
    session = root / "sessions" / "k"
    proc = subprocess.Popen([sys.executable, "-m", "recorder", "archive", str(session), "--formats", "png16,jxl"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not list((session / "archive").glob("*.partial/*.zip")):
        time.sleep(0.02)
    time.sleep(0.3)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    adir = session / "archive"
    for fid in ("png16", "jxl"):
        final = adir / fid
        if final.exists():  # finished before the kill: then it must be complete and in the manifest
            assert load_manifest(session)["formats"][fid]["verified"]
    assert list(adir.glob("*.partial")), "the kill should have caught a format half-written"
    r = run_cli("archive", str(session), "--formats", "png16,jxl")
    assert r.returncode == 0, r.stderr
    assert not list(adir.glob("*.partial"))
    assert all(v["ok"] for v in verify_session(session).values())
    assert len(list(session.glob("*.mcap"))) == 5


def test_archive_refuses_a_session_being_recorded(session):
    (session / "0009.mcap.active").write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(ArchiveError, match="unfinished segments"):
        archive_session(session, ["png16"])


def test_unknown_format_is_a_clear_cli_error(session):
    r = run_cli("archive", str(session), "--formats", "png16,gif")
    assert r.returncode != 0
    assert "unknown format(s) gif" in r.stderr


def test_audit_reports_costs_and_recommends_the_smallest_verified(archived, tmp_path):
    r = run_cli("audit", str(archived), "--json", "--project-cameras", "4", "--project-hours", "6")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    fmts = rep["formats"]
    smallest = min((k for k in fmts if k != "mcap"), key=lambda k: fmts[k]["bytes"])
    assert rep["recommended_format"] == smallest
    std = fmts["png16"]["cost"]["s3-standard"]
    assert std["storage_per_month"] == pytest.approx(fmts["png16"]["bytes"] / 1024**3 * 0.023, rel=1e-3)
    assert std["put_once"] == pytest.approx(4 / 1000 * 0.005)
    assert set(fmts["png16"]["cost"]) == {"s3-standard", "s3-standard-ia", "s3-glacier-ir", "s3-deep-archive", "r2",
                                          "b2"}
    assert rep["projection"]["cameras"] == 4
    prices = tmp_path / "p.json"
    prices.write_text(json.dumps({"s3-standard": {"storage": 1.0}}))
    rep2 = json.loads(run_cli("audit", str(archived), "--json", "--prices", str(prices)).stdout)
    assert rep2["formats"]["png16"]["cost"]["s3-standard"]["storage_per_month"] == pytest.approx(
        fmts["png16"]["bytes"] / 1024**3, rel=1e-3)
    md = run_cli("audit", str(archived), "--markdown").stdout
    assert "| png16 |" in md
    assert "recommended format" in md


@pytest.mark.parametrize("width,height", [(1280, 1024), (97, 61)])
def test_every_format_round_trips_large_and_odd_frames(tmp_path, width, height):
    Recorder(SimSource(width=width, height=height, frames=4, paced=False, seed=9), tmp_path, session_id="big",
             analysis=False).run()
    m = archive_session(tmp_path / "sessions" / "big", ALL)
    assert all(m["formats"][f]["verified"] for f in ALL)


def test_real_sample_frames_archive_bit_exact_in_every_format(samples, tmp_path):
    from recorder.importers.run import import_paths

    picks = [str(samples / "flir" / "FLIR_E40.jpg"), str(samples / "dji" / "DJI_H20T.jpg"),
             str(next((samples / "terraref").glob("*_ir.bin"))), str(samples / "flir" / "example_radiometric.tiff")]
    report = import_paths(picks, tmp_path, analysis=False)
    assert not report.failed
    assert len(report.sessions) == 4
    for res in report.sessions:
        m = archive_session(res.session_dir, ALL)
        assert all(m["formats"][f]["verified"] for f in ALL), res.session_id
        ref = {f["raw_sha256"] for f in report.files if f.get("session_id") == res.session_id}
        assert set(m["frames"]["sha256"]) == ref


def test_extras_keep_attachments_metadata_and_other_topics_past_delete_source(session):
    from mcap.reader import make_reader

    from archive.extras import summarize_mcap
    from recorder.storage.reader import session_segments

    before = summarize_mcap(session_segments(session))
    assert before["attachments"]
    assert "/recorder/stats" in before["topics"]
    archive_session(session, ["png16"], delete_source=True)
    extras = session / "archive" / "extras.mcap"
    entry = load_manifest(session)["extras"]
    assert entry["verified"]
    assert entry["attachments"] == before["attachments"]
    assert entry["topics"] == before["topics"]
    with open(extras, "rb") as f:
        reader = make_reader(f)
        assert "/thermal/image" not in {c.topic for c in reader.get_summary().channels.values()}
        names = [r.name for r in reader.iter_metadata()]
    from recorder.storage.segments import SEGMENT_STATS_METADATA, SESSION_METADATA

    assert names.count(SESSION_METADATA) == 4
    assert names.count(SEGMENT_STATS_METADATA) == 4  # each segment's own
    assert verify_session(session)["extras"]["ok"]
    data = bytearray(extras.read_bytes())  # damage it: verify names it
    data[len(data) // 2] ^= 0xFF
    extras.write_bytes(bytes(data))
    r = verify_session(session)["extras"]
    assert not r["ok"]
    assert "sha256 differs" in r["problems"][0]
