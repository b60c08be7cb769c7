"""After ``thermcap radiometry --set``, every temperature product says which model version it
holds, or gives the new version's numbers. Before, the Zarr store's ``.zmetadata`` stayed byte for
byte the same (same ETag), ``to_xarray()`` over HTTP named the recorded model while its data was
version 1, and the HDF5 archive's CF packing decoded the recorded model saying nothing of it."""

from __future__ import annotations

import json

import h5py
import httpx
import numpy as np
import pytest
import xarray as xr

import thermcap
from tests.conftest import ApiServer
from tests.support.api_data import make_root
from thermcap.recorder.radiometry import model_from_dict
from thermcap.recorder.radiometry.params import add_version
from thermcap.recorder.storage.reader import read_session_meta

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_root(tmp_path_factory.mktemp("versions"))


def test_every_product_names_the_version_it_holds(root):
    session = root / "sessions" / "s-archived"
    server = ApiServer(root)
    try:
        zmeta = f"{server.url}/api/v1/sessions/s-archived/zarr/.zmetadata"
        zjson = f"{server.url}/api/v1/sessions/s-archived/zarr/zarr.json"  # format 3's, the same store
        before, before3 = httpx.get(zmeta, timeout=60), httpx.get(zjson, timeout=60)
        assert before.status_code == 200 and before3.status_code == 200
        base = model_from_dict(read_session_meta(session)["radiometric_model"])
        add_version(session, base, {}, who="test", why="a new calibration",  # measured again 1 °C warmer
                    measured=model_from_dict({**base.to_dict(), "offset_c": -39.0}))
        after = httpx.get(zmeta, timeout=60)
        assert after.content != before.content and after.headers["etag"] != before.headers["etag"]
        attrs = after.json()["metadata"][".zattrs"]
        assert [v["version"] for v in json.loads(attrs["radiometric_model_versions"])] == [1]
        assert "latest version covering each frame" in attrs["model_version"]
        assert after.json()["metadata"]["temperature/.zattrs"]["model_version"] == attrs["model_version"]
        after3 = httpx.get(zjson, timeout=60).json()
        assert after3["attributes"] == attrs and after3 != before3.json()
        assert after3["consolidated_metadata"]["metadata"]["temperature"]["attributes"]["model_version"] == \
            attrs["model_version"]

        remote = thermcap.open(f"{server.url}/api/v1/sessions/s-archived").to_xarray()
        assert [v["version"] for v in json.loads(remote.attrs["radiometric_model_versions"])] == [1]
        local = thermcap.open(session).to_xarray()
        assert [v["version"] for v in json.loads(local.attrs["radiometric_model_versions"])] == [1]
        assert local.temperature.attrs["model_version"] == remote.temperature.attrs["model_version"]
        np.testing.assert_array_equal(local.temperature.isel(time=2).values, remote.temperature.isel(time=2).values)
        pinned = thermcap.open(session).to_xarray(model_version=0)
        assert pinned.temperature.attrs["model_version"] == "0"
        assert not np.array_equal(pinned.temperature.isel(time=2).values, local.temperature.isel(time=2).values,
                                  equal_nan=True)

        r = httpx.get(f"{server.url}/api/v1/sessions/s-archived/frames/2", params={"format": "celsius-tiff"},
                      timeout=60)
        assert r.status_code == 200 and r.headers["x-model-version"] == "1"
    finally:
        server.stop()

    # the HDF5 archive was written before the version: it says it holds the model recorded
    (h5,) = (session / "archive" / "hdf5").glob("*.h5")
    with h5py.File(h5, "r") as f:
        said = f["frames"].attrs["model_version"]
        said = said.decode() if isinstance(said, bytes) else str(said)
        assert said.startswith("0") and "thermcap.open" in said
    ds = xr.open_dataset(h5, engine="h5netcdf", decode_cf=False)
    assert str(ds.frames.attrs["model_version"]).startswith("0")
