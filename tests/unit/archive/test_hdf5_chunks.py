"""The HDF5 archive compresses its SZIP chunks itself (outside h5py's lock) and hands them to
HDF5 whole. That is only sound if the bytes are exactly what HDF5's own SZIP filter writes, so
any HDF5 reader (h5dump, netCDF-C, MATLAB) decodes them: checked byte for byte against the
filter, on several frame widths and contents, and read back through h5py."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from thermcap.archive.formats.hdf5 import _szip_encoder_available, szip_chunk
from thermcap.archive.manifest import FrameProof

pytestmark = pytest.mark.skipif(not _szip_encoder_available(), reason="this h5py build has no SZIP encoder")


@pytest.mark.parametrize("shape", [(512, 640), (256, 320), (120, 160), (768, 1024), (2, 4096)])
@pytest.mark.parametrize("content", ["noise14", "flat", "full16"])
def test_our_szip_chunks_are_the_bytes_hdf5s_filter_writes(tmp_path, shape, content):
    rng = np.random.default_rng(sum(shape))
    frame = {"noise14": rng.integers(0, 1 << 14, shape), "flat": np.full(shape, 7000),
             "full16": rng.integers(0, 1 << 16, shape)}[content].astype(np.uint16)
    with h5py.File(tmp_path / "t.h5", "w") as f:
        theirs = f.create_dataset("theirs", (2, *shape), "<u2", chunks=(1, *shape), compression="szip",
                                  compression_opts=("nn", 32))
        theirs[0] = frame
        ours = f.create_dataset("ours", (2, *shape), "<u2", chunks=(1, *shape), compression="szip",
                                compression_opts=("nn", 32))
        mask, chunk = szip_chunk(frame)
        ours.id.write_direct_chunk((0, 0, 0), chunk, filter_mask=mask)
    with h5py.File(tmp_path / "t.h5") as f:  # as the archiver does: verified once the file is closed
        # (filter mask, bytes): 1 and the raw frame where SZIP would not make it smaller
        assert f["ours"].id.read_direct_chunk((0, 0, 0)) == f["theirs"].id.read_direct_chunk((0, 0, 0))
        assert np.array_equal(f["ours"][0], frame)


@pytest.mark.parametrize("frames_per_call", [1, 3, 7, 40])
def test_reading_in_blocks_gives_every_frame_sidecar_and_time_in_order(tmp_path, monkeypatch, frames_per_call):
    """``Hdf5.read`` takes several frames a call; a count that is no multiple of the block, and
    a block larger than the file, still give each frame once, with its own sidecar and time."""
    from thermcap.archive.formats import ArchiveContext, get_format
    from thermcap.archive.formats import hdf5 as hdf5_format
    from thermcap.recorder.storage.reader import SessionFrame

    shape, n = (64, 96), 20
    monkeypatch.setattr(hdf5_format, "READ_BYTES", frames_per_call * shape[0] * shape[1] * 2)
    rng = np.random.default_rng(5)
    frames = [SessionFrame(i, "seg-0.mcap", 1_700_000_000_000_000_000 + i * 16_666_667,
                           rng.integers(0, 1 << 14, shape).astype(np.uint16), f'{{"i":{i},"t":"é"}}'.encode())
              for i in range(n)]
    fmt = get_format("hdf5")
    ctx = ArchiveContext(session_id="blocks", total_frames=n, frames_per_segment={"seg-0.mcap": n})
    records = fmt.write(iter(frames), tmp_path, ctx)
    back = list(fmt.read(tmp_path, [r.path for r in records]))
    assert len(back) == n
    for want, got in zip(frames, back, strict=True):
        assert np.array_equal(got.pixels, want.pixels)
        assert got.sidecar == want.sidecar
        assert got.log_time == want.log_time


def test_a_damaged_chunk_is_found_by_verification_and_a_reader_may_stop_early(tmp_path, monkeypatch):
    """Reading ahead on a thread changes nothing of what verification sees: a changed byte in
    one frame's chunk is that frame's problem, the frames around it are fine, and a caller
    that stops after one frame leaves no thread reading the closed file."""
    import hashlib

    from thermcap.archive.archiver import verify_format_dir
    from thermcap.archive.formats import ArchiveContext, get_format
    from thermcap.archive.formats import hdf5 as hdf5_format
    from thermcap.recorder.storage.reader import SessionFrame

    shape, n = (64, 96), 20
    monkeypatch.setattr(hdf5_format, "READ_BYTES", 3 * shape[0] * shape[1] * 2)
    rng = np.random.default_rng(6)
    frames = [SessionFrame(i, "seg-0.mcap", 1_700_000_000_000_000_000 + i, rng.integers(0, 1 << 14, shape)
                           .astype(np.uint16), b"{}") for i in range(n)]
    fmt = get_format("hdf5")
    records = fmt.write(iter(frames), tmp_path, ArchiveContext(session_id="d", total_frames=n,
                                                               frames_per_segment={"seg-0.mcap": n}))
    path = tmp_path / records[0].path
    with h5py.File(path) as f:
        info = f["frames"].id.get_chunk_info(11)
    data = bytearray(path.read_bytes())
    data[info.byte_offset + info.size // 2] ^= 0x40
    path.write_bytes(bytes(data))
    want = FrameProof("sha256", [hashlib.sha256(f.pixels.tobytes()).hexdigest() for f in frames], [])
    problems, _ = verify_format_dir(fmt, tmp_path, [{"path": records[0].path, "frames": n}], want, where="hdf5",
                                    times=[f.log_time for f in frames])
    assert problems and all("frame 11 " in p or "cannot decode after 11" in p for p in problems), problems
    reader = fmt.read(tmp_path, [records[0].path])
    assert np.array_equal(next(reader).pixels, frames[0].pixels)
    reader.close()  # the read-ahead is waited for before the file closes
