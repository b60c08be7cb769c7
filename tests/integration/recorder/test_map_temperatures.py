"""Issue 37, the rest of the matrix: the map products (map-tiff, mosaic, hot spots), the heatmap's
scale and the celsius COG x {the capture model, a re-parameterised version}, against flyr.

A drone survey whose frames are a real FLIR T640 image (its raw counts and its Planck model),
flown over a flat field: the map products must give flyr's temperatures at the emissivity of the
version they used, and name that version. Before, hot spots carried the detector's figure from
capture and the mosaic named no version."""

from __future__ import annotations

import json

import imagecodecs
import numpy as np
import pytest
import tifffile

from tests.conftest import SAMPLES, SAMPLES_HOW
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.exports.files import _import_vendor, export_session
from thermcap.recorder.importers.run import import_paths
from thermcap.recorder.maps.footprint import footprint, utm_epsg
from thermcap.recorder.maps.mosaic import build_mosaic
from thermcap.recorder.maps.pose import pose_from_vendor
from thermcap.recorder.maps.synthetic import FlightSource, lawnmower
from thermcap.recorder.radiometry.base import model_from_dict
from thermcap.recorder.radiometry.params import add_version
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

flyr = pytest.importorskip("flyr", reason="flyr is a test dependency (pip install 'thermcap[test]')")
T640 = SAMPLES / "flir" / "FLIR_T640.jpg"
LAT, LON = 33.0746, -111.975
VERSIONS = {0: None, 1: 0.8}  # model version -> the emissivity flyr is given (None: the file's own)
ERRORS: dict[str, float] = {}


def _flyr(emissivity: float | None) -> np.ndarray:
    th = flyr.unpack(str(T640))
    return (th.adjust_metadata(emissivity=emissivity) if emissivity is not None else th).celsius


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    if not T640.is_file():
        pytest.skip(f"{T640} is not here: {SAMPLES_HOW}")
    root = tmp_path_factory.mktemp("flight")
    import_paths([str(T640)], root, session="t640", analysis=False)
    still = root / "sessions" / "t640"
    raw = next(iter(iter_session_frames(still))).pixels
    model = model_from_dict(read_session_meta(still)["radiometric_model"])
    h, w = raw.shape

    class FlirFlight(FlightSource):  # a survey whose every frame is the real image
        def render(self, pose):
            return raw

    poses = lawnmower(LAT, LON, height_m=40, legs=1, per_leg=2, spacing_m=30, hfov_deg=25, width=w, height=h)
    rec = Recorder(FlirFlight(poses=poses, targets=[], epsg=utm_epsg(LAT, LON), model=model), root,
                   session_id="flight", analysis=True)
    assert rec.run().ok
    session = root / "sessions" / "flight"
    add_version(session, model, {"emissivity": 0.8}, who="test", why="painted steel")
    return session


@pytest.mark.parametrize("version", sorted(VERSIONS))
def test_map_tiffs_follow_the_version(flight, tmp_path, version):
    ref = _flyr(VERSIONS[version])
    export_session(flight, "map-tiff", tmp_path, model_version=version)
    paths = sorted(tmp_path.glob("*.map.tiff"))
    assert len(paths) == 2
    for path in paths:
        with tifffile.TiffFile(path) as t:
            data = t.asarray()
            desc = json.loads(t.pages[0].description)
        err = float(np.nanmax(np.abs(data - ref)))
        assert err < 0.01, err
        ERRORS[f"map-tiff v{version}"] = max(ERRORS.get(f"map-tiff v{version}", 0.0), err)
        assert desc["units"] == "degC"
    with tifffile.TiffFile(paths[0]) as t:  # GDAL's metadata tag names the version, for GIS tools
        gdal_xml = t.pages[0].tags["GDAL_METADATA"].value
    assert f'"model_version": {version}' in gdal_xml or f">{version}<" in gdal_xml, gdal_xml


@pytest.mark.parametrize("version", sorted(VERSIONS))
def test_the_mosaic_follows_the_version(flight, tmp_path, version):
    ref = _flyr(VERSIONS[version])
    export_session(flight, "mosaic", tmp_path, model_version=version)
    got = tifffile.imread(tmp_path / "mosaic.tiff")
    # The same cells from flyr's temperatures, through the same geometry
    tiles = []
    for f, vendor in zip(iter_session_frames(flight), _import_vendor(flight).values(), strict=True):
        h, w = f.pixels.shape
        tiles.append((f.index, footprint(pose_from_vendor(vendor, w, h)), ref.astype(np.float32)))
    want = build_mosaic(tiles).temps
    assert got.shape == want.shape and np.array_equal(np.isnan(got), np.isnan(want))
    err = float(np.nanmax(np.abs(got - want)))
    assert err < 0.01, err
    ERRORS[f"mosaic v{version}"] = err
    frames = json.loads((tmp_path / "mosaic.frames.json").read_text())["frames"]
    assert {f["model_version"] for f in frames} == {version}


@pytest.mark.parametrize("version", sorted(VERSIONS))
def test_hot_spots_are_measured_in_the_version(flight, tmp_path, version):
    ref = _flyr(VERSIONS[version])
    export_session(flight, "hotspots", tmp_path, model_version=version)
    spots = [f["properties"] for f in json.loads((tmp_path / "hotspots.geojson").read_text())["features"]]
    assert spots, "the detector found the image's hot objects"
    boxes = {(f.index, t["target_id"]): t["bbox"] for f in iter_session_frames(flight)
             for t in f.sidecar_dict()["targets"]}
    err = 0.0
    for s in spots:
        x0, y0, x1, y1 = boxes[(s["frame_index"], s["target_id"])]
        err = max(err, abs(s["max_temp_c"] - float(np.nanmax(ref[y0:y1 + 1, x0:x1 + 1]))))
        assert s["model_version"] == version
    assert err < 0.01, err
    ERRORS[f"hotspots v{version}"] = err
    if version == 1:  # emissivity 0.8 reads a hot object hotter than the camera's 0.95 did
        assert all(s["max_temp_c"] > s["max_temp_c_at_capture"] for s in spots)


@pytest.mark.parametrize("version", sorted(VERSIONS))
def test_heatmap_scale_and_cog_follow_the_version(flight, tmp_path, version):
    ref = _flyr(VERSIONS[version])
    export_session(flight, "heatmap-png", tmp_path / "h", model_version=version, range_mode="frame")
    png = sorted((tmp_path / "h").glob("*.png"))[0].read_bytes()
    lo, hi = np.percentile(ref, (0.5, 99.5))
    text = _png_text(png)
    assert abs(float(text["thermcap:range_min"]) - lo) < 0.05 and abs(float(text["thermcap:range_max"]) - hi) < 0.05
    assert text["thermcap:model_version"] == str(version)
    assert imagecodecs.png_decode(png).shape[:2][1] >= ref.shape[1]
    export_session(flight, "celsius-cog", tmp_path / "c", model_version=version)
    cog = sorted((tmp_path / "c").glob("*.tiff"))[0]
    err = float(np.nanmax(np.abs(tifffile.imread(cog) - ref)))
    assert err < 0.01, err
    ERRORS[f"celsius-cog v{version}"] = err


def _png_text(png: bytes) -> dict[str, str]:
    out, i = {}, 8
    while i < len(png):
        n = int.from_bytes(png[i:i + 4], "big")
        kind, body = png[i + 4:i + 8], png[i + 8:i + 8 + n]
        if kind == b"tEXt":
            k, _, v = body.partition(b"\0")
            out[k.decode("latin-1")] = v.decode("latin-1")
        i += 12 + n
    return out


def test_zz_print_errors():
    for k, v in sorted(ERRORS.items()):
        print(f"{k}: max |error| {v:.6f} °C against flyr")
