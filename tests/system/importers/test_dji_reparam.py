"""DJI object parameters changed after capture, through DJI's SDK, checked against dji-thermal-cli
run directly on the original R-JPEG at the same parameters (within 0.1 °C, at five parameter sets
on four DJI cameras). The counts stay as recorded, version 0 stays what the camera measured, and
the API names the version its temperatures used."""

from __future__ import annotations

import hashlib
import io
import json
import shutil
import subprocess

import numpy as np
import pytest
import tifffile
from fastapi.testclient import TestClient

from tests.conftest import run_cli
from thermcap.api.app import create_app
from thermcap.api.settings import Settings

DJI_CLI = shutil.which("dji-thermal-cli")
pytestmark = pytest.mark.skipif(DJI_CLI is None, reason="dji-thermal-cli is not installed (optional, needs "
                                                        "Python >= 3.12; .ci/run installs it where it can)")

FILES = ["DJI_H20T.jpg", "M30T_DJI_0001_R.JPG", "M2EA_DJI_0001_R.JPG", "M4T_DJI_0003_R.JPG"]
PARAMS = [
    {"emissivity": 0.95},
    {"emissivity": 0.7, "object_distance_m": 5.0},
    {"relative_humidity_pct": 30.0, "reflected_temp_c": 40.0},
    {"emissivity": 0.85, "object_distance_m": 20.0, "relative_humidity_pct": 80.0, "reflected_temp_c": 10.0},
    {"atmospheric_temp_c": 35.0, "emissivity": 0.9},
]
FLAGS = {"emissivity": "--emissivity", "object_distance_m": "--distance", "relative_humidity_pct": "--humidity",
         "reflected_temp_c": "--reflected-temp", "atmospheric_temp_c": "--ambient-temp"}


def _reference(path, params, tmp_path):
    """dji-thermal-cli on the original file, as a user would run it."""
    out = tmp_path / f"ref-{hashlib.sha256(json.dumps([str(path), params]).encode()).hexdigest()[:8]}"
    cmd = [DJI_CLI, "process", "--input-dir", str(path), "--output-dir", str(out), "--output", "temp_c:tiff",
           "--compression", "none", "--quiet"]
    for k, v in params.items():
        cmd += [FLAGS[k], str(v)]
    subprocess.run(cmd, check=True, capture_output=True, timeout=300)
    return tifffile.imread(next(out.glob("*_temp_c.tiff")))


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    from tests.conftest import SAMPLES as samples

    if not samples.is_dir():
        pytest.skip(f"real sample files not present at {samples} (the shared/ folder beside the checkout)")
    root = tmp_path_factory.mktemp("djireparam")
    src = root / "in"
    src.mkdir()
    for name in FILES:
        shutil.copy(samples / "dji" / name, src / name)
    r = run_cli("import", str(src), "--root", str(root), "--json", "--no-analysis", "--dji-sdk", DJI_CLI, timeout=600)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    return root, {f["path"].rsplit("/", 1)[-1]: f["session_id"] for f in out["files"]}


def test_five_parameter_sets_agree_with_dji_thermal_cli_on_four_cameras(imported, samples, tmp_path):
    root, sids = imported
    worst = 0.0
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as client:
        for name in FILES:
            sid = sids[name]
            raw0 = client.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "raw"}).content
            at_capture = tifffile.imread(io.BytesIO(client.get(f"/api/v1/sessions/{sid}/frames/0",
                                                               params={"format": "celsius-tiff"}).content))
            for k, params in enumerate(PARAMS, start=1):
                sets = [x for kv in params.items() for x in ("--set", f"{kv[0]}={kv[1]}")]
                r = run_cli("radiometry", sid, "--root", str(root), *sets, "--why", f"set {k}", "--json",
                            "--dji-sdk", DJI_CLI, timeout=300)
                assert r.returncode == 0, r.stderr
                assert json.loads(r.stdout)["version"] == k
                ours = tifffile.imread(io.BytesIO(client.get(f"/api/v1/sessions/{sid}/frames/0",
                                                             params={"format": "celsius-tiff"}).content))
                ref = _reference(samples / "dji" / name, params, tmp_path)
                diff = float(np.abs(ours.astype(np.float64) - ref).max())
                worst = max(worst, diff)
                assert diff < 0.1, (name, params, diff)
                px = client.get(f"/api/v1/sessions/{sid}/frames/0/temperature", params={"x": 10, "y": 10}).json()
                assert px["model_version"] == k and abs(px["celsius"] - float(ref[10, 10])) < 0.1
            assert client.get(f"/api/v1/sessions/{sid}/frames/0", params={"format": "raw"}).content == raw0
            # the camera's own measurement is still version 0, and a changed emissivity moved the numbers
            assert float(np.abs(at_capture - _reference(samples / "dji" / name, PARAMS[1], tmp_path)).max()) > 0.1
    print(f"worst difference from dji-thermal-cli: {worst:.4f} °C")


def test_the_api_takes_a_dji_version_through_the_sdk_and_refuses_what_the_sdk_cannot(imported, samples, tmp_path):
    root, sids = imported
    sid = sids["M30T_DJI_0001_R.JPG"]
    with TestClient(create_app(Settings(root=root, tokens={}, rescan_interval_s=0))) as client:
        bad = client.post(f"/api/v1/sessions/{sid}/radiometry",
                          json={"params": {"ir_window_transmission": 0.9}, "why": "a window"})
        assert bad.status_code == 400 and "DJI's SDK takes" in bad.text
        r = client.post(f"/api/v1/sessions/{sid}/radiometry", json={"params": {"emissivity": 0.6}, "why": "rubber"})
        assert r.status_code == 201, r.text
        version = r.json()["version"]
        assert r.json()["model"]["kind"] == "lookup_table" and "dji-thermal-cli" in r.json()["model"]["source"]
        t = tifffile.imread(io.BytesIO(client.get(f"/api/v1/sessions/{sid}/frames/0",
                                                  params={"format": "celsius-tiff"}).content))
        ref = _reference(samples / "dji" / "M30T_DJI_0001_R.JPG", {"emissivity": 0.6}, tmp_path)
        assert float(np.abs(t - ref).max()) < 0.1
        m = client.get(f"/api/v1/sessions/{sid}/frames/0/measure", params={"tool": "box:0,0,20,20"}).json()
        assert m["model_version"] == version
        per_request = client.get(f"/api/v1/sessions/{sid}/frames/0/temperature",
                                 params={"x": 1, "y": 1, "emissivity": 0.5})
        assert per_request.status_code == 409 and "DJI's SDK" in per_request.text
