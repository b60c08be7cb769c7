"""Thermal images on the map, checked with GDAL and with the samples' own metadata:

- a map GeoTIFF near nadir carries a geotransform in the right UTM zone, oblique ones four GCPs
  (``gdalinfo``);
- the DJI H20T sample (gimbal pitch -10.5 deg) is refused: its top edge looks above the
  horizon, and the export says so; the samples without a position say that;
- the same H20T file with its XMP pitch set to -90.00 (a byte-for-byte edit of the real file)
  gets a footprint of 2·h·tan(FOV/2) from its own RelativeAltitude and focal length.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess

import numpy as np
import pytest

from tests.conftest import SAMPLES, SAMPLES_HOW
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.exports.geotiff import utm_tags, write_temperature_tiff
from thermcap.recorder.importers.run import import_paths
from thermcap.recorder.maps.footprint import footprint
from thermcap.recorder.maps.pose import CameraPose

pytest.importorskip("pyproj", reason="pyproj is in the geo extra")
if shutil.which("gdalinfo") is None:
    pytest.skip("no gdalinfo here (apt-get install gdal-bin; .ci/run does this)", allow_module_level=True)


def _info(path) -> dict:
    r = subprocess.run(["gdalinfo", "-json", str(path)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


@pytest.mark.parametrize("pitch", [-90.0, -55.0])
def test_map_geotiffs_in_gdal(tmp_path, pitch):
    fp = footprint(CameraPose(53.4489, -2.815, 60.0, pitch, 20.0, 0.0, 32.0, 640, 512, "test"))
    path = tmp_path / "m.tiff"
    write_temperature_tiff(path, np.full((512, 640), 21.5, np.float32), units="degC", metadata={},
                           geo_tags=utm_tags(fp))
    info = _info(path)
    crs = (info.get("coordinateSystem") or info["gcps"]["coordinateSystem"])["wkt"]  # GCPs carry their own CRS
    assert crs.startswith('PROJCRS["WGS 84 / UTM zone 30N"') and crs.rstrip().endswith('ID["EPSG",32630]]')
    if fp.nadir:
        assert info["geoTransform"] == pytest.approx(list(fp.geotransform()), abs=1e-6)
        centre = info["cornerCoordinates"]["center"]
        assert centre == pytest.approx(list(fp.camera_en), abs=0.01)
    else:
        gcps = info["gcps"]["gcpList"]
        assert len(gcps) == 4
        for g, (e, n) in zip(gcps, fp.corners_en, strict=True):
            assert (g["x"], g["y"]) == pytest.approx((e, n), abs=1e-3)


def _import(tmp_path, data: bytes, name: str):
    src = tmp_path / name
    src.write_bytes(data)
    root = tmp_path / "root"
    import_paths([str(src)], root, session=name.split(".")[0], analysis=False)
    return root / "sessions" / name.split(".")[0]


def test_the_h20t_sample_is_refused_and_a_nadir_copy_gets_its_footprint(tmp_path):
    sample = SAMPLES / "dji" / "DJI_H20T.jpg"
    if not sample.is_file():
        pytest.skip(f"{sample} is not here: {SAMPLES_HOW}")
    data = sample.read_bytes()
    session = _import(tmp_path, data, "h20t.jpg")
    res = export_session(session, "footprints", tmp_path / "fp")
    assert res["features"] == 0 and "horizon" in res["refused"][0] and "-10.5" in res["refused"][0]
    assert b'GimbalPitchDegree="-10.50"' in data
    nadir = _import(tmp_path, data.replace(b'GimbalPitchDegree="-10.50"', b'GimbalPitchDegree="-90.00"'),
                    "h20tnadir.jpg")
    res = export_session(nadir, "footprints", tmp_path / "fpn")
    assert res["features"] == 1 and not res["refused"]
    (feature,) = json.loads((tmp_path / "fpn" / "footprints.geojson").read_text())["features"]
    p = feature["properties"]
    want = 2 * 16.508 * math.tan(math.atan(18 / 58))  # its RelativeAltitude and 35 mm focal length
    assert p["width_m"] == pytest.approx(want, abs=0.01) and p["epsg"] == 32617
    ring = feature["geometry"]["coordinates"][0]
    assert len(ring) == 5 and ring[0] == ring[-1]
    lon, lat = np.mean(ring[:4], axis=0)
    assert (lat, lon) == pytest.approx((40 + 33 / 60 + 49.61 / 3600, -(79 + 45 / 60 + 53.87 / 3600)), abs=2e-5)


@pytest.mark.parametrize("name", ["M30T_DJI_0001_R.JPG", "M2EA_DJI_0001_R.JPG"])
def test_samples_without_a_position_say_so(tmp_path, name):
    sample = SAMPLES / "dji" / name
    if not sample.is_file():
        pytest.skip(f"{sample} is not here: {SAMPLES_HOW}")
    session = _import(tmp_path, sample.read_bytes(), name.lower())
    res = export_session(session, "footprints", tmp_path / "fp")
    assert res["features"] == 0 and "no position" in res["refused"][0]


@pytest.mark.parametrize("crs", ["4326", "utm"])
def test_the_terraref_sample_lands_where_the_pipeline_puts_it(tmp_path, crs):
    binf = SAMPLES / "terraref" / "c3c21db1-deb5-481a-8180-ad447f356a95_ir.bin"
    if not binf.is_file():
        pytest.skip(f"{binf} is not here: {SAMPLES_HOW}")
    root = tmp_path / "root"
    import_paths([str(binf)], root, session="tr", analysis=False)
    session = root / "sessions" / "tr"
    res = export_session(session, "map-tiff", tmp_path / "m", crs=crs)
    assert res["files"] == 1, res
    (path,) = (tmp_path / "m").glob("*.map.tiff")
    info = _info(path)
    assert info["size"] == [480, 640]  # rotated as the pipeline writes it: numpy.rot90(raw, 3)
    md = json.loads((SAMPLES / "terraref" / "c3c21db1-deb5-481a-8180-ad447f356a95_metadata.json").read_text())
    lm = md["lemnatec_measurement_metadata"]
    g, s = lm["gantry_system_variable_metadata"], lm["sensor_fixed_metadata"]
    cx = float(g["position x [m]"]) + float(s["location in camera box x [m]"])
    cy = float(g["position y [m]"]) + float(s["location in camera box y [m]"])
    above = float(g["position z [m]"]) + float(s["location in camera box z [m]"]) + 1.0  # rail_height_offset
    fx, fy = float(s["field of view x [m]"]) * above / 2, float(s["field of view y [m]"]) * above / 2
    gt = info["geoTransform"]
    if crs == "4326":
        assert 'ID["EPSG",4326]' in info["coordinateSystem"]["wkt"]
        assert gt[1] * 480 == pytest.approx(fy / (111320 * math.cos(math.radians(33.0746))), rel=0.01)
        assert -gt[5] * 640 == pytest.approx(fx / 110900, rel=0.01)
        assert (gt[3], gt[0]) == pytest.approx((33.07462, -111.97504), abs=2e-5)  # the field's SE corner area
    else:
        assert info["coordinateSystem"]["wkt"].rstrip().endswith('ID["EPSG",32612]]')
        # The published placement (terrautils: linear transform, to lat/lon, the fixed shift),
        # projected back to UTM 12N as terrautils' tuples_to_utm does: not the unshifted transform.
        from pyproj import Transformer

        e_nw = 409012.2032 + 0.009 * (cx + fx / 2) - 0.9986 * (cy + fy / 2)
        n_nw = 3659974.971 + 1.0002 * (cx + fx / 2) + 0.0078 * (cy + fy / 2)
        lon, lat = Transformer.from_crs(32612, 4326, always_xy=True).transform(e_nw, n_nw)
        want = Transformer.from_crs(4326, 32612, always_xy=True).transform(lon + 0.000020308287, lat - 0.000015258894)
        assert (gt[0], gt[3]) == pytest.approx(want, abs=1e-3)
        assert math.dist((gt[0], gt[3]), (e_nw, n_nw)) == pytest.approx(2.54, abs=0.02)  # the documented shift
    assert "fixed shift" in json.loads(info["metadata"][""]["TIFFTAG_IMAGEDESCRIPTION"])["placement"]
    from thermcap.recorder.radiometry import model_from_dict
    from thermcap.recorder.storage.reader import iter_session_frames
    from thermcap.recorder.storage.reader import read_session_meta as meta

    frame = next(iter(iter_session_frames(session))).pixels
    want = np.rot90(np.asarray(model_from_dict(meta(session)["radiometric_model"]).to_celsius(frame)), 3)
    out = tmp_path / "copy.tiff"  # what GDAL reads, written out by GDAL
    subprocess.run(["gdal_translate", "-q", "-co", "COMPRESS=NONE", str(path), str(out)], check=True, timeout=60)
    import tifffile

    np.testing.assert_allclose(tifffile.imread(out), want, rtol=1e-6)


def test_the_terraref_sample_is_on_the_same_ground_in_both_crs(tmp_path):
    """Issue 37: the UTM product sat 2.54 m from the EPSG:4326 one (the pipeline's fixed shift was
    applied to one only). Every corner and the centre of the two GeoTIFFs, as GDAL reads them,
    must land within a centimetre of each other."""
    from pyproj import Transformer

    binf = SAMPLES / "terraref" / "c3c21db1-deb5-481a-8180-ad447f356a95_ir.bin"
    if not binf.is_file():
        pytest.skip(f"{binf} is not here: {SAMPLES_HOW}")
    root = tmp_path / "root"
    import_paths([str(binf)], root, session="tr", analysis=False)
    ground = {}
    for crs in ("4326", "utm"):
        export_session(root / "sessions" / "tr", "map-tiff", tmp_path / crs, crs=crs)
        (path,) = (tmp_path / crs).glob("*.map.tiff")
        info = _info(path)
        gt, (w, h) = info["geoTransform"], info["size"]
        px = [(0, 0), (w, 0), (w, h), (0, h), (w / 2, h / 2)]
        xy = [(gt[0] + c * gt[1] + r * gt[2], gt[3] + c * gt[4] + r * gt[5]) for c, r in px]
        if crs == "4326":
            xy = [Transformer.from_crs(4326, 32612, always_xy=True).transform(*p) for p in xy]
        ground[crs] = xy
    for a, b in zip(ground["4326"], ground["utm"], strict=True):
        assert math.dist(a, b) < 0.01, (a, b)


def test_a_mosaic_and_its_footprints_render_in_gdal(tmp_path):
    """The README's picture, made the same way: GDAL colours the mosaic and draws the flight's
    footprints over it; the targets show where they are."""
    from pyproj import Transformer

    from thermcap.recorder.capture.recorder import Recorder
    from thermcap.recorder.maps.footprint import utm_epsg
    from thermcap.recorder.maps.synthetic import FlightSource, GroundTarget, lawnmower

    pytest.importorskip("rasterio", reason="rasterio is in the geo extra")
    lat, lon = 33.0746, -111.975
    epsg = utm_epsg(lat, lon)
    e0, n0 = Transformer.from_crs(4326, epsg, always_xy=True).transform(lon, lat)
    targets = [GroundTarget(e0 + 3, n0 + 5, 0.8, 45.0), GroundTarget(e0 + 22, n0 + 31, 0.8, 50.0)]
    poses = lawnmower(lat, lon, height_m=40, legs=3, per_leg=4, spacing_m=12.0,
                      hfov_deg=2 * math.degrees(math.atan(18 / 58)))
    rec = Recorder(FlightSource(poses=poses, targets=targets, epsg=epsg), tmp_path / "root", session_id="f",
                   analysis=False)
    assert rec.run().ok
    out = tmp_path / "out"
    for kind in ("mosaic", "footprints"):
        assert export_session(rec.session_dir, kind, out)["files"]

    def run(*cmd):
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=out)
        assert r.returncode == 0, (cmd, r.stderr)

    run("ogr2ogr", "-t_srs", f"EPSG:{epsg}", "-nlt", "MULTILINESTRING", "lines.geojson", "footprints.geojson")
    (out / "colors.txt").write_text("nv 0 0 0 0\n15 0 0 0\n20 32 0 96\n34 208 48 64\n46 255 208 32\n51 255 255 240\n")
    run("gdaldem", "color-relief", "-q", "mosaic.tiff", "colors.txt", "rgb.tif", "-alpha")
    run("gdal_rasterize", "-q", "-b", "1", "-b", "2", "-b", "3", "-burn", "120", "-burn", "200", "-burn", "255",
        "lines.geojson", "rgb.tif")
    run("gdal_translate", "-q", "-of", "PNG", "rgb.tif", "map.png")
    import imagecodecs
    import rasterio

    img = imagecodecs.png_decode((out / "map.png").read_bytes())
    assert ((img[..., 0] == 120) & (img[..., 2] == 255)).sum() > 500  # the footprint outlines
    with rasterio.open(out / "mosaic.tiff") as m:
        for t in targets:
            row, col = m.index(t.easting, t.northing)
            assert img[row, col, 0] > 200, "the target is not where it is on the map"  # warm, not background


def _with_xmp(data: bytes, xmp: bytes) -> bytes:
    """The JPEG with its XMP APP1 segment replaced (every other byte kept)."""
    head = b"http://ns.adobe.com/xap/1.0/\x00"
    i = data.index(head) - 4
    assert data[i:i + 2] == b"\xff\xe1"
    old = int.from_bytes(data[i + 2:i + 4], "big")
    payload = head + xmp
    return data[:i] + b"\xff\xe1" + (len(payload) + 2).to_bytes(2, "big") + payload + data[i + 2 + old:]


def test_flir_samples_a_duo_pro_r_fff_has_no_attitude_and_an_xt2_laid_out_as_a_flir_drone_file_is_placed(tmp_path):
    """The Duo Pro R FFF holds a GPS fix and the lens's FieldOfView (45 deg) but no attitude: it
    is refused, and says so. The XT2 file (a FLIR-format file from a DJI Zenmuse XT2) looks at
    the horizon (drone-dji pitch 0) and is refused; with its XMP in the layout of FLIR's own
    drone cameras (Pix4D Camera:Pitch 0 = nadir, FLIR:MAVRelativeAltitude, rationals), it gets a
    footprint of 2·h·tan(FOV/2) from the XT2 19 mm lens's datasheet FOV."""
    fff, xt2 = SAMPLES / "flir" / "frame_000000.fff", SAMPLES / "flir" / "DJI_XT2.jpg"
    if not (fff.is_file() and xt2.is_file()):
        pytest.skip(f"the FLIR samples are not here ({fff.parent})")
    duo = _import(tmp_path, fff.read_bytes(), "duo.fff")
    res = export_session(duo, "footprints", tmp_path / "duo")
    assert res["features"] == 0 and "no camera attitude" in res["refused"][0]
    from thermcap.recorder.exports.files import _import_vendor

    (vendor,) = _import_vendor(duo).values()
    assert vendor["field_of_view_deg"] == 45.0 and vendor["gps"]["latitude"] == pytest.approx(53.44890, abs=1e-4)

    data = xt2.read_bytes()
    res = export_session(_import(tmp_path, data, "xt2.jpg"), "footprints", tmp_path / "xt2")
    assert res["features"] == 0 and "horizon" in res["refused"][0]
    xmp = (b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
           b'<rdf:Description rdf:about="" xmlns:Camera="http://pix4d.com/camera/1.0/" '
           b'xmlns:FLIR="http://ns.flir.com/xmp/1.0/"><Camera:Yaw>8240/100</Camera:Yaw>'
           b'<Camera:Pitch>0/100</Camera:Pitch><Camera:Roll>0/100</Camera:Roll>'
           b'<FLIR:MAVRelativeAltitude>30000/1000</FLIR:MAVRelativeAltitude></rdf:Description></rdf:RDF></x:xmpmeta>')
    session = _import(tmp_path, _with_xmp(data, xmp), "xt2flir.jpg")
    res = export_session(session, "footprints", tmp_path / "xt2f")
    assert res["features"] == 1 and not res["refused"], res
    (feature,) = json.loads((tmp_path / "xt2f" / "footprints.geojson").read_text())["features"]
    p = feature["properties"]
    assert p["nadir"] and p["gimbal_yaw_deg"] == pytest.approx(82.4) and "XT2" in p["fov_source"]
    assert p["width_m"] == pytest.approx(2 * 30.0 * math.tan(math.radians(16.0)), abs=0.01)
    lon, lat = np.mean(feature["geometry"]["coordinates"][0][:4], axis=0)
    assert (lat, lon) == pytest.approx((9 + 58 / 60 + 19.77 / 3600, 76 + 22 / 60 + 40.03 / 3600), abs=2e-5)
    res = export_session(session, "map-tiff", tmp_path / "xt2t")
    (tif,) = (tmp_path / "xt2t").glob("*.map.tiff")
    assert _info(tif)["coordinateSystem"]["wkt"].endswith('ID["EPSG",32643]]')  # UTM 43N
