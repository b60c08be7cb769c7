"""One convention for a session as an array: the kerchunk references beside an HDF5 archive open
as the served Zarr store and ``to_xarray()`` do: ``counts`` (time, y, x) with ``y`` the row, 0 at
the top, and ``axis`` on each coordinate. Before, the references gave ``frames`` with ``y``
running 119 ... 0, so ``sel(y=0)`` was the last row in one and the first in the other."""

from __future__ import annotations

import json
import shutil

import h5py
import imagecodecs.numcodecs
import numpy as np
import pytest
import xarray as xr

import thermcap
from tests.support.api_data import make_root
from thermcap.archive.hdf5_refs import hdf5_references

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_root(tmp_path_factory.mktemp("refs"))


def _open_refs(h5, tmp_path):
    refs = tmp_path / "refs.json"
    refs.write_text(json.dumps(hdf5_references(h5, str(h5))))
    imagecodecs.numcodecs.register_codecs()
    return xr.open_dataset("reference://", engine="zarr", backend_kwargs={
        "consolidated": False, "storage_options": {"fo": str(refs), "remote_protocol": "file"}})


@pytest.mark.parametrize("written", ["now", "before the convention"])
def test_references_open_as_the_session_does(root, tmp_path, written):
    (h5,) = (root / "sessions" / "s-archived" / "archive" / "hdf5").glob("*.h5")
    if written != "now":  # an archive of an earlier release: y stored counting from the bottom
        h5 = shutil.copy(h5, tmp_path / h5.name)
        with h5py.File(h5, "r+") as f:
            f["y"][...] = f["y"][...][::-1]
    ds = _open_refs(h5, tmp_path)
    local = thermcap.open(root / "sessions" / "s-archived").to_xarray()
    assert "frames" not in ds and ds.counts.dims == ("time", "y", "x") and ds.counts.dtype == np.uint16
    np.testing.assert_array_equal(ds.y.values, local.y.values)
    assert ds.y.attrs["axis"] == local.y.attrs["axis"] == "Y" and ds.time.attrs["axis"] == "T"
    np.testing.assert_array_equal(ds.counts.isel(time=5).sel(y=0).values, local.counts.isel(time=5).sel(y=0).values)
    np.testing.assert_array_equal(ds.counts.values, local.counts.values)
