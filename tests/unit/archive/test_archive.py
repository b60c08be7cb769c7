"""Archive a real recorded session in every format, read it with stock libraries, break it."""

from __future__ import annotations

import contextlib
import json
import threading
import zipfile
from typing import ClassVar

import h5py
import imagecodecs
import numpy as np
import pytest
import tifffile

from tests.support.archive_sessions import ALL, H, W
from thermcap.archive.archiver import archive_session
from thermcap.archive.codecs import Png16
from thermcap.archive.exceptions import ArchiveError, VerificationError
from thermcap.archive.formats import format_registry, register_format
from thermcap.archive.formats.zipped import ZippedFrames
from thermcap.archive.manifest import frame_digest, load_manifest
from thermcap.archive.verify import verify_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.storage.reader import iter_session_frames


def _source_frames(d):
    return [f.pixels.copy() for f in iter_session_frames(d)]


def test_manifest_records_every_format_verified(archived):
    m = load_manifest(archived)
    frames = _source_frames(archived)
    assert m["frames"]["blake3"] == [frame_digest(f, "blake3") for f in frames]
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


def test_verify_after_delete_source_uses_manifest_alone(session):
    archive_session(session, ["png16", "hdf5"], delete_source=True)
    assert not list(session.glob("*.mcap"))
    assert load_manifest(session)["source"]["deleted"] is True
    report = verify_session(session)
    assert set(report) == {"png16", "hdf5", "extras"}
    assert all(r.ok for r in report.values())
    assert report["png16"].frames == 48
    assert report["hdf5"].frames == 48


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


def test_read_back_compares_by_the_digest_its_source_read_took(session):
    """The first archive compares each read-back frame by xxh3-128 taken on the same source read
    as the manifest's digests; a format added later, whose source may have rotted since, by the
    manifest's (BLAKE3). A one-count change is caught either way."""
    register_format("broken-test", _Broken)
    try:
        with pytest.raises(VerificationError, match="frame 7") as first:
            archive_session(session, ["png16", "broken-test"])
        assert "xxh3-128 differs" in str(first.value.problems)
        assert "xxh3-128 taken on the same read" in load_manifest(session)["formats"]["png16"]["verification"]
        with pytest.raises(VerificationError, match="frame 7") as later:
            archive_session(session, ["broken-test"])
        assert "blake3 differs" in str(later.value.problems)
        archive_session(session, ["tiff-lzw"])
        assert "by the manifest's blake3" in load_manifest(session)["formats"]["tiff-lzw"]["verification"]
    finally:
        format_registry.pop("broken-test")


def test_rerun_skips_verified_formats(session):
    archive_session(session, ["png16"])
    before = (session / "archive" / "png16" / "0000.zip").stat().st_mtime_ns
    archive_session(session, ["png16", "tiff-lzw"])
    assert (session / "archive" / "png16" / "0000.zip").stat().st_mtime_ns == before
    assert (session / "archive" / "tiff-lzw").is_dir()


def test_archive_refuses_a_session_being_recorded(session):
    (session / "0009.mcap.active").write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(ArchiveError, match="unfinished segments"):
        archive_session(session, ["png16"])


@pytest.mark.parametrize("width,height", [(1280, 1024), (97, 61)])
def test_every_format_round_trips_large_and_odd_frames(tmp_path, width, height):
    Recorder(SimSource(width=width, height=height, frames=4, paced=False, seed=9), tmp_path, session_id="big",
             analysis=False).run()
    m = archive_session(tmp_path / "sessions" / "big", ALL)
    assert all(m["formats"][f]["verified"] for f in ALL)


def test_real_sample_frames_archive_bit_exact_in_every_format(samples, tmp_path):
    from thermcap.recorder.importers.run import import_paths

    picks = [str(samples / "flir" / "FLIR_E40.jpg"), str(samples / "dji" / "DJI_H20T.jpg"),
             str(next((samples / "terraref").glob("*_ir.bin"))), str(samples / "flir" / "example_radiometric.tiff")]
    report = import_paths(picks, tmp_path, analysis=False)
    assert not report.failed
    assert len(report.sessions) == 4
    for res in report.sessions:
        m = archive_session(res.session_dir, ALL, digest="sha256")  # the importer's report names frames by sha256
        assert all(m["formats"][f]["verified"] for f in ALL), res.session_id
        ref = {f["raw_sha256"] for f in report.files if f.get("session_id") == res.session_id}
        assert set(m["frames"]["sha256"]) == ref


def test_extras_keep_attachments_metadata_and_other_topics_past_delete_source(session):
    from mcap.reader import make_reader

    from thermcap.archive.extras import summarize_mcap
    from thermcap.recorder.storage.reader import session_segments

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
    from thermcap.recorder.storage.segments import SEGMENT_STATS_METADATA, SESSION_METADATA

    assert names.count(SESSION_METADATA) == 4
    assert names.count(SEGMENT_STATS_METADATA) == 4  # each segment's own
    assert verify_session(session)["extras"].ok
    data = bytearray(extras.read_bytes())  # damage it: verify names it
    data[len(data) // 2] ^= 0xFF
    extras.write_bytes(bytes(data))
    r = verify_session(session)["extras"]
    assert not r.ok
    assert "blake3 differs" in r.problems[0]


class _Counting(ZippedFrames):
    """PNG16 that records the encoder threads the archiver gave it, and the reader threads its
    read-back got."""

    seen: ClassVar[list[int]] = []
    read_with: ClassVar[list[int]] = []

    def __init__(self):
        super().__init__(Png16(), "counting-test")

    def write(self, frames, out_dir, ctx):
        _Counting.seen.append(ctx.workers)
        return super().write(frames, out_dir, ctx)

    def read(self, out_dir, files, workers=2):
        _Counting.read_with.append(workers)
        return super().read(out_dir, files, workers)


@pytest.mark.parametrize("workers, formats, each", [(2, 3, 1), (2, 1, 2), (6, 3, 2), (1, 2, 1), (5, 2, 2)])
def test_encoder_threads_are_shared_among_the_formats_written_at_once(session, workers, formats, each):
    """Three formats with two threads each on two cores cost 4% more CPU than one each, for the
    same wall time: ``--workers`` is the threads in all, not per format. Each format reads its
    copy back on as many threads as it wrote it with (two reader threads each, three formats
    verifying on two cores, had cost 3% more CPU for the whole archive)."""
    ids = [f"counting-test-{k}" for k in range(formats)]
    for fid in ids:
        register_format(fid, _Counting)
    _Counting.seen, _Counting.read_with = [], []
    try:
        archive_session(session, ids, workers=workers)
    finally:
        for fid in ids:
            format_registry.pop(fid)
    assert _Counting.seen == [each] * formats
    assert _Counting.read_with and set(_Counting.read_with) == {each}  # a read a file


class _Overlapping(ZippedFrames):
    """PNG16 that counts how many of its kind are encoding at once. On its first frame each
    waits for another to arrive too: where two may work at once they meet there; where one may,
    the wait gives up and it goes on."""

    lock = threading.Lock()
    now = 0
    most = 0
    meet: ClassVar[threading.Barrier] = threading.Barrier(2, timeout=1.0)

    def __init__(self):
        super().__init__(Png16(), "overlap-test")

    def write(self, frames, out_dir, ctx):
        def counted(stream):
            for f in stream:
                with _Overlapping.lock:
                    _Overlapping.now += 1
                    _Overlapping.most = max(_Overlapping.most, _Overlapping.now)
                if f.index == 0:
                    with contextlib.suppress(threading.BrokenBarrierError):
                        _Overlapping.meet.wait()
                yield f
                with _Overlapping.lock:
                    _Overlapping.now -= 1
        return super().write(counted(frames), out_dir, ctx)


@pytest.mark.parametrize("workers, most", [(1, 1), (2, 2)])
def test_workers_bound_the_codecs_working_at_once(session, workers, most):
    """``--workers 1`` is one thread in all: two formats take turns, never encoding together."""
    ids = ["overlap-test-0", "overlap-test-1"]
    for fid in ids:
        register_format(fid, _Overlapping)
    _Overlapping.now, _Overlapping.most = 0, 0
    _Overlapping.meet = threading.Barrier(2, timeout=1.0)
    try:
        archive_session(session, ids, workers=workers)
    finally:
        for fid in ids:
            format_registry.pop(fid)
    assert _Overlapping.most == most


def test_encoder_threads_default_to_the_usable_cores(monkeypatch):
    from thermcap.archive import archiver

    monkeypatch.setattr(archiver, "usable_cores", lambda: 8)
    assert [archiver.encoder_threads(None, n) for n in (1, 2, 3, 8, 9)] == [8, 4, 2, 1, 1]
    assert archiver.encoder_threads(3, 0) == 3  # nothing to write at once: no division by zero
