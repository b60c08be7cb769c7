"""TERRA-REF re-parameterised after capture reproduces a published pipeline's parameters: the
gantry's FLIR sample at PhytoOracle's flir2tif settings (air temperature = the shutter's,
320.365 K; distance 3.778 m) gives the values derived with that pipeline, within 0.01 °C, and
names the version it used. (At the TERRA-REF pipeline's own parameters the import is checked in
tests/integration/importers/test_export.py.)"""

from __future__ import annotations

import io
import json

import pytest
import tifffile
from fastapi.testclient import TestClient

from tests.conftest import SAMPLES, SAMPLES_HOW
from thermcap.api.app import create_app
from thermcap.api.settings import Settings
from thermcap.recorder.importers.run import import_paths


def test_phytooracle_parameters_through_the_api(tmp_path):
    if not (SAMPLES / "terraref").is_dir():
        pytest.skip(f"real sample files not present at {SAMPLES}: {SAMPLES_HOW}")
    ref = json.loads((SAMPLES / "terraref" / "reference_temperatures_derived.json").read_text())[
        "phytooracle_flir2tif_s17_variant (T=shutter temp, D=3.778m)"]
    import_paths([str(SAMPLES / "terraref")], tmp_path, session="gantry", analysis=False)
    with TestClient(create_app(Settings(root=tmp_path, tokens={}, rescan_interval_s=0))) as c:
        r = c.post("/api/v1/sessions/gantry/radiometry", json={
            "params": {"atmospheric_temp_c": 320.365 - 273.15, "object_distance_m": 3.778},
            "why": "PhytoOracle flir2tif: the shutter's temperature for the air, the gantry's distance"})
        assert r.status_code == 201, r.text
        got = c.get("/api/v1/sessions/gantry/frames/0", params={"format": "celsius-tiff"})
        assert got.headers["x-model-version"] == str(r.json()["version"])
        t = tifffile.imread(io.BytesIO(got.content))
        for k, v in (("min", float(t.min())), ("max", float(t.max())), ("mean", float(t.mean()))):
            assert abs(v - ref[k]) < 0.01, (k, v, ref[k])
