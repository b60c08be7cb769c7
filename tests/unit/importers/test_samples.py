"""Every real sample imports bit-exact with the temperatures the vendors' own tools give."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from thermcap.recorder.importers import read_file
from thermcap.recorder.importers.jpeg import app_segments, concat_app
from thermcap.recorder.radiometry import TemperatureUnavailable, TerraRefPlanckModel


def _sha(px):
    return hashlib.sha256(np.ascontiguousarray(px, dtype="<u2").tobytes()).hexdigest()


def _ref(samples: Path, folder: str) -> dict:
    return json.loads((samples / folder / "reference.json").read_text())


def test_flir_raw_and_temperatures_within_0_01_c(samples):
    ref = _ref(samples, "flir")
    for name in ("FLIR_E40.jpg", "FLIR_T640.jpg", "DJI_XT2.jpg", "frame_000000.fff"):
        (f,) = read_file(samples / "flir" / name)
        r = ref[name]
        assert _sha(f.pixels) == r["raw_sha256"], name
        t = f.model.to_celsius(f.pixels)
        tr = r["temperature_reference"]
        for y, x, v in tr["pixels_row_col_C"]:
            assert abs(t[y, x] - v) < 0.01, (name, y, x)
        assert abs(t.min() - tr["min_C"]) < 0.01
        assert abs(t.max() - tr["max_C"]) < 0.01
        assert abs(t.mean() - tr["mean_C"]) < 0.01
        cp = r["camera_params"]
        assert f.model.emissivity == pytest.approx(cp["E"], abs=1e-5)
        assert f.model.planck_r1 == pytest.approx(cp["PR1"], rel=1e-6)


def test_flir_radiometric_tiff(samples):
    (f,) = read_file(samples / "flir" / "example_radiometric.tiff")
    r = _ref(samples, "flir")["example_radiometric.tiff"]
    assert _sha(f.pixels) == r["raw_sha256"]
    t = f.model.to_celsius(f.pixels)
    assert abs(t.min() - r["temperature_reference"]["min_C"]) < 0.01
    assert abs(t.max() - r["temperature_reference"]["max_C"]) < 0.01


def test_dji_raw_bit_exact_layouts_and_blobs(samples):
    ref = _ref(samples, "dji")
    for name, r in ref.items():
        path = samples / "dji" / name
        (f,) = read_file(path)
        assert f.layout == r["layout"], name
        assert f.pixels.shape == (r["height"], r["width"]), name
        assert _sha(f.pixels) == r["raw_sha256"], name
        segs = app_segments(str(path), path.read_bytes())
        assert f.blobs["dji_app4_params.bin"] == concat_app(segs, 0xE4)
        assert f.blobs["dji_app5_calibration.bin"] == concat_app(segs, 0xE5)
        for k in ("distance_m", "humidity_pct", "emissivity", "reflection_C"):
            ours = f.vendor_metadata["embedded_params"][k.replace("_C", "_c")]
            assert ours == pytest.approx(r["embedded_params"][k], abs=0.01), (name, k)


def test_dji_iirp_is_exactly_the_uncorrected_formula_and_labelled(samples):
    ref = _ref(samples, "dji")
    for name, r in ref.items():
        (f,) = read_file(samples / "dji" / name)
        if r["layout"] == "iirp":
            t = f.model.to_celsius(f.pixels)
            assert np.array_equal(t, (f.pixels >> 2) * 0.0625 - 273.15)
            u = r["uncorrected_formula_C"]
            assert round(float(t.min()), 3) == u["min_C"]
            assert round(float(t.max()), 3) == u["max_C"]
            assert f.model.approximate
            assert "approximate" in f.model.to_dict()["temperature"]
        else:
            with pytest.raises(TemperatureUnavailable, match="DJI Thermal SDK"):
                f.model.to_celsius(f.pixels)


def test_m30t_frame_size_comes_from_the_thermal_header_not_the_jpeg(samples):
    (f,) = read_file(samples / "dji" / "M30T_DJI_0001_R.JPG")
    assert f.pixels.shape == (512, 640)


def test_terraref_pipeline_and_physical_variants(samples):
    ref = json.loads((samples / "terraref" / "reference_temperatures_derived.json").read_text())
    (f,) = read_file(next((samples / "terraref").glob("*_ir.bin")))
    assert _sha(f.pixels) == ref["raw"]["sha256"]
    assert f.pixels.shape == (480, 640)
    pipe = ref["terraref_Get_FLIR_2017_as_implemented (T=22C,D=2.5m,E=0.98,H=0.1; forward-model bug kept)"]
    t = f.model.to_celsius(f.pixels)
    assert f.model.variant == "pipeline"
    assert abs(t.min() - pipe["min"]) < 0.01
    assert abs(t.max() - pipe["max"]) < 0.01
    assert abs(t.mean() - pipe["mean"]) < 0.01
    assert abs(t[0, 0] - pipe["pixel_row0_col0"]) < 0.01
    params = {k: v for k, v in f.model.to_dict().items() if k not in ("kind", "variant")}
    phys = TerraRefPlanckModel(**params, variant="physical").to_celsius(f.pixels)
    ref_phys = ref["physically_inverted_same_constants (T=22C,D=2.5,E=0.98,H=0.1)"]
    assert abs(phys.mean() - ref_phys["mean"]) < 0.01
    assert abs(phys[0, 0] - ref_phys["pixel_row0_col0"]) < 0.01
    plain = TerraRefPlanckModel(**params, variant="plain").to_celsius(f.pixels)
    assert abs(plain.mean() - ref["plain_planck_E1_tau1: B/ln(R*J1/(raw-J0)+F)-273.15"]["mean"]) < 0.01
    assert f.vendor_metadata["position_m"]["x"] == "5.7185"


def _exiftool_flir_times(txt: Path) -> list[int]:
    """exiftool's 'Date/Time Original' values that carry a zone (FLIR's own CameraInfo time), as UTC ns."""
    from datetime import datetime

    raw = txt.read_bytes()
    text = raw.decode("utf-16") if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else raw.decode("utf-8", "replace")
    out = []
    for line in text.splitlines():
        key, _, value = line.partition(":")
        value = value.strip()
        if key.strip() == "Date/Time Original" and value[-6:-5] in "+-" and value[-3:-2] == ":":
            dt = datetime.strptime(value, "%Y:%m:%d %H:%M:%S.%f%z")
            out.append(int(dt.timestamp()) * 1_000_000_000 + dt.microsecond * 1000)
    return out


def test_flir_capture_times_agree_with_exiftool(samples):
    """FLIR's CameraInfo time (UTC seconds, milliseconds, zone) read by us and by exiftool 12.x."""
    checked = 0
    for name in ("FLIR_E40.jpg", "FLIR_T640.jpg", "DJI_XT2.jpg", "frame_000000.fff"):
        (f,) = read_file(samples / "flir" / name)
        times = _exiftool_flir_times(samples / "flir" / (name.rsplit(".", 1)[0] + ".exiftool.txt"))
        assert times, name
        assert f.timestamp_ns == times[0], name
        assert f.vendor_metadata["time_basis"].startswith("utc: FLIR"), name
        checked += 1
    assert checked == 4
