"""Exports: temperature TIFFs, heatmaps, ICD pairs and the surface_temperature summary."""

from __future__ import annotations

import csv
import json

import imagecodecs
import numpy as np
import pytest
import tifffile

from tests.conftest import run_cli
from thermcap.recorder.capture.recorder import Recorder
from thermcap.recorder.capture.sources.sim import SimSource
from thermcap.recorder.exports.colorbar import png_text
from thermcap.recorder.exports.files import export_session
from thermcap.recorder.icd.sidecar import validate_sidecar
from thermcap.recorder.storage.reader import iter_session_frames


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    root = tmp_path_factory.mktemp("exp")
    Recorder(SimSource(width=96, height=64, frames=5, paced=False, start_time_ns=1_800_000_000_000_000_000), root,
             session_id="e", analysis=False).run()
    return root / "sessions" / "e"


def test_celsius_and_kelvin_tiffs_follow_the_model(session, tmp_path):
    frames = list(iter_session_frames(session))
    export_session(session, "celsius-tiff", tmp_path / "c", summary="csv")
    export_session(session, "kelvin-tiff", tmp_path / "k")
    c = sorted((tmp_path / "c").glob("*.tiff"))
    k = sorted((tmp_path / "k").glob("*.tiff"))
    assert len(c) == len(k) == 5
    assert c[0].name.startswith("thermal_20270115T080000.000000000Z_SIM640_N40_P550")
    tc, tk = tifffile.imread(c[2]), tifffile.imread(k[2])
    assert tc.dtype == np.float32
    good = np.isfinite(tc)  # the session's bad pixels have no temperature (issue 37)
    assert 0 < (~good).sum() < 100 and np.array_equal(good, np.isfinite(tk))
    assert np.allclose(tc[good], (frames[2].pixels * 0.036 - 40)[good], atol=1e-4)
    assert np.allclose(tk[good], tc[good] + 273.15, atol=1e-3)
    with open(tmp_path / "c" / "summary.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5
    assert float(rows[2]["surface_temperature_max"]) == pytest.approx(float(tc[good].max()), abs=1e-3)
    assert float(rows[2]["surface_temperature_p50"]) == pytest.approx(float(np.percentile(tc[good], 50)), abs=1e-3)


def test_icd_pairs_are_uncompressed_with_sidecars(session, tmp_path):
    frames = list(iter_session_frames(session))
    export_session(session, "icd", tmp_path / "i", summary="json")
    tiffs = sorted((tmp_path / "i").glob("*.tiff"))
    with tifffile.TiffFile(tiffs[1]) as t:
        page = t.pages[0]
        assert page.compression == 1
        assert t.byteorder == "<"
        assert page.rowsperstrip == 64
        assert np.array_equal(page.asarray(), frames[1].pixels)
    validate_sidecar(json.loads(tiffs[1].with_suffix(".json").read_text()))
    summary = json.loads((tmp_path / "i" / "summary.json").read_text())
    assert summary["standard_name"] == "surface_temperature"
    assert len(summary["frames"]) == 5


def test_heatmaps_share_one_scale(session, tmp_path):
    export_session(session, "heatmap-png", tmp_path / "h", palette_name="turbo")
    pngs = sorted((tmp_path / "h").glob("*.png"))
    img = imagecodecs.png_decode(pngs[0].read_bytes())
    assert img.dtype == np.uint8
    assert img.shape[0] == 64 and img.shape[1] > 96 and img.shape[2] == 3  # the picture, then its colour bar
    scales = {tuple(sorted(png_text(p.read_bytes()).items())) for p in pngs}
    assert len(scales) == 1  # one scale, written in every file


def test_export_cli_refuses_temperatures_without_a_model(samples, tmp_path):
    root = tmp_path / "r"
    r = run_cli("import", str(samples / "dji" / "DJI_H20T.jpg"), "--root", str(root), "--session", "h20t",
                "--no-analysis",
                "--dji-sdk", "off")
    assert r.returncode == 0, r.stderr
    r = run_cli("export", "h20t", "--root", str(root), "--to", "celsius-tiff")
    assert r.returncode == 1
    assert "DJI Thermal SDK" in r.stderr
    r = run_cli("export", "h20t", "--root", str(root), "--to", "icd")
    assert r.returncode == 0, r.stderr


def test_celsius_tiff_has_geotiff_tags_where_the_source_has_a_position(samples, tmp_path):
    import tifffile

    root = tmp_path / "r"
    r = run_cli("import", str(samples / "dji" / "DJI_H20T.jpg"), str(samples / "dji" / "M2EA_DJI_0001_R.JPG"),
                "--root", str(root), "--no-analysis", "--json", "--dji-sdk", "off")
    assert r.returncode == 0, r.stderr
    files = {f["path"].rsplit("/", 1)[-1]: f for f in json.loads(r.stdout)["files"]}
    # H20T keeps its drone-dji XMP (formats.md): it has a position, but needs DJI's SDK for temperatures,
    # so check the tags through the helper with its recorded position, and M2EA (no XMP) gets none.
    from thermcap.recorder.exports.files import _positions, geotiff_tags

    h20t = root / "sessions" / files["DJI_H20T.jpg"]["session_id"]
    (pos,) = _positions(h20t).values()
    tags = geotiff_tags(pos, (512, 640))
    assert tags
    assert tags[0][0] == 33922
    assert tags[0][3][:2] == (320.0, 256.0)
    assert abs(tags[0][3][4] - float(pos["latitude"])) < 1e-9
    assert 4326 in tags[1][3]
    out = tmp_path / "geo.tiff"
    tifffile.imwrite(out, np.zeros((512, 640), np.float32), extratags=tags, metadata=None)
    with tifffile.TiffFile(out) as t:
        geo = t.pages[0].geotiff_tags
        assert geo["GeographicTypeGeoKey"] == 4326
        assert geo["ModelTiepoint"][4] == pytest.approx(float(pos["latitude"]))
    m2ea = root / "sessions" / files["M2EA_DJI_0001_R.JPG"]["session_id"]
    assert _positions(m2ea) == {}
    res = export_session(m2ea, "celsius-tiff", tmp_path / "m", allow_approximate=True)
    with tifffile.TiffFile(next((tmp_path / "m").glob("*.tiff"))) as t:
        assert 33922 not in {tag.code for tag in t.pages[0].tags}
    assert res["files"] == 1


@pytest.mark.parametrize("variant,key", [
    ("pipeline", "terraref_Get_FLIR_2017_as_implemented (T=22C,D=2.5m,E=0.98,H=0.1; forward-model bug kept)"),
    ("physical", "physically_inverted_same_constants (T=22C,D=2.5,E=0.98,H=0.1)"),
    ("plain", "plain_planck_E1_tau1: B/ln(R*J1/(raw-J0)+F)-273.15"),
])
def test_import_cli_offers_each_terraref_variant(samples, tmp_path, variant, key):
    ref = json.loads((samples / "terraref" / "reference_temperatures_derived.json").read_text())[key]
    r = run_cli("import", str(samples / "terraref"), "--root", str(tmp_path / "r"), "--json", "--no-analysis",
                "--terraref-variant", variant)
    assert r.returncode == 0, r.stderr
    (f,) = json.loads(r.stdout)["files"]
    assert f["model"]["variant"] == variant
    for k in ("min", "max", "mean"):
        assert abs(f["celsius"][k] - ref[k]) < 0.01, (variant, k, f["celsius"][k], ref[k])


def test_approximate_dji_temperatures_are_refused_unless_allowed_and_then_marked(samples, tmp_path):
    """M2EA is iirp: without DJI's SDK its °C are only the uncorrected blackbody formula."""
    import tifffile

    sample = samples / "dji" / "M2EA_DJI_0001_R.JPG"
    root = tmp_path / "r"
    assert run_cli("import", str(sample), "--root", str(root), "--session", "m2ea", "--no-analysis",
                   "--dji-sdk", "off").returncode == 0
    for kind in ("celsius-tiff", "heatmap-png"):
        r = run_cli("export", "m2ea", "--root", str(root), "--to", kind, "--out", str(tmp_path / kind))
        assert r.returncode == 1 and "approximate" in r.stderr and "--allow-approximate" in r.stderr, r.stderr
        assert not (tmp_path / kind).exists() or not any((tmp_path / kind).iterdir())
    r = run_cli("export", "m2ea", "--root", str(root), "--to", "celsius-tiff", "--out", str(tmp_path / "ok"),
                "--allow-approximate")
    assert r.returncode == 0, r.stderr
    (tiff,) = (tmp_path / "ok").glob("*.tiff")
    assert "_APPROXIMATE" in tiff.name
    with tifffile.TiffFile(tiff) as t:
        gdal = t.pages[0].tags[42112].value
    assert 'role="description">temperature, APPROXIMATE' in gdal and "temperature_quality" in gdal
    # the counts are another matter: an ICD export of the same session is not refused
    assert run_cli("export", "m2ea", "--root", str(root), "--to", "icd", "--out", str(tmp_path / "icd")).returncode == 0


def test_export_takes_a_frame_or_time_range(tmp_path):
    root = tmp_path / "r"
    assert run_cli("record", "--root", str(root), "--session", "s", "--duration", "0.5", "--width", "32",
                   "--height", "24").returncode == 0
    r = run_cli("export", "s", "--root", str(root), "--to", "icd", "--frames", "3:7", "--out", str(tmp_path / "a"),
                "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["files"] == 4
    r = run_cli("export", "s", "--root", str(root), "--to", "icd", "--start", "0", "--end", "0.1",
                "--out", str(tmp_path / "b"), "--json")
    assert r.returncode == 0, r.stderr
    assert 4 <= json.loads(r.stdout)["files"] <= 8  # 0.1 s at 60 fps
    for bad in (["--frames", "7:3"], ["--frames", "x"], ["--start", "noon"], ["--start", "1", "--end", "0.5"]):
        r = run_cli("export", "s", "--root", str(root), "--to", "icd", *bad, "--out", str(tmp_path / "c"))
        assert r.returncode == 1 and "Traceback" not in r.stderr and ("--" in r.stderr), (bad, r.stderr)
