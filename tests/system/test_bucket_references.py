"""Bucket reads without the server: `thermcap upload` writes a kerchunk reference file beside each
HDF5 archive, and stock xarray reads the frames' chunks straight from S3 (SeaweedFS), bit-exact."""

from __future__ import annotations

import json
import uuid

import numpy as np
import pytest

from tests.conftest import run_cli
from tests.support.api_data import make_root
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.system


def test_xarray_reads_an_uploaded_hdf5_archive_from_the_bucket(tmp_path, seaweedfs):
    import imagecodecs.numcodecs
    import xarray as xr

    root = make_root(tmp_path / "root")
    prefix = f"refs-{uuid.uuid4().hex[:12]}"  # the bucket is shared with other tests' sessions of this name
    env = {"THERMCAP_S3_BUCKET": seaweedfs["bucket"], "THERMCAP_S3_ENDPOINT": seaweedfs["endpoint"],
           "THERMCAP_S3_PREFIX": prefix,
           "AWS_ACCESS_KEY_ID": seaweedfs["AWS_ACCESS_KEY_ID"],
           "AWS_SECRET_ACCESS_KEY": seaweedfs["AWS_SECRET_ACCESS_KEY"]}
    r = run_cli("upload", "s-archived", "--root", str(root), "--json", env=env)
    assert r.returncode == 0, r.stderr
    manifest = json.loads((root / "sessions" / "s-archived" / "archive" / "manifest.json").read_text())
    (entry,) = manifest["upload"]["references"].values()
    refs_key = entry["references"]
    assert refs_key.endswith(".h5.refs.json")
    s3 = {"key": seaweedfs["AWS_ACCESS_KEY_ID"], "secret": seaweedfs["AWS_SECRET_ACCESS_KEY"],
          "client_kwargs": {"endpoint_url": seaweedfs["endpoint"]}}
    imagecodecs.numcodecs.register_codecs()  # the frames' SZIP chunks
    ds = xr.open_dataset("reference://", engine="zarr", backend_kwargs={
        "consolidated": False,
        "storage_options": {"fo": f"s3://{seaweedfs['bucket']}/{prefix}/{refs_key}", "target_options": s3,
                            "remote_protocol": "s3", "remote_options": {**s3, "asynchronous": True}}})
    frames = list(iter_session_frames(root / "sessions" / "s-archived"))
    assert ds.frames.dtype == np.uint16
    np.testing.assert_array_equal(ds.frames.values, np.stack([f.pixels for f in frames]))
    np.testing.assert_array_equal(ds.time.values.astype(np.int64), [f.log_time for f in frames])
    assert ds.attrs["session_id"] == "s-archived"
