"""GDAL (Debian's gdalinfo and gdal_translate, as QGIS uses it) reads our artefacts right: the
°C GeoTIFF and its COG variant with unit, NoData, DEFLATE + floating-point predictor, tiles,
the radiometric model and, where the frame has a position, its ground control point; and the
HDF5 archive through GDAL's netCDF driver, band for frame, with the recorded counts."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from tests.conftest import SAMPLES, SAMPLES_HOW
from thermcap.archive.archiver import archive_session
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources import SimSource
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.importers.run import import_paths
from thermcap.recorder.radiometry import model_from_dict
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

if shutil.which("gdalinfo") is None:
    pytest.skip("no gdalinfo here (apt-get install gdal-bin; .ci/run does this)", allow_module_level=True)


def _info(path) -> dict:
    r = subprocess.run(["gdalinfo", "-json", "-stats", str(path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


@pytest.fixture(scope="module")
def duo(tmp_path_factory):
    sample = SAMPLES / "flir" / "frame_000000.fff"
    if not sample.is_file():
        pytest.skip(f"{sample} is not here: {SAMPLES_HOW}")
    root = tmp_path_factory.mktemp("duo")
    import_paths([str(sample)], root, session="duo", analysis=False)
    return root / "sessions" / "duo"


@pytest.mark.parametrize("kind", ["celsius-tiff", "celsius-cog"])
@pytest.mark.filterwarnings("error::rasterio.errors.NotGeoreferencedWarning")  # no noise for the user
def test_temperature_geotiff_in_gdal(duo, tmp_path, kind):
    export_session(duo, kind, tmp_path)
    (path,) = tmp_path.glob("*.tiff")
    info = _info(path)
    band = info["bands"][0]
    assert band["type"] == "Float32" and band["unit"] == "degC" and band["noDataValue"] == "NaN"
    structure = info["metadata"]["IMAGE_STRUCTURE"]
    assert structure["COMPRESSION"] == "DEFLATE" and structure["PREDICTOR"] == "3"
    assert band["block"][0] == band["block"][1] and band["block"][0] % 16 == 0
    if kind == "celsius-cog":
        assert structure["LAYOUT"] == "COG"
    model = json.loads(info["metadata"][""]["radiometric_model"])
    assert model["kind"] == "flir_planck"
    gcp = info["gcps"]["gcpList"][0]  # the Duo Pro R's own GPS fix (53.4489 N, 2.8150 W)
    assert (round(gcp["y"], 4), round(gcp["x"], 4)) == (53.4489, -2.815)
    # the values GDAL computes statistics on are our temperatures
    frame = next(iter(iter_session_frames(duo))).pixels
    want = np.asarray(model_from_dict(read_session_meta(duo)["radiometric_model"]).to_celsius(frame))
    assert band["minimum"] == pytest.approx(float(np.nanmin(want)), abs=1e-3)
    assert band["maximum"] == pytest.approx(float(np.nanmax(want)), abs=1e-3)


def test_the_hdf5_archive_opens_in_gdal_as_netcdf(tmp_path):
    rec = Recorder(SimSource(width=64, height=48, fps=30, frames=6, paced=False, seed=2), tmp_path, session_id="g",
                   analysis=False)
    assert rec.run().ok
    archive_session(rec.session_dir, ["hdf5"])
    (h5,) = (rec.session_dir / "archive" / "hdf5").glob("*.h5")
    frames = list(iter_session_frames(rec.session_dir))
    # opening the file as it is (what QGIS does) picks GDAL's HDF5 driver: a band per frame
    info = _info(h5)
    assert info["driverShortName"] == "HDF5Image" and info["size"] == [64, 48] and len(info["bands"]) == 6
    assert _band(h5, 3, tmp_path).tolist() == frames[2].pixels.tolist()
    # the netCDF driver sees the CF conventions; it turns grids without georeferencing bottom-up
    # unless told not to (GDAL's documented GDAL_NETCDF_BOTTOMUP=NO)
    info = _info(f'NETCDF:"{h5}":frames')
    assert info["driverShortName"] == "netCDF" and len(info["bands"]) == 6
    assert info["metadata"][""]["NC_GLOBAL#Conventions"] == "CF-1.10"
    assert info["metadata"][""]["frames#units"] == "degC"
    assert np.array_equal(_band(f'NETCDF:"{h5}":frames', 3, tmp_path, "--config", "GDAL_NETCDF_BOTTOMUP", "NO"),
                          frames[2].pixels)


def _band(source, n, tmp_path, *options) -> np.ndarray:
    out = tmp_path / f"band{n}.raw"
    r = subprocess.run(["gdal_translate", "-q", *options, "-of", "ENVI", "-b", str(n), str(source), str(out)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return np.fromfile(out, "<u2").reshape(48, 64)
