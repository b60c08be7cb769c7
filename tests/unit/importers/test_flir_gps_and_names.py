"""FLIR files keep what they say: the FFF GPSInfo position (checked against exiftool's values
on every sample that has one), the camera model as the sensor id, and the camera's calibrated
range in ICD file names instead of an invented one."""

from __future__ import annotations

import re

import pytest

from thermcap.recorder.exports.files import export_session
from thermcap.recorder.icd.names import parse_name
from thermcap.recorder.importers import read_file
from thermcap.recorder.importers.run import import_paths


def _exiftool(path):
    out = {}
    raw = path.read_bytes()
    text = raw.decode("utf-16") if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else raw.decode("utf-8", "replace")
    for line in text.splitlines():
        k, sep, v = line.partition(":")
        if sep:
            out[k.strip()] = v.strip()
    return out


def _dms(text: str) -> float:
    d, m, s, ref = re.match(r"(\d+) deg (\d+)' ([\d.]+)\" ([NSEW])", text).groups()
    v = int(d) + int(m) / 60 + float(s) / 3600
    return -v if ref in "SW" else v


FLIR = ["FLIR_T640.jpg", "FLIR_E40.jpg", "frame_000000.fff", "DJI_XT2.jpg"]


@pytest.mark.parametrize("name", FLIR)
def test_gps_model_and_range_as_exiftool_reads_them(samples, name):
    path = samples / "flir" / name
    ref = _exiftool(path.with_suffix(".exiftool.txt"))
    (frame,) = read_file(str(path))
    gps = frame.vendor_metadata.get("gps")
    if "GPS Latitude" in ref:
        assert gps is not None, "the file has a GPS position and it was dropped"
        assert gps["source"] == ("FLIR GPSInfo" if ref.get("GPS Valid") == "Yes" else "EXIF GPS")
        assert gps["latitude"] == pytest.approx(_dms(ref["GPS Latitude"]), abs=1e-5)
        assert gps["longitude"] == pytest.approx(_dms(ref["GPS Longitude"]), abs=1e-5)
        if "GPS Altitude" in ref:
            assert gps["altitude_m"] == pytest.approx(float(ref["GPS Altitude"].split()[0]), abs=0.01)
    else:
        assert gps is None
    model = ref.get("Camera Model")
    if model:
        assert frame.sensor_model == model
        assert frame.sensor_id == re.sub(r"[^A-Za-z0-9-]+", "-", model if model.upper().startswith("FLIR")
                                         else f"FLIR {model}").strip("-")
    lo, hi = (float(ref[f"Camera Temperature Range {k}"].split()[0]) for k in ("Min", "Max"))
    assert frame.vendor_metadata["camera_range_c"] == pytest.approx([lo, hi], abs=0.01)


def test_exported_names_carry_the_camera_and_its_range(samples, tmp_path):
    import_paths([str(samples / "flir" / "frame_000000.fff")], tmp_path, session="duo", analysis=False)
    res = export_session(tmp_path / "sessions" / "duo", "celsius-tiff", tmp_path / "out")
    (name,) = [p.name for p in (tmp_path / "out").glob("*.tiff")]
    parsed = parse_name(name)  # our own exports parse as ICD names
    assert parsed.sensor_id == "FLIR-Duo-Pro-R"
    assert (parsed.temp_min_c, parsed.temp_max_c) == (-25.0, 135.0)
    assert res["files"] == 1
