"""The HDF5 archive is valid netCDF-4 with CF conventions: xarray (h5netcdf engine) opens it
with its dimensions and CF time, gives °C for a linear model through CF packing, and a lookup
table for any other model, each equal to our own temperature path, while the stored counts
stay the recorded ones."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import RawSource, SimSource
from thermcap.recorder.radiometry import DEFAULT_MODEL, FlirPlanckModel
from thermcap.recorder.storage.reader import iter_session_frames

xr = pytest.importorskip("xarray", reason="xarray is a test dependency (pip install 'thermcap[test]')")
pytest.importorskip("h5netcdf", reason="h5netcdf is a test dependency")


def _archive(session_dir):
    archive_session(session_dir, ["hdf5"])
    (h5,) = (session_dir / "archive" / "hdf5").glob("*.h5")
    return h5


def test_linear_model_gives_degc_through_cf_packing(tmp_path):
    rec = Recorder(SimSource(width=64, height=48, fps=30, frames=12, paced=False, seed=5), tmp_path,
                   session_id="lin", analysis=False)
    assert rec.run().ok
    h5 = _archive(rec.session_dir)
    frames = list(iter_session_frames(rec.session_dir))
    with xr.open_dataset(h5, engine="h5netcdf") as ds:
        assert ds["frames"].dims == ("time", "y", "x")
        assert ds.sizes == {"time": 12, "y": 48, "x": 64}
        assert ds.attrs["Conventions"] == "CF-1.10"
        assert ds["frames"].attrs["units"] == "degC"
        got = ds["frames"].values
        want = np.stack([DEFAULT_MODEL.to_celsius(f.pixels) for f in frames])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        times = ds["time"].values.astype("datetime64[ns]").astype(np.int64)
        assert times.tolist() == [f.log_time for f in frames]
        assert ds["metadata"].values[3] == frames[3].sidecar.decode()
    with xr.open_dataset(h5, engine="h5netcdf", mask_and_scale=False) as raw:
        assert raw["frames"].dtype == np.uint16
        assert all(np.array_equal(raw["frames"].values[i], f.pixels) for i, f in enumerate(frames))
    with h5py.File(h5) as f:  # our own reader's view is unchanged
        assert f["frames"].dtype == np.uint16 and "timestamps_ns" in f


def test_a_planck_model_gets_a_lookup_table(tmp_path):
    model = FlirPlanckModel(planck_r1=17096.453, planck_b=1428.0, planck_f=1.0, planck_o=-66.0,
                            planck_r2=0.0125, emissivity=0.95)
    px = np.random.default_rng(1).integers(12000, 20000, size=(4, 32, 40), dtype=np.uint16)
    raw = tmp_path / "f.raw"
    px.astype("<u2").tofile(raw)
    rec = Recorder(RawSource(str(raw), width=40, height=32, fps=9, model=model), tmp_path, session_id="flir",
                   analysis=False)
    assert rec.run().ok
    h5 = _archive(rec.session_dir)
    with xr.open_dataset(h5, engine="h5netcdf") as ds:
        assert ds["frames"].dtype == np.uint16  # counts, no packing: the model is not linear
        lut = ds["temperature_lut"]
        assert lut.dims == ("counts",) and lut.attrs["units"] == "degC"
        celsius = lut.values[ds["frames"].values]
        np.testing.assert_allclose(celsius, np.asarray(model.to_celsius(px), dtype=np.float32), rtol=1e-6)
