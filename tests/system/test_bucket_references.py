"""Bucket reads without the server: `thermcap upload` writes a kerchunk reference file beside each
HDF5 archive, and stock xarray reads the frames' chunks straight from S3 (SeaweedFS), bit-exact."""

from __future__ import annotations

import json
import uuid

import numpy as np
import pytest

from tests.conftest import bucket_env, run_cli
from tests.support.api_data import make_root
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.system


def test_xarray_reads_an_uploaded_hdf5_archive_from_the_bucket(tmp_path, seaweedfs):
    import imagecodecs.numcodecs
    import obstore.fsspec
    import xarray as xr

    root = make_root(tmp_path / "root")
    prefix = f"refs-{uuid.uuid4().hex[:12]}"  # the bucket is shared with other tests' sessions of this name
    env = bucket_env(seaweedfs, prefix)
    r = run_cli("upload", "s-archived", "--root", str(root), "--json", env=env)
    assert r.returncode == 0, r.stderr
    manifest = json.loads((root / "sessions" / "s-archived" / "archive" / "manifest.json").read_text())
    (entry,) = manifest["upload"]["references"].values()
    refs_key = entry["references"]
    assert refs_key.endswith(".h5.refs.json")
    # s3:// through obstore's fsspec adapter: the archive's own S3 client, not a second one
    obstore.fsspec.register("s3", asynchronous=True)
    s3 = {"config": {"endpoint": seaweedfs["endpoint"], "access_key_id": seaweedfs["AWS_ACCESS_KEY_ID"],
                     "secret_access_key": seaweedfs["AWS_SECRET_ACCESS_KEY"], "region": "us-east-1"},
          "client_options": {"allow_http": True}}
    imagecodecs.numcodecs.register_codecs()  # the frames' SZIP chunks
    ds = xr.open_dataset("reference://", engine="zarr", backend_kwargs={
        "consolidated": False,
        "storage_options": {"fo": f"s3://{seaweedfs['bucket']}/{prefix}/{refs_key}", "target_options": s3,
                            "remote_protocol": "s3", "remote_options": {**s3, "asynchronous": True}}})
    frames = list(iter_session_frames(root / "sessions" / "s-archived"))
    assert ds.counts.dtype == np.uint16 and ds.counts.dims == ("time", "y", "x")  # as the served store names them
    np.testing.assert_array_equal(ds.counts.values, np.stack([f.pixels for f in frames]))
    np.testing.assert_array_equal(ds.time.values.astype(np.int64), [f.log_time for f in frames])
    assert ds.attrs["session_id"] == "s-archived"


def test_thermcap_open_reads_an_uploaded_session_from_the_bucket(tmp_path, seaweedfs, monkeypatch):
    """Issue 38: ``thermcap.open("s3://BUCKET/PREFIX/sessions/ID")``, no server: every frame
    bit-exact against the MCAP frames, each checked against the manifest; the sidecars, times,
    events and model versions the session holds; a damaged object is skipped for another copy."""
    import thermcap
    from thermcap.recorder.radiometry.base import model_from_dict
    from thermcap.recorder.radiometry.params import add_version
    from thermcap.recorder.radiometry.session import read_bad_pixel_map
    from thermcap.recorder.storage.reader import read_session_meta

    root = make_root(tmp_path / "root")
    session = root / "sessions" / "s-archived"
    prefix = f"open-{uuid.uuid4().hex[:12]}"
    env = bucket_env(seaweedfs, prefix)
    # a version the bucket must carry: the model measured again 1 °C warmer
    base = model_from_dict(read_session_meta(session)["radiometric_model"])
    add_version(session, base, {}, who="test", why="a new calibration",
                measured=model_from_dict({**base.to_dict(), "offset_c": -39.0}))
    r = run_cli("upload", "s-archived", "--root", str(root), "--json", env=env)
    assert r.returncode == 0, r.stderr
    for k, v in env.items():
        if k != "THERMCAP_S3_BUCKET":
            monkeypatch.setenv(k, v)
    url = f"s3://{seaweedfs['bucket']}/{prefix}/sessions/s-archived"
    s = thermcap.open(url)
    frames = list(iter_session_frames(session))
    assert len(s) == len(frames) and (s.width, s.height) == frames[0].pixels.shape[::-1]
    for f in frames:
        np.testing.assert_array_equal(s.counts(f.index), f.pixels)
    assert s.sidecar(3) == json.loads(frames[3].sidecar)
    np.testing.assert_array_equal(s.table.timestamp_ns, [f.log_time for f in frames])
    local = thermcap.open(session)
    assert s.events == local.events
    assert [v.version for v in s.model_versions] == [1]
    ds = s.to_xarray(chunk_frames=7)
    np.testing.assert_array_equal(ds.counts.values, np.stack([f.pixels for f in frames]))
    listed = read_bad_pixel_map(session)
    t = ds.temperature.isel(time=5).values
    assert listed is not None and np.isnan(t[listed]).all() and np.isfinite(t[~listed]).all()
    np.testing.assert_allclose(t[~listed], frames[5].pixels[~listed] * 0.036 - 39, atol=1e-4)
    t0 = s.to_xarray(model_version=0).temperature.isel(time=5).values
    np.testing.assert_allclose(t0[~listed], frames[5].pixels[~listed] * 0.036 - 40, atol=1e-4)
    # a damaged object: the png16 ZIP rots in the bucket; the frames come from another copy
    from thermcap.archive.blobs import open_store

    store = open_store(root, bucket=seaweedfs["bucket"], endpoint=seaweedfs["endpoint"], prefix=prefix)
    key = "sessions/s-archived/archive/png16/0000.zip"
    raw = bytearray(store.get_range(key, 0, store.head(key)["size"]))
    raw[len(raw) // 3] ^= 0x40
    store.put_bytes(key, bytes(raw))
    again = thermcap.open(url)
    for f in frames:
        np.testing.assert_array_equal(again.counts(f.index), f.pixels)
    with pytest.raises(FileNotFoundError, match="no session here"):
        thermcap.open(f"s3://{seaweedfs['bucket']}/{prefix}/sessions/nobody")
    with pytest.raises(ValueError, match="sessions/ID"):
        thermcap.open(f"s3://{seaweedfs['bucket']}/{prefix}/s-archived")
