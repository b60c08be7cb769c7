"""``import thermcap``: a session opened from a folder, an id, an HTTP URL, and the Zarr endpoint
read with stock ``xr.open_zarr``, each compared with the MCAP frames bit-exact."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import thermcap
from tests.support.api_data import H, W, make_root, token_server
from thermcap.recorder.radiometry.session import SessionTemperatures
from thermcap.recorder.storage.reader import iter_session_frames

pytestmark = pytest.mark.integration

TOKEN = "python-api-token-0123456789"


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_root(tmp_path_factory.mktemp("pyroot"))


@pytest.fixture(scope="module")
def server(root, tmp_path_factory):
    s = token_server(root, tmp_path_factory.mktemp("tok"), TOKEN)
    yield s
    s.stop()


def _mcap(root, sid):
    frames = list(iter_session_frames(root / "sessions" / sid))
    return np.stack([f.pixels for f in frames]), np.array([f.log_time for f in frames], np.int64)


@pytest.mark.parametrize("sid", ["s-archived", "s-mcap-only"])
def test_open_a_folder_and_an_id(root, sid):
    counts, times = _mcap(root, sid)
    for s in (thermcap.open(root / "sessions" / sid), thermcap.open(sid, root=root)):
        assert len(s) == len(counts) and (s.width, s.height) == (W, H)
        np.testing.assert_array_equal(s.table.timestamp_ns, times)
        f = s.frame(3)
        assert f.counts.dtype == np.uint16 and np.array_equal(f.counts, counts[3]) and f.time_ns == times[3]
        assert s.frame_at(int(times[5]) + 1).index == 5
        assert s.frame_at(str(s.times[7])).index == 7
        assert s[-1].index == len(counts) - 1


def test_to_xarray_is_lazy_exact_and_cf(root):
    s = thermcap.open("s-archived", root=root)
    counts, times = _mcap(root, "s-archived")
    ds = s.to_xarray(chunk_frames=7)
    assert ds.counts.dtype == np.uint16 and ds.counts.dims == ("time", "y", "x")
    assert ds.counts.chunks[0][0] == 7  # dask-backed: nothing read yet
    assert ds.temperature.dtype == np.float32 and ds.temperature.attrs["units"] == "degC"
    assert ds.time.dtype == np.dtype("datetime64[ns]")
    np.testing.assert_array_equal(ds.time.values.astype(np.int64), times)
    np.testing.assert_array_equal(ds.counts.values, counts)
    assert list(ds.y.values[:3]) == [0, 1, 2]  # top-down, as stored
    expected = SessionTemperatures.of(root / "sessions" / "s-archived").celsius(10, counts[10]).celsius
    np.testing.assert_array_equal(ds.temperature.isel(time=10).values, expected)
    assert "thermal_contrast_grade" in ds.coords and "target_count" in ds.coords


def test_an_unknown_model_version_is_refused_before_reading(root):
    s = thermcap.open("s-archived", root=root)
    with pytest.raises(ValueError, match="model version 9"):
        s.to_xarray(model_version=9)


def test_bad_names_are_clear(root, tmp_path):
    with pytest.raises(FileNotFoundError, match="no session 'nope'"):
        thermcap.open("nope", root=root)
    with pytest.raises(ValueError, match="session id"):
        thermcap.open("..", root=root)
    with pytest.raises(ValueError, match="session URL"):
        thermcap.open("http://127.0.0.1:1/somewhere")


def test_the_zarr_endpoint_reads_with_stock_xarray(root, server):
    counts, times = _mcap(root, "s-archived")
    url = f"{server.url}/api/v1/sessions/s-archived/zarr"
    ds = xr.open_zarr(url, storage_options={"headers": {"Authorization": f"Bearer {TOKEN}"}})
    assert ds.counts.dtype == np.uint16
    np.testing.assert_array_equal(ds.counts.values, counts)
    np.testing.assert_array_equal(ds.time.values.astype(np.int64), times)
    expected = SessionTemperatures.of(root / "sessions" / "s-archived").celsius(4, counts[4]).celsius
    np.testing.assert_array_equal(ds.temperature.isel(time=4).values, expected)
    assert ds.attrs["session_id"] == "s-archived"


def test_the_zarr_endpoint_needs_the_token(server):
    import httpx

    r = httpx.get(f"{server.url}/api/v1/sessions/s-archived/zarr/.zmetadata")
    assert r.status_code == 401
    r = httpx.get(f"{server.url}/api/v1/sessions/s-archived/zarr/zarr.json")
    assert r.status_code == 401  # format 3's metadata is guarded as format 2's is
    r = httpx.get(f"{server.url}/api/v1/sessions/s-archived/zarr/counts/99999.0.0",
                  headers={"Authorization": f"Bearer {TOKEN}"})
    assert r.status_code == 404


def test_the_client_and_an_http_session(root, server):
    counts, _times = _mcap(root, "s-crossover")
    with thermcap.Client(server.url, TOKEN) as client:
        ids = [s.id for s in client.sessions(page_size=1)]  # paging through the cursor
        assert sorted(ids) == ["s-archived", "s-crossover", "s-mcap-only"]
        info = client.session("s-crossover")
        assert (info.width, info.height, info.frames) == (W, H, len(counts))
        frames = list(client.frames("s-crossover", page_size=50))
        assert [f.index for f in frames] == list(range(len(counts)))
        np.testing.assert_array_equal(client.frame_counts("s-crossover", 9), counts[9])
        with pytest.raises(thermcap.ServerError) as caught:
            client.session("nope")
        assert caught.value.status == 404 and "nope" in caught.value.message
    s = thermcap.open(f"{server.url}/api/v1/sessions/s-crossover", token=TOKEN)
    assert len(s) == len(counts)
    np.testing.assert_array_equal(s.frame(2).counts, counts[2])
    np.testing.assert_array_equal(s.to_xarray().counts.values, counts)
    with pytest.raises(thermcap.ServerError) as caught:
        thermcap.Client(server.url, "wrong-token").session("s-crossover")
    assert caught.value.status == 401
