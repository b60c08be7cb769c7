"""The ICD data standard: radiometry, naming, sidecar schema, contrast grade, NETD, bad pixels."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from thermcap.recorder.exceptions import SidecarError
from thermcap.recorder.icd.names import format_name, parse_name
from thermcap.recorder.icd.quality import contrast_grade, contrast_metrics, correct_bad_pixels, netd_mk
from thermcap.recorder.icd.sidecar import SIDECAR_SCHEMA, SidecarEncoder, dumps_sidecar, validate_sidecar
from thermcap.recorder.radiometry import LinearModel, model_from_dict

ICD_EXAMPLE = {
    "format_version": "1.0",
    "sensor": {"model": "FLIR Boson 640", "type": "uncooled_microbolometer", "serial_number": "BOSON640-12345",
               "spectral_range_um": [8.0, 14.0], "resolution": {"width": 640, "height": 512},
               "pixel_pitch_um": 12.0, "netd_mk": 50.0, "frame_rate_hz": 60.0},
    "radiometric": {"bit_depth": 14, "scale_factor_deg_c_per_count": 0.036, "offset_deg_c": -40.0,
                    "scene_temp_min_deg_c": -40.0, "scene_temp_max_deg_c": 550.0,
                    "calibration_date": "2026-01-11T00:00:00Z", "calibration_method": "factory_blackbody"},
    "capture": {"timestamp": "2026-01-11T15:30:45.123456Z", "exposure_time_us": 8000, "gain_db": 0.0,
                "fpa_temperature_c": 25.3, "lens_focal_length_mm": 9.1, "f_number": 1.0},
    "environment": {"ambient_temp_c": 22.5, "humidity_percent": 45.0, "atmospheric_transmission": 0.98,
                    "weather_condition": "clear", "visibility_m": 10000},
    "thermal_analysis": {"thermal_contrast_grade": 0.85, "max_target_temp_c": 48.2, "min_background_temp_c": 8.5,
                         "delta_t_deg_c": 39.7, "snr_db": 28.5, "detection_confidence": 0.92},
    "slew_to_cue": {"slew_to_cue_active": True, "radar_cue_received": True, "radar_azimuth_deg": 45.2,
                    "radar_elevation_deg": 12.8, "radar_range_m": 850.0, "turret_pan_deg": 45.5,
                    "turret_tilt_deg": 13.1, "search_pattern_active": False},
    "targets": [{"target_id": "TGT001", "bbox": [245, 180, 280, 215], "centroid": [262, 197], "max_temp_c": 48.2,
                 "mean_temp_c": 42.5, "classification": "drone_motor", "confidence": 0.89}],
}


# -- radiometry ---------------------------------------------------------------------------------
def test_icd_linear_examples():
    m = LinearModel()
    assert m.to_celsius(np.array([0, 8192, 16383])) == pytest.approx([-40.0, 254.912, 549.788])


def test_inverse_mapping_round_trips_every_count():
    m = LinearModel()
    counts = np.arange(0, 16384, dtype=np.uint16)
    assert np.array_equal(m.from_celsius(m.to_celsius(counts)), counts)


def test_inverse_mapping_clamps_to_14_bits():
    m = LinearModel()
    assert m.from_celsius(np.array([-100.0, 1000.0])).tolist() == [0, 16383]
    assert m.from_celsius(-40.0) == 0


def test_user_defined_range_section_3_3():
    m = LinearModel.from_range(0.0, 100.0)
    assert m.scale_c_per_count == pytest.approx(100 / 16383)
    assert m.to_celsius(np.array([0, 16383])) == pytest.approx([0.0, 100.0])
    with pytest.raises(ValueError):
        LinearModel.from_range(10, 10)


def test_model_survives_json():
    m = LinearModel.from_range(-20, 120)
    again = model_from_dict(json.loads(json.dumps(m.to_dict())))
    assert again == m
    with pytest.raises(ValueError, match="unknown radiometric model kind"):
        model_from_dict({"kind": "magic"})
    with pytest.raises(ValueError, match="unknown parameters"):
        model_from_dict({"kind": "linear", "gain": 2})


# -- naming ---------------------------------------------------------------------------------
def test_icd_name_example_parses_and_formats():
    parsed = parse_name("thermal_20260111T153045Z_BOSON640_N40_P60.tiff")
    assert (parsed.sensor_id, parsed.temp_min_c, parsed.temp_max_c) == ("BOSON640", -40, 60)
    assert format_name(parsed.timestamp_ns, "BOSON640", -40, 60, subsecond=False) == \
        "thermal_20260111T153045Z_BOSON640_N40_P60"


def test_icd_name_keeps_nanoseconds():
    ts = 1_768_145_445_123_456_789
    name = format_name(ts, "SIM640", -40, 550)
    assert name == "thermal_20260111T153045.123456789Z_SIM640_N40_P550"
    assert parse_name(name + ".json").timestamp_ns == ts


def test_icd_name_rejects_garbage():
    with pytest.raises(ValueError, match="naming convention"):
        parse_name("frame_0001.tiff")


# -- sidecar --------------------------------------------------------------------------------
def test_icd_example_sidecar_is_valid():
    validate_sidecar(copy.deepcopy(ICD_EXAMPLE))


@pytest.mark.parametrize("path,value,field", [
    (("sensor", "resolution", "width"), "640", "sensor.resolution.width"),
    (("thermal_analysis", "thermal_contrast_grade"), 1.5, "thermal_analysis.thermal_contrast_grade"),
    (("slew_to_cue", "slew_to_cue_active"), "yes", "slew_to_cue.slew_to_cue_active"),
    (("capture", "timestamp"), "yesterday", "capture.timestamp"),
])
def test_invalid_sidecar_names_the_field(path, value, field):
    doc = copy.deepcopy(ICD_EXAMPLE)
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(SidecarError) as err:
        validate_sidecar(doc)
    assert err.value.field == field
    assert field in str(err.value)


def test_missing_mandatory_block_is_an_error():
    doc = copy.deepcopy(ICD_EXAMPLE)
    del doc["slew_to_cue"]
    with pytest.raises(SidecarError, match="slew_to_cue"):
        validate_sidecar(doc)


def test_nan_is_rejected_not_written():
    doc = copy.deepcopy(ICD_EXAMPLE)
    doc["thermal_analysis"]["snr_db"] = math.nan
    with pytest.raises(SidecarError, match="snr_db"):
        dumps_sidecar(doc)


def test_encoder_output_equals_full_validation():
    enc = SidecarEncoder(ICD_EXAMPLE["sensor"], ICD_EXAMPLE["radiometric"])
    blocks = {k: ICD_EXAMPLE[k] for k in ("capture", "environment", "thermal_analysis", "slew_to_cue", "targets")}
    out = json.loads(enc.encode(blocks))
    assert out == ICD_EXAMPLE
    bad = copy.deepcopy(blocks)
    bad["targets"][0]["bbox"] = [1, 2, 3]
    with pytest.raises(SidecarError, match=r"targets"):
        enc.encode(bad)


def test_schema_is_draft_2020_12_valid():
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.Draft202012Validator.check_schema(SIDECAR_SCHEMA)
    jsonschema.Draft202012Validator(SIDECAR_SCHEMA).validate(ICD_EXAMPLE)


# -- contrast grade (ICD 4.3.1 / 7.1) -----------------------------------------------------------
@pytest.mark.parametrize("delta,grade", [(4.9, 0.0), (5.0, 0.0), (7.5, 0.5), (10.0, 1.0), (9.99, 0.998), (30, 1.0)])
def test_contrast_grade_thresholds(delta, grade):
    assert contrast_grade(delta) == pytest.approx(grade, abs=1e-9)


def _icd_reference(image, target_mask, background_mask):
    """ICD section 7.1, verbatim."""
    target_temps = image[target_mask]
    background_temps = image[background_mask]
    max_target_temp = np.max(target_temps)
    min_background_temp = np.min(background_temps)
    delta_T = max_target_temp - min_background_temp
    if delta_T < 5.0:
        grade = 0.0
    elif delta_T < 10.0:
        grade = (delta_T - 5.0) / 5.0
    else:
        grade = 1.0
    target_std = np.std(target_temps)
    background_std = np.std(background_temps)
    snr = delta_T / (target_std + background_std + 1e-6)
    snr_db = 10 * np.log10(snr + 1e-6)
    return grade, {"max_target_temp_c": max_target_temp, "mean_target_temp_c": np.mean(target_temps),
                   "min_background_temp_c": min_background_temp, "mean_background_temp_c": np.mean(background_temps),
                   "delta_t_deg_c": delta_T, "snr_db": snr_db, "thermal_contrast_grade": grade}


@pytest.mark.parametrize("target_temp", [24.9, 25.0, 27.5, 30.0, 60.0])
def test_contrast_metrics_match_icd_reference_on_hand_built_masks(target_temp):
    rng = np.random.default_rng(3)
    image = 20.0 + rng.normal(0, 0.05, (64, 64))
    image[30:36, 30:36] = target_temp
    target = np.zeros((64, 64), bool)
    target[30:36, 30:36] = True
    background = np.zeros((64, 64), bool)
    background[20:46, 20:46] = True
    background[28:38, 28:38] = False
    grade, ref = _icd_reference(image, target, background)
    ours = contrast_metrics(image, target, background)
    assert ours == pytest.approx(ref)
    assert ours["thermal_contrast_grade"] == grade


def test_contrast_metrics_refuse_empty_masks():
    with pytest.raises(ValueError):
        contrast_metrics(np.zeros((4, 4)), np.zeros((4, 4), bool), np.ones((4, 4), bool))


# -- NETD and bad pixels --------------------------------------------------------------------------
def test_netd_of_a_uniform_frame():
    rng = np.random.default_rng(0)
    sigma_counts = 0.050 / 0.036
    frame = 8000 + rng.normal(0, sigma_counts, (512, 640))
    assert netd_mk(frame, 0.036) == pytest.approx(50.0, rel=0.01)


def test_bad_pixels_replaced_by_median_of_good_neighbours():
    frame = np.full((5, 5), 100, np.uint16)
    frame[1, 1] = 90
    frame[2, 2] = 16383
    frame[2, 3] = 0
    bpm = np.zeros((5, 5), bool)
    bpm[2, 2] = bpm[2, 3] = True
    fixed = correct_bad_pixels(frame, bpm)
    assert fixed[2, 2] == 100
    assert fixed[2, 3] == 100
    assert fixed[1, 1] == 90  # a good pixel is never touched
    assert frame[2, 2] == 16383  # the input (the recorded counts) is never altered
