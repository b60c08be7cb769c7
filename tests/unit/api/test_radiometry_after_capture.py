"""Object parameters changed after capture, checked against an independent implementation:
flyr (pip) recomputes the FLIR samples at five parameter sets, and our API, through a
per-request override and through a recorded version, agrees within 0.01 °C; the counts never
change; every temperature names its version; models that cannot take the change say why."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from fastapi.testclient import TestClient

from tests.conftest import SAMPLES, SAMPLES_HOW
from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.cli import cli
from thermcap.recorder.importers.run import import_paths

flyr = pytest.importorskip("flyr", reason="flyr is a test dependency (pip install 'thermcap[test]')")

PARAMS = [
    {"emissivity": 0.95, "object_distance_m": 1.0, "reflected_temp_c": 20.0, "atmospheric_temp_c": 20.0,
     "relative_humidity_pct": 50.0},
    {"emissivity": 0.9, "object_distance_m": 5.0, "reflected_temp_c": 20.0, "atmospheric_temp_c": 10.0,
     "relative_humidity_pct": 40.0},
    {"emissivity": 0.75, "object_distance_m": 1.0, "reflected_temp_c": -10.0, "atmospheric_temp_c": 30.0,
     "relative_humidity_pct": 80.0},
    {"emissivity": 0.98, "object_distance_m": 20.0, "reflected_temp_c": 35.0, "atmospheric_temp_c": 25.0,
     "relative_humidity_pct": 20.0},
    {"emissivity": 0.6, "object_distance_m": 0.5, "reflected_temp_c": 0.0, "atmospheric_temp_c": 15.0,
     "relative_humidity_pct": 95.0},
]
SAMPLE_FILES = ["FLIR_T640.jpg", "FLIR_E40.jpg"]


def _flyr(path, p) -> np.ndarray:
    th = flyr.unpack(str(path)).adjust_metadata(
        emissivity=p["emissivity"], object_distance=p["object_distance_m"],
        reflected_apparent_temperature=p["reflected_temp_c"] + 273.15,
        atmospheric_temperature=p["atmospheric_temp_c"] + 273.15, relative_humidity=p["relative_humidity_pct"] / 100)
    return th.celsius


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("radio")
    for name in SAMPLE_FILES:
        if not (SAMPLES / "flir" / name).is_file():
            pytest.skip(f"{SAMPLES / 'flir' / name} is not here: {SAMPLES_HOW}")
        import_paths([str(SAMPLES / "flir" / name)], root, session=name.split(".")[0].lower().replace("_", "-"),
                     analysis=False)
    dji = SAMPLES / "dji" / "M30T_DJI_0001_R.JPG"
    if dji.is_file():
        import_paths([str(dji)], root, session="m30t", analysis=False)
    return root


@pytest.fixture(scope="module")
def client(root):
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as c:
        yield c


@pytest.mark.parametrize("name", SAMPLE_FILES)
@pytest.mark.parametrize("k", range(len(PARAMS)))
def test_per_request_parameters_agree_with_flyr(client, name, k):
    sid = name.split(".")[0].lower().replace("_", "-")
    ref = _flyr(SAMPLES / "flir" / name, PARAMS[k])
    h, w = ref.shape
    for x, y in ((0, 0), (w // 2, h // 2), (w - 1, h - 1), (w // 3, 2 * h // 3)):
        r = client.get(f"/api/v1/sessions/{sid}/frames/0/temperature", params={"x": x, "y": y, **PARAMS[k]})
        assert r.status_code == 200, r.text
        body = r.json()
        assert body["celsius"] == pytest.approx(float(ref[y, x]), abs=0.01)
        assert body["model_version"] == 0 and body["object_parameters"] == PARAMS[k]
    box = client.get(f"/api/v1/sessions/{sid}/frames/0/measure", params={"tool": f"box:0,0,{w - 1},{h - 1}",
                                                                           **PARAMS[k]}).json()
    m = box["measurements"][0]
    assert m["max_c"] == pytest.approx(float(ref.max()), abs=0.01)
    assert m["mean_c"] == pytest.approx(float(ref.mean()), abs=0.01)


def test_a_recorded_version_applies_to_its_frames_and_is_named(client, root):
    sid = "flir-t640"
    before = client.get(f"/api/v1/sessions/{sid}/frames/0/temperature", params={"x": 10, "y": 10}).json()
    raw_before = client.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "raw"}).content
    r = client.post(f"/api/v1/sessions/{sid}/radiometry",
                    json={"params": PARAMS[2], "why": "painted steel, emissivity measured on site", "who": "test"})
    assert r.status_code == 201, r.text
    assert r.json()["version"] == 1
    after = client.get(f"/api/v1/sessions/{sid}/frames/0/temperature", params={"x": 10, "y": 10}).json()
    ref = _flyr(SAMPLES / "flir" / "FLIR_T640.jpg", PARAMS[2])
    assert after["model_version"] == 1 and after["celsius"] == pytest.approx(float(ref[10, 10]), abs=0.01)
    assert after["celsius"] != before["celsius"]
    assert client.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "raw"}).content == raw_before
    listed = client.get(f"/api/v1/sessions/{sid}/radiometry").json()
    assert [v["why"] for v in listed["versions"]] == ["painted steel, emissivity measured on site"]
    tiff = client.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "celsius-tiff"})
    assert tiff.headers["x-model-version"] == "1"


def test_the_cli_records_versions_and_refusals_say_why(client, root, monkeypatch):
    r = CliRunner().invoke(cli, ["radiometry", "flir-e40", "--root", str(root), "--set", "emissivity=0.8",
                                 "--why", "wet surface", "--frames", "0:1", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.output)["frames"] == [0, 1]
    r = CliRunner().invoke(cli, ["radiometry", "flir-e40", "--root", str(root), "--set", "emissivity=3",
                                 "--why", "x"])
    assert r.exit_code == 1 and "outside" in r.output
    r = CliRunner().invoke(cli, ["radiometry", "flir-e40", "--root", str(root), "--set", "emissivity=0.9"])
    assert r.exit_code == 1 and "why" in r.output
    bad = client.get("/api/v1/sessions/flir-e40/frames/0/temperature", params={"x": 1, "y": 1, "emissivity": "x"})
    assert bad.status_code == 400
    if (root / "sessions" / "m30t").is_dir():
        monkeypatch.setenv("THERMCAP_DJI_SDK", "off")  # a server without DJI's SDK (with it: tests/system)
        r = client.post("/api/v1/sessions/m30t/radiometry", json={"params": {"emissivity": 0.9}, "why": "x"})
        assert r.status_code == 409 and "DJI's SDK" in r.json()["error"]


def test_a_session_scale_follows_the_parameters_it_was_made_with(client):
    url = "/api/v1/sessions/flir-e40/frames/0"
    plain = client.get(url, params={"format": "preview", "range": "session"})
    changed = client.get(url, params={"format": "preview", "range": "session", **PARAMS[4]})
    assert plain.status_code == changed.status_code == 200
    assert plain.headers["x-range-max"] != changed.headers["x-range-max"]  # not the scale of the other model
