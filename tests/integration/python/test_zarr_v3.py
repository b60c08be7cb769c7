"""The Zarr endpoint in format 3, sharded over time, beside format 2 under one URL: zarr-python
(format 3 and format 2), tensorstore's ``zarr3`` driver and ``xr.open_zarr`` read the same
counts, bit-exact against the MCAP frames; a shard is served whole or by the byte ranges a
reader of one frame asks for, and only those frames are read."""

from __future__ import annotations

import struct

import google_crc32c
import httpx
import numpy as np
import pytest
import xarray as xr
import zarr

from tests.support.api_data import H, W, make_root, token_server
from thermcap.recorder.radiometry.session import SessionTemperatures
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.integration

TOKEN = "zarr-v3-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
SHARD_BYTES = 3 * W * H * 2 + 100  # three frames a shard: 60 frames are 20 shards


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_root(tmp_path_factory.mktemp("zroot"))


@pytest.fixture(scope="module")
def server(root, tmp_path_factory):
    s = token_server(root, tmp_path_factory.mktemp("tok"), TOKEN, THERMCAP_ZARR_SHARD_BYTES=str(SHARD_BYTES))
    yield s
    s.stop()


def _mcap(root, sid):
    frames = list(iter_session_frames(root / "sessions" / sid))
    return np.stack([f.pixels for f in frames]), np.array([f.log_time for f in frames], np.int64)


def _url(server, sid="s-archived"):
    return f"{server.url}/api/v1/sessions/{sid}/zarr"


@pytest.mark.parametrize("sid", ["s-archived", "s-mcap-only"])
def test_zarr_python_reads_format_3_and_format_2_alike(root, server, sid):
    counts, times = _mcap(root, sid)
    g3 = zarr.open_group(_url(server, sid), mode="r", zarr_format=3, storage_options={"headers": AUTH})
    a = g3["counts"]
    assert a.metadata.zarr_format == 3 and a.metadata.dimension_names == ("time", "y", "x")
    assert a.shards == (3, H, W) and a.chunks == (1, H, W)  # shards over time, one frame an inner chunk
    np.testing.assert_array_equal(a[:], counts)
    np.testing.assert_array_equal(a[7], counts[7])  # one frame, by range requests into its shard
    np.testing.assert_array_equal(g3["time"][:], times)
    g2 = zarr.open_group(_url(server, sid), mode="r", zarr_format=2, storage_options={"headers": AUTH})
    np.testing.assert_array_equal(g2["counts"][:], counts)
    assert dict(g3.attrs) == dict(g2.attrs)  # one description of the session, in both formats


def test_tensorstore_reads_the_same_counts(root, server):
    ts = pytest.importorskip("tensorstore", reason="tensorstore is in the test extra")
    counts, _ = _mcap(root, "s-archived")
    spec = {"driver": "zarr3", "kvstore": {"driver": "http", "base_url": _url(server) + "/",
                                            "headers": [f"Authorization: Bearer {TOKEN}"]}, "path": "counts/"}
    arr = ts.open(spec, read=True).result()
    np.testing.assert_array_equal(arr.read().result(), counts)
    np.testing.assert_array_equal(arr[13].read().result(), counts[13])


def test_xarray_opens_format_3_by_default(root, server):
    counts, times = _mcap(root, "s-archived")
    ds = xr.open_zarr(_url(server), storage_options={"headers": AUTH})
    assert ds.counts.dtype == np.uint16 and ds.counts.dims == ("time", "y", "x")
    assert ds.counts.encoding.get("shards") in (None, (3, H, W))
    np.testing.assert_array_equal(ds.counts.values, counts)
    np.testing.assert_array_equal(ds.time.values.astype(np.int64), times)
    expected = SessionTemperatures.of(root / "sessions" / "s-archived").celsius(4, counts[4]).celsius
    np.testing.assert_array_equal(ds.temperature.isel(time=4).values, expected)
    assert ds.temperature.attrs["units"] == "degC" and "model_version" in ds.temperature.attrs


def test_a_shard_whole_and_by_range(root, server):
    counts, _ = _mcap(root, "s-archived")
    frame_bytes, per = W * H * 2, 3
    index_bytes = per * 16 + 4
    url = _url(server) + "/counts/c/2/0/0"  # frames 6, 7, 8
    with httpx.Client(headers=AUTH) as http:
        whole = http.get(url)
        assert whole.status_code == 200 and len(whole.content) == per * frame_bytes + index_bytes
        assert whole.content[: per * frame_bytes] == counts[6:9].astype("<u2").tobytes()
        index = whole.content[-index_bytes:]
        assert struct.unpack("<I", index[-4:])[0] == google_crc32c.value(index[:-4])
        assert np.frombuffer(index[:-4], "<u8").reshape(per, 2).tolist() == \
            [[k * frame_bytes, frame_bytes] for k in range(per)]
        tail = http.get(url, headers={"Range": f"bytes=-{index_bytes}"})  # what a reader of one frame asks first
        assert tail.status_code == 206 and tail.content == index
        assert tail.headers["content-range"] == f"bytes {per * frame_bytes}-{per * frame_bytes + index_bytes - 1}/" \
                                                f"{per * frame_bytes + index_bytes}"
        one = http.get(url, headers={"Range": f"bytes={frame_bytes}-{2 * frame_bytes - 1}"})
        assert one.status_code == 206 and one.content == counts[7].astype("<u2").tobytes()
        head = http.head(url)
        assert head.status_code == 200 and int(head.headers["content-length"]) == len(whole.content)
        # the last shard holds what is left (60 frames: 20 shards of 3), and no shard past it
        assert http.get(_url(server) + "/counts/c/19/0/0").status_code == 200
        assert http.get(_url(server) + "/counts/c/20/0/0").status_code == 404
        assert http.get(url, headers={"Range": "bytes=999999999-"}).status_code == 416
        assert http.get(url, headers={"Range": "lines=1-2"}).status_code == 416
        assert http.get(_url(server) + "/counts/c/2/0/1").status_code == 404  # one shard across y and x
        assert http.get(_url(server) + "/zarr.json").json()["consolidated_metadata"]["metadata"]["counts"][
            "dimension_names"] == ["time", "y", "x"]


def test_the_client_follows_the_served_shards(root, server):
    import thermcap

    counts, _ = _mcap(root, "s-archived")
    s = thermcap.open(f"{server.url}/api/v1/sessions/s-archived", token=TOKEN)
    ds = s.to_xarray()
    assert set(ds.counts.chunks[0][:-1]) == {3}  # a dask task a shard, not a frame
    np.testing.assert_array_equal(ds.counts.values, counts)
    assert set(s.to_xarray(chunk_frames=12).counts.chunks[0][:-1]) == {12}
    with pytest.raises(ValueError, match="chunk_frames"):
        s.to_xarray(chunk_frames=0)


def test_the_local_and_the_remote_dataset_are_one(root, server, tmp_path):
    """The same variables, coordinates, dtypes and attributes, attribute by attribute, whether the
    session is read here or through the server, and both write to netCDF."""
    import thermcap

    local = thermcap.open("s-archived", root=root).to_xarray()
    remote = thermcap.open(f"{server.url}/api/v1/sessions/s-archived", token=TOKEN).to_xarray()
    assert local.attrs == remote.attrs
    assert sorted(local.variables) == sorted(remote.variables)
    for name in local.variables:
        a, b = local[name], remote[name]
        assert (a.dims, a.dtype) == (b.dims, b.dtype), name
        assert a.attrs == b.attrs, name
    assert local.attrs["Conventions"] == "CF-1.11" and local.attrs["fps"] > 0
    t = local.temperature.attrs
    assert t["standard_name"] == "surface_temperature" and t["units_metadata"] == "temperature: on_scale"
    assert all(local[c].attrs.get("axis") == c.upper() for c in ("y", "x")) and local.time.attrs["axis"] == "T"
    for ds, name in ((local, "local"), (remote, "remote")):
        out = tmp_path / f"{name}.nc"
        ds.isel(time=slice(0, 4)).to_netcdf(out, engine="h5netcdf")
        back = xr.open_dataset(out, engine="h5netcdf")
        np.testing.assert_array_equal(back.counts.values, local.counts.isel(time=slice(0, 4)).values)
        back.close()
