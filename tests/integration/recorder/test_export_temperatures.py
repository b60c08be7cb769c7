"""Issue 37: every product's temperatures come from one place (``SessionTemperatures``): the model
version covering the frame and the session's bad pixels NaN. Before, ``export`` ignored
``thermcap radiometry``: after ``--set emissivity=0.8`` the celsius-tiff of two real FLIR JPEGs
was bit-identical to the emissivity-0.95 one and up to 6.56 °C off flyr; and the simulator's
dead and hot pixels came out as -40 and 549.8 °C.

The matrix: product kinds (celsius-tiff, kelvin-tiff, heatmap-png's scale, the CSV summary) x
{the capture model, a re-parameterised version}, each checked against an independent
implementation: flyr for FLIR, the ICD's linear formula for the simulator."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import tifffile

from tests.conftest import SAMPLES, SAMPLES_HOW
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.importers.run import import_paths
from thermcap.recorder.radiometry.base import model_from_dict
from thermcap.recorder.radiometry.params import add_version
from thermcap.recorder.radiometry.session import read_bad_pixel_map
from thermcap.recorder.storage.reader import iter_session_frames, read_session_meta

flyr = pytest.importorskip("flyr", reason="flyr is a test dependency (pip install 'thermcap[test]')")
FLIR = ["FLIR_T640.jpg", "FLIR_E40.jpg"]
ERRORS: dict[str, float] = {}  # product -> largest |ours - reference| °C, for the closing note


def _flyr(path, emissivity=None):
    th = flyr.unpack(str(path))
    if emissivity is not None:
        th = th.adjust_metadata(emissivity=emissivity)
    return th.celsius


def _tiff(out):
    [path] = sorted(out.glob("*.tiff"))
    with tifffile.TiffFile(path) as t:
        data = t.asarray()
        meta = json.loads(t.pages[0].description)
    return data, meta


@pytest.fixture(scope="module")
def flir_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("flir")
    for name in FLIR:
        if not (SAMPLES / "flir" / name).is_file():
            pytest.skip(f"{SAMPLES / 'flir' / name} is not here: {SAMPLES_HOW}")
        import_paths([str(SAMPLES / "flir" / name)], root, session=name.split(".")[0].lower().replace("_", "-"),
                     analysis=False)
    return root


@pytest.mark.parametrize("name", FLIR)
@pytest.mark.parametrize("kind", ["celsius-tiff", "kelvin-tiff"])
def test_flir_exports_follow_the_model_version(flir_root, tmp_path, name, kind):
    session = flir_root / "sessions" / name.split(".")[0].lower().replace("_", "-")
    offset = 273.15 if kind == "kelvin-tiff" else 0.0
    before, meta0 = _tiff(_export(session, kind, tmp_path / "v0"))
    ref0 = _flyr(SAMPLES / "flir" / name)
    err0 = float(np.nanmax(np.abs(before - offset - ref0)))
    assert err0 < 0.01, err0
    assert meta0["model_version"] == 0
    base = model_from_dict(read_session_meta(session)["radiometric_model"])
    add_version(session, base, {"emissivity": 0.8}, who="test", why="a painted surface")
    after, meta1 = _tiff(_export(session, kind, tmp_path / "v1"))
    ref1 = _flyr(SAMPLES / "flir" / name, emissivity=0.8)
    err1 = float(np.nanmax(np.abs(after - offset - ref1)))
    assert err1 < 0.01, err1
    assert meta1["model_version"] == 1 and meta1["radiometric_model"]["emissivity"] == 0.8
    assert not np.array_equal(before, after)
    pinned, meta_p = _tiff(_export(session, kind, tmp_path / "pinned", model_version=0))
    assert np.array_equal(pinned, before) and meta_p["model_version"] == 0
    ERRORS[f"{kind} FLIR {name} v0"] = err0
    ERRORS[f"{kind} FLIR {name} v1 (emissivity 0.8)"] = err1
    (session / "radiometry.json").unlink()


def _export(session, kind, out, **kw):
    export_session(session, kind, out, **kw)
    return out


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim")
    Recorder(SimSource(width=96, height=64, frames=4, paced=False, seed=5, start_time_ns=1_800_000_000_000_000_000),
             root, session_id="s", analysis=False).run()
    return root / "sessions" / "s"


def test_known_bad_pixels_are_nan_and_out_of_every_statistic(sim, tmp_path):
    mask = read_bad_pixel_map(sim)
    assert mask is not None and mask.any(), "the simulator lists dead and hot pixels"
    frames = list(iter_session_frames(sim))
    export_session(sim, "celsius-tiff", tmp_path / "c", summary="csv")
    tiffs = sorted((tmp_path / "c").glob("*.tiff"))
    assert len(tiffs) == len(frames)
    for f, path in zip(frames, tiffs, strict=True):
        data = tifffile.imread(path)
        assert np.isnan(data[mask]).all() and np.isfinite(data[~mask]).all()
        icd = f.pixels.astype(np.float64) * 0.036 - 40  # the ICD's own formula
        err = float(np.max(np.abs(data[~mask] - icd[~mask])))
        assert err < 1e-4
        ERRORS["celsius-tiff linear (ICD formula)"] = max(ERRORS.get("celsius-tiff linear (ICD formula)", 0), err)
        meta = json.loads(tifffile.TiffFile(path).pages[0].description)
        assert meta["bad_pixels"]["listed"] == int(mask.sum()) and meta["bad_pixels"]["rule"] == "nan"
    rows = list(csv.DictReader((tmp_path / "c" / "summary.csv").read_text().splitlines()))
    for f, row in zip(frames, rows, strict=True):
        good = f.pixels[~mask].astype(np.float64) * 0.036 - 40
        assert abs(float(row["surface_temperature_max"]) - good.max()) < 1e-3
        assert abs(float(row["surface_temperature_min"]) - good.min()) < 1e-3
        assert float(row["surface_temperature_max"]) < 549 and float(row["surface_temperature_min"]) > -40
    export_session(sim, "celsius-tiff", tmp_path / "k", bad_pixels="keep")
    kept = tifffile.imread(sorted((tmp_path / "k").glob("*.tiff"))[0])
    assert np.isfinite(kept).all()


def test_heatmap_scale_ignores_bad_pixels(sim, tmp_path):
    import imagecodecs

    export_session(sim, "heatmap-png", tmp_path / "h", colorbar=False)
    path = sorted((tmp_path / "h").glob("*.png"))[0]
    rgb = imagecodecs.png_decode(path.read_bytes())
    mask = read_bad_pixel_map(sim)
    assert (rgb[mask] == (255, 0, 255)).all()
    text = path.read_bytes()
    assert b"549.8" not in text and b"-40.0" not in text


def test_an_unknown_model_version_is_refused(sim, tmp_path):
    from thermcap.recorder.exceptions import ThermcapError

    with pytest.raises(ThermcapError, match="model version 3"):
        export_session(sim, "celsius-tiff", tmp_path / "x", model_version=3)


def test_zz_print_errors():
    """The figures of the closing note: each product's largest error against its reference."""
    for k, v in sorted(ERRORS.items()):
        print(f"{k}: max |error| {v:.6f} °C")
